"""bench/_table.py writes the docs' result files: what it writes the docs extension reads, and every
file of docs/data/bench says whether a bench script wrote it or it was transcribed (and then how
to re-measure it, or which bench script run regenerates the file)."""

import json
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "docs" / "_ext"))  # the generators of the pages: vcsdocs
sys.path.insert(0, str(ROOT / "bench"))  # the bench scripts' shared table writer: _table


import _table
import vcsdocs


def test_write_table_writes_what_the_directive_reads(tmp_path):
    command = ".venv/bin/python bench/fit_table.py --json docs/data/bench/fit_table.json"
    path = _table.write_table(
        tmp_path / "sub" / "t.json",
        command=command,
        measured="one run",
        columns=["mesh", "L"],
        rows=[["tube", 9], ["aorta", "12"]],
        notes=["a note with `code`"],
    )
    data = vcsdocs.read_bench_table(path)
    assert data["command"] == command and data["source"] == f"written by {command}"
    assert data["rows"] == [["tube", "9"], ["aorta", "12"]]
    assert data["measured"].endswith("; one run") and f"{os.cpu_count()} cores" in data["measured"]
    assert "load " in data["measured"] and data["notes"] == ["a note with `code`"]


def test_write_table_refuses_a_short_row(tmp_path):
    try:
        _table.write_table(tmp_path / "t.json", command="c", measured="m", columns=["a", "b"], rows=[["x"]])
    except ValueError as e:
        assert "2 cells" in str(e)
    else:
        raise AssertionError("a row shorter than the columns was written")


def test_every_result_file_says_where_its_numbers_come_from():
    for f in sorted((ROOT / "docs" / "data" / "bench").glob("*.json")):
        data = json.loads(f.read_text())
        source = data["source"]
        if source.startswith("written by "):
            assert source == f"written by {data['command']}", f.name
        else:
            assert source.startswith("transcribed from the measured run of "), f.name
            regenerate = f"regenerate with: `{data['command']}`" in source
            if regenerate:  # the bench script writes this very file when run again
                assert data["command"].endswith(f" --json docs/data/bench/{f.name}"), f.name
                script = next(w for w in data["command"].split() if w.startswith("bench/"))
                assert '"--json"' in (ROOT / script).read_text(), f"{f.name}: {script} has no --json"
            remeasure = f"re-measure with: `{data['command']}`" in source
            no_command = f"no single command re-measures it yet: {data['command']}" in source
            assert regenerate or remeasure or no_command, f.name
