"""Errors raised for bad user input.

Every message is one line that says what is wrong and how to fix it; the CLI prints it and exits
with code 2 (no traceback).
"""


class VCSInputError(ValueError):
    """Bad input: the message names the problem and the fix, on one line."""
