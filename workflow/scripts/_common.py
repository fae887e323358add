"""Shared start-up of the workflow scripts: log to snakemake.log[0], one-line errors.

Imported by the scripts of workflow/scripts/ (``sys.path`` gets ``snakemake.scriptdir`` first).
"""

from __future__ import annotations

import logging
import os
import signal
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
    signal.signal(signal.SIGTERM, _interrupted)  # scancel, or snakemake killing its jobs
    return logging.getLogger(name)


def _interrupted(signum, frame):
    """SIGTERM handler: unwind like Ctrl-C, so that running OpenFOAM process groups are stopped."""
    raise KeyboardInterrupt(signal.Signals(signum).name)


def run(main, snakemake, log: logging.Logger) -> None:
    """Run ``main(snakemake)``; bad input ends the job with one line (exit 2), a bug with its
    traceback in the log (exit 1)."""
    from vcs.errors import VCSInputError

    try:
        main(snakemake)
    except (VCSInputError, FileNotFoundError) as exc:  # a plain ValueError is a bug: traceback below
        log.error("%s", " ".join(str(exc).split()))
        sys.exit(2)
    except KeyboardInterrupt as exc:  # Ctrl-C or SIGTERM: solvers already stopped by vcs.cfd.utilities
        log.error("interrupted (%s): this job's outputs are incomplete and will be recomputed", exc or "SIGINT")
        sys.exit(130)
    except Exception:  # a bug: keep the traceback
        log.error("internal error\n%s", traceback.format_exc())
        sys.exit(1)
