"""`vcs ends`: list the candidate ends of a surface and the `vcs fit` options that choose two of them."""

from __future__ import annotations

import argparse
import shlex
from pathlib import Path
from typing import Any

from vcs.cli._args import atomic_file, output_file, write_json

# decimals of coordinates printed per unit: 0.01 mm, 0.001 cm, 0.00001 m
_DECIMALS = {"mm": 2, "cm": 3, "m": 5}


def ends_table(mesh: str | Path, units: str = "auto", cap_array: str | None = "auto") -> dict[str, Any]:
    """The candidate ends of a surface, as `vcs ends` prints and writes them (JSON-ready).

    The surface is read and reduced to the vessel's component exactly as `vcs fit` does
    with no end option (:func:`vcs.vessel.vessel_component`), so
    ``end:N`` here is ``end:N`` there.

    Parameters
    ----------
    mesh : str or Path
        Surface file (STL, VTP, VTK, PLY, OBJ).
    units : {"auto", "mm", "cm", "m"}
        Units of the file (as ``vcs fit --units``).
    cap_array : str or None
        Cell array labelling caps (``"auto"`` searches; None skips labelled caps).

    Returns
    -------
    dict
        ``mesh``, ``units``, ``units_source``, ``units_evidence``, ``cap_array``, ``n_open_loops``,
        ``lumen_radius`` (mesh units), ``candidates`` (per end: ``index``, ``select`` (``end:N``),
        ``kind``, ``label``, ``center``, ``radius``, ``normal`` (unit, into the lumen; None for none),
        ``n_triangles``, ``point`` (``x,y,z`` text)), ``suggested`` (``inlet``, ``outlet``,
        ``options``, ``automatic``: true when `vcs fit` picks these two with no end option),
        ``notes`` and ``warnings``. Coordinates and radii in the units of the mesh.

    Raises
    ------
    VCSInputError
        Unreadable mesh, unknown units or cap array.
    """
    from vcs.ends import list_ends
    from vcs.io import read_surface
    from vcs.vessel import vessel_component

    surf = vessel_component(read_surface(mesh, units))
    listing = list_ends(
        surf.vertices, surf.faces, surf.cell_data, cap_array=cap_array, lumen_radius=surf.lumen_radius_mm
    )
    s, dec = surf.scale_to_mm, _DECIMALS[surf.units]
    rows = []
    for i, c in enumerate(listing.candidates):
        center = c.end.center / s
        rows.append(
            {
                "index": i,
                "select": f"end:{i}",
                "kind": c.kind,
                "label": c.label,
                "center": [round(float(x), dec + 2) for x in center],
                "radius": round(float(c.radius / s), dec + 2),
                "normal": None if c.normal is None else [round(float(x), 4) for x in c.normal],
                "n_triangles": int(len(c.faces)),
                "point": ",".join(f"{x:.{dec}f}" for x in center),
            }
        )
    # the default of `vcs fit` when it has one (exactly two ends of one kind), else the two largest
    groups: dict[str, list[int]] = {}
    for i, c in enumerate(listing.candidates):
        groups.setdefault("closed" if c.kind in ("flat cap", "closed end") else c.kind, []).append(i)
    auto = next((g for g in groups.values() if len(g) >= 2), None)
    suggested: dict[str, Any] = {}
    if auto is not None or len(rows) >= 2:
        pool = auto if auto is not None else list(range(len(rows)))
        two = sorted(pool, key=lambda i: -listing.candidates[i].radius)[:2]
        suggested = {
            "inlet": f"end:{two[0]}",
            "outlet": f"end:{two[1]}",
            "options": f"--inlet end:{two[0]} --outlet end:{two[1]}",
            "point_options": f"--inlet={rows[two[0]]['point']} --outlet={rows[two[1]]['point']}",
            "automatic": auto is not None and len(auto) == 2,
        }
    return {
        "mesh": str(mesh),
        "units": surf.units,
        "units_source": surf.units_source,
        "units_evidence": surf.units_evidence,
        "cap_array": listing.cap_array,
        "n_open_loops": len(listing.loops),
        "lumen_radius": None if listing.lumen_radius is None else round(float(listing.lumen_radius / s), dec + 2),
        "candidates": rows,
        "suggested": suggested,
        "notes": listing.notes,
        "warnings": list(surf.warnings),
    }


def cmd_ends(args: argparse.Namespace) -> None:
    """Run `vcs ends`: print the candidate ends (index, kind, label, centre, radius, normal) and the
    `vcs fit` options that choose two of them; with ``-o`` also write them as JSON.

    Parameters
    ----------
    args : argparse.Namespace
        ``mesh``, ``units``, ``cap_array`` and ``output`` (JSON file or None); see :func:`ends_table`.

    Raises
    ------
    VCSInputError
        Bad input (reported by :func:`vcs.cli.main.main` as one line, exit code 2).
    """
    out = None if args.output is None else output_file(args.output, args.mesh, suffixes=(".json",))
    table = ends_table(args.mesh, args.units, None if args.cap_array == "none" else args.cap_array)
    u = table["units"]
    rows = table["candidates"]
    print(f"{args.mesh}: {len(rows)} candidate end(s); units {u} ({table['units_source']})")
    width = max([5, *(len(r["label"] or "") for r in rows)])
    if rows:
        print(
            f"{'end':>6}  {'kind':<12} {'label':<{width}} {'centre (' + u + ')':<34} {'radius':>9}  "
            "normal (into the lumen)"
        )
    for r in rows:
        c = ", ".join(f"{x:.{_DECIMALS[u]}f}" for x in r["center"])
        n = "-" if r["normal"] is None else "(" + ", ".join(f"{x:.2f}" for x in r["normal"]) + ")"
        print(
            f"{r['select']:>6}  {r['kind']:<12} {r['label'] or '-':<{width}} {'(' + c + ')':<34} "
            f"{r['radius']:>9.{_DECIMALS[u]}f}  {n}"
        )
    sug = table["suggested"]
    mesh = shlex.quote(str(args.mesh))
    if sug and sug["automatic"]:
        print(f"vcs fit {mesh} -o DIR finds these two ends by itself (the larger as inlet); to choose them:")
    elif sug:
        print("choose the inlet (tau = 0) and outlet (tau = 1) of the section, e.g. the two largest:")
    if sug:
        print(f"  vcs fit {mesh} -o DIR {sug['options']}")
        print(f"  vcs fit {mesh} -o DIR {sug['point_options']}")
        print("(in the patients sheet: inlet/outlet columns end:N, NAME=VALUE or x,y,z)")
    else:
        print("fewer than two ends found: give them as points, vcs fit MESH -o DIR --inlet=x,y,z --outlet=x,y,z")
    for w in table["warnings"]:
        print(f"warning: {w}")
    if out is not None:
        with atomic_file(out) as tmp:
            write_json(tmp, table)
        print(f"-> {out}")


def add_commands(subparsers: argparse._SubParsersAction) -> None:
    """Register `vcs ends` on the subparsers object of the `vcs` parser.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        As returned by :meth:`argparse.ArgumentParser.add_subparsers`.
    """
    e = subparsers.add_parser(
        "ends",
        help="list the candidate ends of a surface (open loops, labelled or flat caps, closed ends)",
        description="List the candidate ends of a surface, with the `vcs fit` options that choose two of them.",
    )
    e.add_argument("mesh", help="wall surface: STL, VTP, VTK, PLY or OBJ")
    e.add_argument("--units", default="auto", choices=["auto", "mm", "cm", "m"], help="units of the mesh (as vcs fit)")
    e.add_argument(
        "--cap-array", default="auto", help="cell array labelling caps (auto: ModelFaceID, CapID, ...; none: ignore)"
    )
    e.add_argument("-o", "--output", help="also write the list as .json (e.g. ends.json)")
    e.set_defaults(func=cmd_ends)
