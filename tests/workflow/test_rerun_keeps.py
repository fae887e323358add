"""Nothing a user had is lost to an interrupted rerun of the workflow (issue 22, item 3).

Snakemake removes a job's outputs before the job starts; workflow/rules/keep.smk keeps them aside
as hard links and puts them back when the job does not finish. An aorta phantom is fitted and
walled (no OpenFOAM needed), then a rerun with other wall knots is stopped (Ctrl-C to the whole
process group, as a terminal does) while the fit runs: every earlier output is back byte for byte
with its time stamp, nothing is left in .snakemake/vcs-kept, and the next run reruns the fit and
finishes. SIGTERM to Snakemake (a batch system) lets the running fit finish: a whole new fit, the
wall not yet rerun is the earlier one. After SIGKILL (nothing of Snakemake runs), the next run
puts the earlier outputs back before it starts.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time

import pytest
from conftest import SNAKEFILE, SNAKEMAKE, make_workdir

IDS = ("a0",)
TARGETS = [f"results/patients/{i}/wall/wall.stl" for i in IDS]


def _outputs(wd) -> dict[str, tuple[bytes, int]]:
    return {
        str(p.relative_to(wd.path)): (p.read_bytes(), p.stat().st_mtime_ns)
        for i in IDS
        for p in sorted((wd.path / "results" / "patients" / i).rglob("*"))
        if p.is_file()
    }


@pytest.mark.parametrize("how", ["SIGINT to the process group", "SIGTERM to snakemake", "SIGKILL to the process group"])
def test_an_interrupted_rerun_puts_every_earlier_output_back(tmp_path, how):
    wd = make_workdir(
        tmp_path, [{"id": i, "mesh": f"results/demo/aorta_seed{k}.stl", "units": "mm"} for k, i in enumerate(IDS)]
    )
    wd.update_config("demo", "resolution", 1.0)  # fits of ~2-4 s each: time to interrupt one
    wd.snakemake("-c1", *TARGETS)
    before = _outputs(wd)
    assert len(before) == 5
    wd.update_config("vcs", "K", 15)  # reruns the fit and the wall
    cmd = [
        str(SNAKEMAKE),
        "-s",
        str(SNAKEFILE),
        "-d",
        str(wd.path),
        "--configfile",
        str(wd.config_file),
        "-c1",
        *TARGETS,
    ]
    # SIGINT at its default, as under a terminal, even when this suite runs as a background job
    # (whose shell set it to ignored: then nothing would notice the Ctrl-C and the run would finish)
    p = subprocess.Popen(
        cmd,
        cwd=wd.path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    log = wd.path / "results" / "logs" / "vcs_fit" / f"{IDS[0]}.log"
    deadline = time.monotonic() + 120
    while not (wd.path / ".snakemake" / "vcs-kept").is_dir() or not log.exists() or log.stat().st_size:
        assert time.monotonic() < deadline and p.poll() is None, p.communicate()
        time.sleep(0.02)
    # inside the fit (~1.7 s on a quiet machine, ~0.75 s of it Python's start-up): vcs's own
    # interrupt handling is installed by 0.6 s and the fit runs on for about a second more
    time.sleep(0.6)
    assert not (wd.path / "results" / "patients" / IDS[0] / "fit" / "model.json").exists()
    if how.startswith("SIGTERM"):
        p.send_signal(signal.SIGTERM)
    else:
        os.killpg(p.pid, getattr(signal, how.split()[0]))
    out, err = p.communicate(timeout=120)
    assert p.returncode != 0, f"the interrupt did not stop the run; its log:\n{err[-3000:]}"
    now = _outputs(wd)
    if how.startswith("SIGINT"):  # the fit stops at once: its earlier outputs are put back
        if "of interrupted jobs put back as they were before this run" not in err:
            # Snakemake may have seen the fit fail before it saw the Ctrl-C: then the earlier
            # outputs are in previous/, whole (nothing lost either way)
            assert "kept in previous/" in err, err[-3000:]
            aside = {k.replace("/previous/", "/", 1): v for k, v in now.items() if "/previous/" in k}
            now = {**{k: v for k, v in now.items() if "/previous/" not in k}, **aside}
        assert now == before, err[-3000:]
    elif how.startswith("SIGKILL"):  # nothing runs after a kill: the next run settles first
        kept = wd.path / ".snakemake" / "vcs-kept"
        assert {k: v for k, v in before.items() if "/fit/" in k} == {
            k: ((kept / k).read_bytes(), (kept / k).stat().st_mtime_ns) for k in before if "/fit/" in k
        }  # the earlier fit is whole, aside
        assert not (wd.path / "results" / "patients" / IDS[0] / "fit" / "model.json").exists()
        wd.snakemake("--unlock")
        r = wd.snakemake("-c1", "--rerun-incomplete", *TARGETS)
        assert "of interrupted jobs put back as they were before this run" in r.stderr
        return
    else:  # Snakemake lets the running fit finish, then stops: a whole new fit, the earlier wall
        assert "Will exit after finishing currently running jobs" in err
        wall = "results/patients/a0/wall/wall.stl"
        assert now[wall] == before[wall]
        assert json.loads(now["results/patients/a0/fit/model.json"][0])["wall"]["K"] == 15
    assert not (wd.path / ".snakemake" / "vcs-kept").exists()
    r = wd.snakemake("-c1", "--rerun-incomplete", *TARGETS)  # as the profiles do
    after = _outputs(wd)
    assert sorted(after) == sorted(before)
    assert after["results/patients/a0/fit/model.json"][0] != before["results/patients/a0/fit/model.json"][0], r.stderr
