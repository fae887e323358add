"""Meshing a rendered case and checking the mesh: blockMesh, snappyHexMesh (jet refinement, wall
prism layers), checkMesh, and the patch check (every STL solid became a patch of enough faces,
nothing leaked into the background box), with the mesh's part of ``status.json``."""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

from vcs.cfd.case import patch_role
from vcs.cfd.foamfiles import parse_check_mesh_volume, parse_layer_summary, read_boundary
from vcs.cfd.utilities import Stop, _Runner, _utility_failure


def mesh_case(case_dir: Path, state: dict[str, Any], status: dict[str, Any], run: _Runner) -> None:
    """Mesh the case and check it; fills ``status`` (``mesh``, ``cells``, ``lumen_volume_m3``,
    ``mesh_ok``, ``stage``).

    blockMesh, snappyHexMesh -overwrite, the prism-layer report, the patch check
    (:func:`patch_check`), checkMesh (:func:`_check_mesh`).

    Raises
    ------
    Stop
        A utility failed, a patch was lost or under-resolved or the mesh leaked (reported before a
        failed checkMesh: checkMesh calls such a mesh OK), or checkMesh failed.
    """
    if run(["blockMesh"], "blockMesh").returncode != 0:
        raise Stop(_utility_failure(case_dir, "blockMesh"), "blockMesh")
    if run(["snappyHexMesh", "-overwrite"], "snappyHexMesh").returncode != 0:
        raise Stop(_utility_failure(case_dir, "snappyHexMesh"), "snappyHexMesh")
    status["mesh"].update(_mesh_report(case_dir, state))
    patches = patch_check(case_dir, state)
    status["mesh"]["patches"] = patches["patches"]
    status["mesh"]["background_faces"] = patches["background_faces"]
    run(["checkMesh"], "checkMesh")
    ok, cells, why = _check_mesh(case_dir / "logs" / "log.checkMesh")
    status["cells"] = cells
    check_log = (case_dir / "logs" / "log.checkMesh").read_text(errors="replace")
    status["lumen_volume_m3"] = parse_check_mesh_volume(check_log)
    if not patches["ok"]:  # a lost end or a leak: say so before anything else (checkMesh says OK)
        status["mesh_ok"] = False
        status["stage"] = "mesh"
        raise Stop(patches["reason"], "snappyHexMesh")
    if not ok:
        status["mesh_ok"] = False
        raise Stop(why, "checkMesh")
    status["mesh_ok"] = True


def _check_mesh(log: Path) -> tuple[bool, int | None, str]:
    """(mesh OK, number of cells, why not) from a checkMesh log."""
    txt = log.read_text(errors="replace")
    m = re.search(r"^\s*cells:\s+(\d+)", txt, re.M)
    cells = int(m.group(1)) if m else None
    if "Mesh OK." in txt:
        return True, cells, ""
    fails = re.findall(r"\*\*\*.*", txt)
    m = re.search(r"Failed (\d+) mesh checks", txt)
    why = (f"checkMesh failed {m.group(1)} check(s): " if m else "checkMesh did not report 'Mesh OK.': ") + "; ".join(
        f.strip() for f in fails[:5]
    )
    return False, cells, why


def _mesh_report(case_dir: Path, state: dict[str, Any]) -> dict[str, Any]:
    """What status.json keeps of the mesh: prism-layer coverage (snappyHexMesh's layer table)
    and the jet refinement region."""
    m = state["cfd"]["mesh"]
    log = case_dir / "logs" / "log.snappyHexMesh"
    layers: dict[str, Any] = {"requested": int(m["layers"])}
    if int(m["layers"]) > 0:
        rep: dict[str, Any] = parse_layer_summary(log.read_text(errors="replace") if log.exists() else "")
        layers.update(rep)
        walls = [p for name, p in rep["patches"].items() if patch_role(name) == "wall"]
        if walls:
            faces = sum(p["faces"] for p in walls)
            layers["mean_layers"] = sum(p["mean_layers"] * p["faces"] for p in walls) / faces
            layers["coverage"] = layers["mean_layers"] / int(m["layers"])  # layers added / requested
        else:  # no layer table: snappyHexMesh added none
            layers["coverage"] = 0.0
    return {"layers": layers, "jet_refinement": state.get("jet_region")}


def patch_check(case_dir: Path, state: dict[str, Any]) -> dict[str, Any]:
    """Did every STL solid become a patch of at least ``mesh.min_patch_faces`` faces, and is the
    ``background`` patch (the blockMesh box) empty? Read from the meshed case's
    ``constant/polyMesh/boundary``.

    snappyHexMesh drops an end whose cap is small against the cells around it and still writes a
    mesh that checkMesh calls OK; the solver then fails far from the cause ("Unable to set
    reference cell", a floating point exception). A non-empty ``background`` patch means the
    mesh leaked out of the vessel into the box.

    Parameters
    ----------
    case_dir : Path
        A case after snappyHexMesh (ASCII polyMesh).
    state : dict
        Case description (``solids`` with role, area and cell size, ``mesh_sizing``).

    Returns
    -------
    dict
        ``ok`` (bool), ``patches``: {solid: {``role``, ``faces`` (0 when missing),
        ``min_faces``, ``cell_size_m`` (at that patch), ``radius_m`` (equivalent radius of an
        end cap)}}, ``background_faces`` (int or None), ``problems`` (list of str), ``reason``
        (one line: what happened and what to change; None when ok).
    """
    sizing = state.get("mesh_sizing") or {}
    min_faces = int(sizing.get("min_patch_faces", state["cfd"]["mesh"].get("min_patch_faces", 1)))
    try:
        boundary = read_boundary(case_dir / "constant" / "polyMesh")
    except (OSError, ValueError) as exc:
        why = f"no readable mesh boundary after snappyHexMesh ({exc})"
        return {"ok": False, "patches": {}, "background_faces": None, "problems": [why], "reason": why}
    patches: dict[str, Any] = {}
    problems = []
    for s in state["solids"]:
        faces = int(boundary.get(s["name"], {}).get("nFaces", 0))
        info: dict[str, Any] = {"role": s["role"], "faces": faces, "min_faces": min_faces}
        h = s.get("cell_size_m")
        if h is not None:
            info["cell_size_m"] = h
        if s["role"] in ("inlet", "outlet") and s.get("area_m2"):
            info["radius_m"] = math.sqrt(s["area_m2"] / math.pi)
        patches[s["name"]] = info
        if faces >= min_faces:
            continue
        what = "lost in meshing: 0 faces" if faces == 0 else f"under-resolved in meshing: {faces} faces"
        text = f"{s['name']} {what} (minimum {min_faces})"
        if h is not None and "radius_m" in info:
            text += f"; cell size {h * 1e3:.3g} mm vs {s['name']} radius {info['radius_m'] * 1e3:.3g} mm"
        elif h is not None:
            text += f"; cell size {h * 1e3:.3g} mm"
        problems.append(text)
    bg = int(boundary.get("background", {}).get("nFaces", 0))  # snappyHexMesh removes an empty patch
    if bg:
        problems.append(
            f"the mesh leaked out of the vessel: the background patch (the blockMesh box) has {bg} faces "
            "(must be 0); the wall STL is not closed or cfd.mesh.inside_point is outside the lumen"
        )
    reason = None
    if problems:
        source = (sizing.get("cell_size") or {}).get("source")
        lost = [p for p in problems if "in meshing" in p]
        advice = {
            "patient": "lower the patient's cell_size_mm in the patients sheet",
            "auto": "raise cfd.mesh.cells_across_end (or give a smaller cfd.mesh.cell_size)",
        }.get(str(source), "lower cfd.mesh.cell_size")
        if lost and all(p.startswith("branch") for p in lost):  # only side branches lost: their own refinement
            advice = "raise cfd.mesh.cells_across_branch (the branch ends' refinement)"
        reason = "; ".join(problems) + (f"; {advice}" if lost else "")
    return {"ok": not problems, "patches": patches, "background_faces": bg, "problems": problems, "reason": reason}
