"""Sphinx directives that generate the reference pages from their one source.

* ``vcs-config-reference``: every key of ``workflow/schemas/config.schema.yaml`` (its description,
  type and range) with its value in ``config/config.yaml`` and the value taken when it is left out
  (the schema's default, or ``vcs.cfd.DEFAULTS`` for the ``cfd`` block);
* ``vcs-patients-reference``: the columns of ``workflow/schemas/patients.schema.yaml``;
* ``vcs-cli-reference``: every ``vcs`` subcommand from the argparse parsers (``vcs.cli.main``);
* ``vcs-bench-table FILE``: a measured table from a JSON result file (``docs/data/bench/``), with
  the command that produced it;
* ``vcs-errors``: the one-line errors a user can meet (``docs/data/errors.yaml``, checked against
  the code by ``tests/docs/test_errors_catalogue.py``).

The functions that read the sources (``config_reference_rows``, ``config_yaml_keys``, ...) are
plain Python so that the tests under ``tests/docs/`` check the same rows the pages show.
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path
from typing import Any

import yaml
from docutils import nodes
from docutils.parsers.rst import Directive, directives

ROOT = Path(__file__).resolve().parents[2]
CONFIG_SCHEMA = ROOT / "workflow" / "schemas" / "config.schema.yaml"
PATIENTS_SCHEMA = ROOT / "workflow" / "schemas" / "patients.schema.yaml"
CONFIG_YAML = ROOT / "config" / "config.yaml"
DOCS = ROOT / "docs"

# ---------------------------------------------------------------------------------------------
# sources


def _load(path: Path) -> Any:
    return yaml.safe_load(path.read_text())


def _resolve(node: dict, schema: dict) -> dict:
    """A schema node with a local ``$ref`` merged in (the node's own keys win)."""
    ref = node.get("$ref")
    if not ref or not ref.startswith("#/$defs/"):
        return node
    merged = dict(schema["$defs"][ref.rsplit("/", 1)[1]])
    merged.update({k: v for k, v in node.items() if k != "$ref"})
    return merged


def _schema_leaves(node: dict, schema: dict, prefix: str = ""):
    node = _resolve(node, schema)
    if node.get("type") == "object" and "properties" in node:
        for key, sub in node["properties"].items():
            yield from _schema_leaves(sub, schema, f"{prefix}{key}.")
    else:
        yield prefix[:-1], node


def schema_keys(schema: dict | None = None) -> dict[str, dict]:
    """Dotted key -> schema node of every leaf key of the config schema."""
    schema = schema or _load(CONFIG_SCHEMA)
    return dict(_schema_leaves(schema, schema))


def _yaml_leaves(d: dict, prefix: str = ""):
    for key, value in d.items():
        if isinstance(value, dict) and value:
            yield from _yaml_leaves(value, f"{prefix}{key}.")
        else:
            yield f"{prefix}{key}", value


def config_yaml_keys(path: Path = CONFIG_YAML) -> dict[str, Any]:
    """Dotted key -> value of every leaf key of config/config.yaml."""
    return dict(_yaml_leaves(_load(path)))


def _fmt_value(v: Any) -> str:
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return v
    return json.dumps(v)


def _allowed(node: dict, schema: dict) -> str:
    node = _resolve(node, schema)
    if "oneOf" in node:
        return " or ".join(_allowed(alt, schema) for alt in node["oneOf"])
    if "const" in node:
        return _fmt_value(node["const"])
    if "enum" in node:
        return " | ".join(_fmt_value(e) for e in node["enum"])
    kind = node.get("type", "")
    if kind == "array":
        items = node.get("items", {})
        inner = _allowed(items, schema) if items else "any"
        n = node.get("minItems")
        size = f"{n} " if n is not None and n == node.get("maxItems") else ""
        return f"list of {size}({inner})"
    lo = node.get("minimum")
    lo_x = node.get("exclusiveMinimum")
    hi = node.get("maximum")
    hi_x = node.get("exclusiveMaximum")
    left = f"[{_fmt_value(lo)}" if lo is not None else (f"({_fmt_value(lo_x)}" if lo_x is not None else "")
    right = f"{_fmt_value(hi)}]" if hi is not None else (f"{_fmt_value(hi_x)})" if hi_x is not None else "")
    rng = f" in {left or '(-inf'}, {right or 'inf)'}" if (left or right) else ""
    if kind == "string" and "pattern" in node:
        return "string (checked)"
    return f"{kind}{rng}" if kind else "any"


def _cfd_default(dotted: str) -> tuple[bool, Any]:
    from vcs.cfd import DEFAULTS

    node: Any = DEFAULTS
    for part in dotted.split(".")[1:]:
        if not isinstance(node, dict) or part not in node:
            return False, None
        node = node[part]
    return True, node


def config_reference_rows() -> list[dict[str, str]]:
    """One row per configuration key, in the schema's order: what the reference page shows."""
    schema = _load(CONFIG_SCHEMA)
    values = config_yaml_keys()
    rows = []
    for key, node in schema_keys(schema).items():
        node = _resolve(node, schema)
        if "default" in node:
            default = _fmt_value(node["default"])
        elif key.startswith("cfd."):
            found, value = _cfd_default(key)
            default = f"{_fmt_value(value)} (vcs.cfd.DEFAULTS)" if found else "-"
        else:
            default = "required"
        rows.append(
            {
                "key": key,
                "allowed": _allowed(node, schema),
                "config": _fmt_value(values.get(key, "-")),
                "default": default,
                "description": " ".join(str(node.get("description", "")).split()),
            }
        )
    return rows


def patients_reference_rows() -> list[dict[str, str]]:
    """One row per column of the patients sheet (workflow/schemas/patients.schema.yaml)."""
    schema = _load(PATIENTS_SCHEMA)
    required = set(schema.get("required", []))
    rows = []
    for key, node in schema["properties"].items():
        rows.append(
            {
                "column": key,
                "required": "yes" if key in required else "no",
                "allowed": _allowed(node, schema),
                "description": " ".join(str(node.get("description", "")).split()),
            }
        )
    return rows


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def cli_commands() -> dict[str, argparse.ArgumentParser]:
    """``vcs`` subcommand name -> its parser, in the order of ``vcs --help``."""
    from vcs.cli.main import build_parser

    return _subparsers(build_parser())


def cli_option_rows(parser: argparse.ArgumentParser) -> list[dict[str, str]]:
    rows = []
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction | argparse._SubParsersAction) or action.help == argparse.SUPPRESS:
            continue
        name = ", ".join(action.option_strings) if action.option_strings else (action.metavar or action.dest)
        if action.choices:
            kind = " | ".join(str(c) for c in action.choices)
        elif action.nargs == 0:
            kind = "flag"
        else:
            kind = str(action.metavar or action.dest.upper())
            if action.nargs in ("+", "*"):
                kind += " ..."
        default = action.default
        shown = "" if default in (None, argparse.SUPPRESS, False) or action.nargs == 0 else _fmt_value(default)
        rows.append({"option": name, "value": kind, "default": shown, "help": (action.help or "") % vars(action)})
    return rows


# ---------------------------------------------------------------------------------------------
# rendering


_CODE = re.compile(r"`([^`]+)`")


def _inline(text: str) -> list[nodes.Node]:
    """Text with ``code`` spans (single backticks) as literal nodes."""
    out: list[nodes.Node] = []
    pos = 0
    for m in _CODE.finditer(text):
        if m.start() > pos:
            out.append(nodes.Text(text[pos : m.start()]))
        out.append(nodes.literal(m.group(1), m.group(1)))
        pos = m.end()
    if pos < len(text):
        out.append(nodes.Text(text[pos:]))
    return out


def _table(headers: list[str], rows: list[list[str]], widths: list[int] | None = None, code_cols=()) -> nodes.table:
    table = nodes.table(classes=["vcs-generated"])
    group = nodes.tgroup(cols=len(headers))
    table += group
    for w in widths or [1] * len(headers):
        group += nodes.colspec(colwidth=w)
    head = nodes.thead()
    group += head
    row = nodes.row()
    for h in headers:
        row += nodes.entry("", nodes.paragraph("", "", *_inline(h)))
    head += row
    body = nodes.tbody()
    group += body
    for cells in rows:
        row = nodes.row()
        for i, c in enumerate(cells):
            content = [nodes.literal(c, c)] if i in code_cols and c else _inline(str(c))
            row += nodes.entry("", nodes.paragraph("", "", *content))
        body += row
    return table


def _para(text: str) -> nodes.paragraph:
    return nodes.paragraph("", "", *_inline(text))


class ConfigReference(Directive):
    has_content = False

    def run(self):
        env = self.state.document.settings.env
        for p in (CONFIG_SCHEMA, CONFIG_YAML):
            env.note_dependency(str(p))
        out: list[nodes.Node] = []
        groups: dict[str, list[dict[str, str]]] = {}
        for row in config_reference_rows():
            groups.setdefault(row["key"].split(".")[0], []).append(row)
        schema = _load(CONFIG_SCHEMA)
        for group, rows in groups.items():
            out.append(nodes.rubric("", "", nodes.literal(group, group)))
            desc = schema["properties"][group].get("description")
            if desc:
                out.append(_para(" ".join(desc.split())))
            out.append(
                _table(
                    ["key", "allowed", "config.yaml", "left out", "description"],
                    [[r["key"], r["allowed"], r["config"], r["default"], r["description"]] for r in rows],
                    widths=[22, 18, 12, 14, 34],
                    code_cols=(0, 2),
                )
            )
        return out


class PatientsReference(Directive):
    has_content = False

    def run(self):
        self.state.document.settings.env.note_dependency(str(PATIENTS_SCHEMA))
        rows = patients_reference_rows()
        return [
            _table(
                ["column", "required", "allowed", "description"],
                [[r["column"], r["required"], r["allowed"], r["description"]] for r in rows],
                widths=[20, 8, 20, 52],
                code_cols=(0,),
            )
        ]


class CliReference(Directive):
    has_content = False

    def run(self):
        from vcs.cli.main import build_parser

        out: list[nodes.Node] = []
        top = build_parser()
        out.append(nodes.literal_block(top.format_usage(), top.format_usage().strip()))
        for name, parser in cli_commands().items():
            section_id = nodes.make_id(f"vcs-{name}")
            title = f"vcs {name}"
            sec = nodes.section(ids=[section_id], names=[nodes.fully_normalize_name(title)])
            sec += nodes.title(title, "", nodes.literal(title, title))
            if parser.description:
                sec += _para(" ".join(parser.description.split()))
            usage = parser.format_usage().strip()
            sec += nodes.literal_block(usage, usage)
            rows = cli_option_rows(parser)
            sec += _table(
                ["option", "value", "default", "meaning"],
                [[r["option"], r["value"], r["default"], r["help"]] for r in rows],
                widths=[20, 18, 10, 52],
                code_cols=(0,),
            )
            self.state.document.note_implicit_target(sec, sec)
            out.append(sec)
        return out


def read_bench_table(path: Path) -> dict[str, Any]:
    """A result file of docs/data/bench (written by bench/_table.py's ``write_table``, or transcribed):
    its command, measured, columns and rows, every row as long as the columns."""
    data = json.loads(Path(path).read_text())
    for field in ("command", "measured", "columns", "rows"):
        if field not in data:
            raise ValueError(f"{path}: no {field!r} (every result file names its command)")
    bad = [i for i, row in enumerate(data["rows"]) if len(row) != len(data["columns"])]
    if bad:
        raise ValueError(f"{path}: rows {bad} do not have {len(data['columns'])} cells")
    return data


class BenchTable(Directive):
    required_arguments = 1
    has_content = False
    option_spec = {"columns": directives.unchanged}

    def run(self):
        env = self.state.document.settings.env
        src = DOCS / self.arguments[0]
        env.note_dependency(str(src))
        try:
            data = read_bench_table(src)
        except ValueError as e:
            raise self.error(str(e)) from None
        out: list[nodes.Node] = [
            _table(data["columns"], [[_fmt_value(c) for c in row] for row in data["rows"]]),
        ]
        source = data.get("source", "")
        if source.startswith("transcribed"):  # names its re-measuring command itself
            made = f"{source[0].upper()}{source[1:]}; measured {data['measured']}."
        else:
            made = f"Produced by `{data['command']}`; measured {data['measured']}."
        out.append(_para(made))
        for note in data.get("notes", []):
            out.append(_para(note))
        return out


class ErrorTable(Directive):
    has_content = False
    option_spec = {"group": directives.unchanged}

    def run(self):
        src = DOCS / "data" / "errors.yaml"
        self.state.document.settings.env.note_dependency(str(src))
        entries = _load(src)["errors"]
        group = self.options.get("group")
        rows = [[e["input"], e["message"]] for e in entries if group is None or e.get("group") == group]
        return [_table(["input", "what the user sees (and what to do)"], rows, widths=[30, 70])]


_LITERAL_SPAN = re.compile(r"(``.*?``)")


def escape_bars(lines: list[str]) -> list[str]:
    """Docstrings write norms as plain text (``|x - y|``), which reST reads as a substitution:
    escape those bars, leaving literal blocks, doctest lines, line blocks and ````code```` alone."""
    out = []
    literal_indent: int | None = None
    for line in lines:
        stripped = line.lstrip()
        indent = len(line) - len(stripped)
        if literal_indent is not None:
            if stripped and indent <= literal_indent:
                literal_indent = None
            else:
                out.append(line)
                continue
        if "|" in line and not stripped.startswith(("| ", ">>>", "...")):
            parts = _LITERAL_SPAN.split(line)
            line = "".join(p if p.startswith("``") else p.replace("|", "\\|") for p in parts)
        if stripped.endswith("::"):
            literal_indent = indent
        out.append(line)
    return out


def _process_docstring(app, what, name, obj, options, lines):
    lines[:] = escape_bars(lines)


def setup(app):
    app.connect("autodoc-process-docstring", _process_docstring, priority=400)
    app.add_directive("vcs-config-reference", ConfigReference)
    app.add_directive("vcs-patients-reference", PatientsReference)
    app.add_directive("vcs-cli-reference", CliReference)
    app.add_directive("vcs-bench-table", BenchTable)
    app.add_directive("vcs-errors", ErrorTable)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
