"""The configuration reference (docs/guide/configuration.md) cannot drift: its keys are the schema's
and config/config.yaml's, every key has a description, the CLI reference lists every command."""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "docs" / "_ext"))  # the generators of the pages: vcsdocs


import vcsdocs
import yaml


def test_reference_keys_equal_schema_and_config_yaml_keys():
    page = [row["key"] for row in vcsdocs.config_reference_rows()]
    schema = list(vcsdocs.schema_keys())
    config = list(vcsdocs.config_yaml_keys())
    assert len(page) == len(set(page))
    assert set(page) == set(schema) == set(config)
    assert page == schema  # the page lists the keys in the schema's order


def test_every_config_key_has_a_description_and_its_config_value():
    rows = vcsdocs.config_reference_rows()
    assert len(rows) > 100
    assert [r["key"] for r in rows if not r["description"]] == []
    values = vcsdocs.config_yaml_keys()
    for r in rows:
        assert r["config"] == vcsdocs._fmt_value(values[r["key"]])


def test_patients_reference_lists_every_schema_column():
    schema = yaml.safe_load((ROOT / "workflow" / "schemas" / "patients.schema.yaml").read_text())
    rows = vcsdocs.patients_reference_rows()
    assert [r["column"] for r in rows] == list(schema["properties"])
    assert all(r["description"] for r in rows)


def test_cli_reference_lists_every_command_with_its_options():
    commands = vcsdocs.cli_commands()
    assert {"fit", "ends", "coords", "cartesian", "wall", "grid", "lumen", "phantom", "sensitivity"} <= set(commands)
    fit = {r["option"] for r in vcsdocs.cli_option_rows(commands["fit"])}
    assert any("--inlet" in o for o in fit) and any("--units" in o for o in fit)


def test_the_pages_use_the_generators():
    docs = ROOT / "docs"
    assert "{vcs-config-reference}" in (docs / "guide" / "configuration.md").read_text()
    assert "{vcs-patients-reference}" in (docs / "guide" / "patients-sheet.md").read_text()
    assert "{vcs-cli-reference}" in (docs / "guide" / "cli.md").read_text()
