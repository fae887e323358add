"""``python -m vcs.cli ...``: the `vcs` command line."""

import sys

from vcs.cli.main import main

sys.exit(main())
