"""Shared start-up of the workflow scripts: log to snakemake.log[0], one-line errors.

Imported by the scripts of workflow/scripts/ (``sys.path`` gets ``snakemake.scriptdir`` first).
"""

from __future__ import annotations

import logging
import os
import sys
import traceback


def setup(snakemake, name: str) -> logging.Logger:
    """Send stderr and logging of this job to its log file; return the script's logger."""
    log_file = open(snakemake.log[0], "a", buffering=1)
    sys.stderr.flush()
    os.dup2(log_file.fileno(), 2)  # C-level stderr too (VTK, OpenFOAM readers)
    sys.stderr = log_file
    logging.basicConfig(
        stream=log_file, level=logging.INFO, force=True, format="%(asctime)s %(levelname)s %(name)s: %(message)s"
    )
    return logging.getLogger(name)


def run(main, snakemake, log: logging.Logger) -> None:
    """Run ``main(snakemake)``; bad input ends the job with one line (exit 2), a bug with its
    traceback in the log (exit 1)."""
    from vcs.errors import VCSInputError

    try:
        main(snakemake)
    except (VCSInputError, FileNotFoundError) as exc:  # a plain ValueError is a bug: traceback below
        log.error("%s", " ".join(str(exc).split()))
        sys.exit(2)
    except Exception:  # a bug: keep the traceback
        log.error("internal error\n%s", traceback.format_exc())
        sys.exit(1)
