"""The measured tables of the docs (docs/data/bench/*.json): each names the command that produced it
(a bench/ script, a test, a shipped command), and each is shown on a page."""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "docs" / "_ext"))  # the generators of the pages: vcsdocs


import json

DOCS = ROOT / "docs"


def test_every_result_file_names_an_existing_command_and_is_shown():
    files = sorted((DOCS / "data" / "bench").glob("*.json"))
    assert len(files) >= 15
    pages = "\n".join(p.read_text() for p in DOCS.rglob("*.md"))
    for f in files:
        data = json.loads(f.read_text())
        assert data["command"] and data["measured"], f.name
        assert all(len(row) == len(data["columns"]) for row in data["rows"]), f.name
        words = data["command"].replace(",", " ").replace(";", " ").replace("(", " ").replace(")", " ").split()
        named = [w.rstrip(":") for w in words if "/" in w and "." in w]
        assert named, f"{f.name}: the command names no file of the repository"
        for path in named:
            if path.startswith(("bench/", "tests/", "scripts/", "config/")):
                assert (ROOT / path).exists(), f"{f.name}: {path} does not exist"
        assert f"data/bench/{f.name}" in pages, f"{f.name} is on no page"
