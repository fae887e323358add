"""docs/data/errors.yaml (the troubleshooting page) against the code: every message it shows is
still produced there (its fixed fragments are found in vcs/, workflow/ or the Snakefile)."""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "docs" / "_ext"))  # the generators of the pages: vcsdocs


import re

import yaml

GROUPS = {"surface", "points", "cli", "workflow"}


def _code_text() -> str:
    files = [*ROOT.joinpath("vcs").rglob("*.py"), *ROOT.joinpath("workflow").rglob("*.py")]
    files += [*ROOT.joinpath("workflow").rglob("*.smk"), ROOT / "Snakefile"]
    text = "\n".join(p.read_text() for p in files)
    # a message split over source lines by implicit string concatenation reads as one
    return re.sub(r"""["']\s+(?:rf|fr|f|r)?["']""", "", text)


def test_every_catalogued_message_is_in_the_code():
    entries = yaml.safe_load((ROOT / "docs" / "data" / "errors.yaml").read_text())["errors"]
    assert len(entries) >= 40
    code = _code_text()
    missing = []
    for e in entries:
        assert set(e) == {"input", "message", "group", "code"}, e
        assert e["group"] in GROUPS and e["code"], e["input"]
        missing += [(e["input"], frag) for frag in e["code"] if frag not in code]
    assert missing == []
