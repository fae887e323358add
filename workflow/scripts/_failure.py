"""One patient's failure as data, not as a failed job (standard library only).

A stage of one patient that cannot make its result (bad mesh, folded wall, case that cannot be set
up, ...) does not fail its Snakemake job: every output of the job holds a *failure record*
instead, a small JSON object

    {"failed": true, "stage": "fit", "reason": "fit failed: ...", "patient": "P3",
     "log": "/abs/results/logs/vcs_fit/P3.log", "exit_code": 2, "note": "..."}

The next stages pass it on (the wall STL of a failed fit is the fit's record, openfoam_case turns it
into SETUP_FAILED.json, openfoam_solve into status.json, fields_sample into a placeholder
fields.npz), so the chain ends as usual and the atlas lists the patient under
``patients_excluded`` with the stage and the reason. The outputs are replaced by the record, so
a rerun after fixing the input reruns the chain (Snakemake sees new inputs) and nothing that looks
like a result is left behind.

Command line (the tail of the shell rules vcs_fit, vcs_wall and vcs_lumen, see workflow/rules/geometry.smk):

    python _failure.py propagate --patient ID --log LOG --upstream FILE... -- OUTPUT...
        exit 0 after writing the first upstream failure record found into every OUTPUT
        (the stage is then not run); exit 1 when no upstream file is a failure record
    python _failure.py record STAGE EXIT_CODE --patient ID --log LOG -- OUTPUT...
        after the stage's command failed with EXIT_CODE: the record (reason: the last line of
        LOG) into every OUTPUT, exit 0. An exit code of 126/127 (command not found) or >= 128
        (killed by a signal: an interrupted run) is not this patient's failure: exit with it,
        so the job fails as usual.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

NOTE = "written by the workflow in place of a result: this patient failed at the stage below; see reason and log"
_ERROR_PREFIX = re.compile(r"^(?:vcs(?: [a-z]+)?: )?error: ")


def make_record(stage: str, reason: str, *, patient: str, log: str | None, exit_code: int | None = None) -> dict:
    """The failure record of one patient's stage."""
    return {
        "failed": True,
        "stage": stage,
        "reason": reason,
        "patient": patient,
        "log": str(Path(log).resolve()) if log else None,
        "exit_code": exit_code,
        "note": NOTE,
    }


def read_record(path: str | Path) -> dict | None:
    """The failure record held by ``path``, or None (a result, a binary file, a missing file)."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(1 << 16)
    except OSError:
        return None
    if not head.lstrip().startswith(b"{"):
        return None
    try:
        data = json.loads(head.decode("utf-8"))
    except (UnicodeDecodeError, ValueError):
        return None
    if isinstance(data, dict) and data.get("failed") is True and isinstance(data.get("stage"), str):
        return data
    return None


def write_record(record: dict, paths: list[str]) -> None:
    """Write ``record`` (JSON) into every path, replacing whatever a failed command left there."""
    text = json.dumps(record, indent=1) + "\n"
    for p in paths:
        path = Path(p)
        path.parent.mkdir(parents=True, exist_ok=True)
        if path.is_dir():  # a directory() output: the record inside it
            path = path / "FAILED.json"
        path.write_text(text)


def last_error_line(log: str | Path) -> str:
    """The last non-empty line of a log (the one-line error of `vcs`), without 'vcs fit: error: '."""
    try:
        lines = [ln.strip() for ln in Path(log).read_text(errors="replace").splitlines() if ln.strip()]
    except OSError:
        return "no log"
    if not lines:
        return "the command failed without a message"
    return _ERROR_PREFIX.sub("", lines[-1])[:500]


def _append_log(log: str | None, line: str) -> None:
    if log:
        with open(log, "a") as fh:
            fh.write(line + "\n")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="_failure.py", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    prop = sub.add_parser("propagate")
    rec = sub.add_parser("record")
    rec.add_argument("stage")
    rec.add_argument("exit_code", type=int)
    for p in (prop, rec):
        p.add_argument("--patient", required=True)
        p.add_argument("--log")
        p.add_argument("outputs", nargs="+")
    prop.add_argument("--upstream", nargs="+", required=True)
    args = parser.parse_args(argv)

    if args.command == "propagate":
        for up in args.upstream:
            record = read_record(up)
            if record is not None:
                write_record(record, args.outputs)
                _append_log(
                    args.log,
                    f"not run: {args.patient} failed at an earlier stage ({record['stage']}): {record['reason']}",
                )
                return 0
        return 1

    code = args.exit_code
    if code in (126, 127) or code >= 128:
        _append_log(args.log, f"exit code {code}: the command did not run or was interrupted (not recorded)")
        return code
    reason = f"{args.stage} failed: {last_error_line(args.log) if args.log else f'exit code {code}'}"
    write_record(make_record(args.stage, reason, patient=args.patient, log=args.log, exit_code=code), args.outputs)
    _append_log(args.log, f"recorded as a failure of {args.patient} at the {args.stage} stage (exit code {code})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
