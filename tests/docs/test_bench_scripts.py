"""The bench scripts print their table and, with ``--json PATH``, write the docs' table
(bench/_table.py ``emit`` / ``save``): checked on small synthetic results, without OpenFOAM."""

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench"))  # the bench scripts and their shared table writer: _table


import _table


def test_emit_prints_the_table_and_writes_the_docs_columns(tmp_path, capsys):
    made = []

    def rows():  # each row printed before the next is made
        for i in range(2):
            made.append(i)
            yield [f"p{i}", str(i), "yes"]
            assert capsys.readouterr().out.endswith(f"| p{i} | {i} | yes |\n")

    out = _table.emit(
        ["id", "n", "ok"],
        rows(),
        tmp_path / "t.json",
        "one run",
        command="bench/x.py --json t.json",
        json_columns=["id", "n"],
        json_row=lambda c: c[:-1],
    )
    assert out == [["p0", "0", "yes"], ["p1", "1", "yes"]] and made == [0, 1]
    data = json.loads((tmp_path / "t.json").read_text())
    assert data["columns"] == ["id", "n"] and data["rows"] == [["p0", "0"], ["p1", "1"]]
    assert data["command"] == "bench/x.py --json t.json" and data["measured"].endswith("; one run")


def test_emit_without_a_path_only_prints(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _table.emit(["a", "b"], [["1", "2"]])
    assert capsys.readouterr().out == "| a | b |\n|---|---|\n| 1 | 2 |\n"
    assert _table.save(None, columns=["a"], rows=[["1"]], measured="m") is None
    assert list(tmp_path.iterdir()) == []


def test_save_names_this_process_command_by_default(tmp_path):
    path = _table.save(tmp_path / "t.json", columns=["a"], rows=[["1"]], measured="m")
    assert json.loads(path.read_text())["command"] == _table.command_line()
