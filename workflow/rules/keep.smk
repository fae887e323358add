# Nothing a user had is lost to an interrupted or failed rerun (issue 22).
#
# Snakemake removes a job's outputs before the job starts. So, before any job runs (onstart), every
# existing output of the workflow's per-patient and atlas rules is kept aside as hard links (no
# copy; the same bytes, mode and modification time) in .snakemake/vcs-kept/. After the run
# (onsuccess/onerror, or at the next start when Snakemake itself was killed) each one is settled:
#   * its job was interrupted (Ctrl-C, a kill: Snakemake still marks the output incomplete): the
#     earlier output is put back whole, with its old time stamp; the next run reruns the job;
#   * its job failed (Snakemake removed the output and its record) or finished with a failure of
#     this patient (a failure record, a failed or not converged status.json, placeholder fields)
#     where the earlier output held a result: the earlier one is moved to previous/
#     (results/patients/<id>/previous/..., results/previous/atlas/...; the atlas never reads it);
#   * otherwise (unchanged, or a new result) the hard link is dropped.
# Each restore or move is said in one line on stderr.

import shutil
import zipfile

KEEP_DIR = Path(".snakemake") / "vcs-kept"
_KEEP_WILDCARD = re.compile(r"\{(\w+)(?:,[^{}]*)?\}")
sys.path.insert(0, os.path.join(VCS_REPO, "workflow", "scripts"))
import _failure  # noqa: E402  (standard library only)


def kept_units():
    """Every output path of the per-patient rules (for the sheet's patients) and of the atlas."""
    units = []
    for r in workflow.rules:
        for pattern in r.output:
            plain = _KEEP_WILDCARD.sub(r"{\1}", str(pattern))
            names = set(_KEEP_WILDCARD.findall(plain))
            if not names:
                units.append(plain)
            elif names == {"id"}:
                units.extend(expand(plain, id=PATIENT_IDS))
    return sorted(set(units))


def _link_tree(src, dst):
    """A mirror of ``src`` (file or directory) made of hard links (copies where links fail)."""
    dst.parent.mkdir(parents=True, exist_ok=True)
    if src.is_dir():
        shutil.copytree(src, dst, copy_function=_link_or_copy, symlinks=True)
    else:
        _link_or_copy(src, dst)


def _link_or_copy(src, dst):
    try:
        os.link(src, dst)
    except OSError:  # another file system, or links not allowed
        shutil.copy2(src, dst)


def _same(a, b):
    """Is ``a`` still the output that was kept as ``b``: the same files, not rewritten (the same
    inodes, or, where the keeping had to copy, the same sizes and modification times)?"""

    def same_file(x, y):
        if os.path.samefile(x, y):
            return True
        sx, sy = x.stat(), y.stat()
        return sx.st_size == sy.st_size and sx.st_mtime_ns == sy.st_mtime_ns

    try:
        if a.is_dir() != b.is_dir():
            return False
        if not a.is_dir():
            return same_file(a, b)
        fa = sorted(p.relative_to(a) for p in a.rglob("*") if not p.is_dir())
        fb = sorted(p.relative_to(b) for p in b.rglob("*") if not p.is_dir())
        return fa == fb and all(same_file(a / f, b / f) for f in fa)
    except OSError:
        return False


def is_failure(path):
    """Does this output say that its patient failed (rather than hold a result)?"""
    path = Path(path)
    if path.is_dir():
        return any((path / n).exists() for n in ("SETUP_FAILED.json", "FAILED.json"))
    if not path.is_file():
        return False
    if _failure.read_record(path) is not None:
        return True
    if path.name in ("status.json", "fields.json"):
        try:
            data = json.loads(path.read_text())
        except (OSError, ValueError):
            return False
        return bool(data.get("failed") or data.get("excluded") or data.get("converged") is False)
    if path.suffix == ".npz":
        try:
            with zipfile.ZipFile(path) as z:
                return "excluded.npy" in z.namelist()
        except (OSError, zipfile.BadZipFile):
            return False
    return False


def _patient_of(unit):
    m = re.match(r"results/patients/([^/]+)/", unit)
    return m.group(1) if m else None


def _remove(path):
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif path.exists() or path.is_symlink():
        path.unlink()


MANIFEST = "units.json"


def keep_outputs():
    """onstart: settle what a killed run left, then keep every existing output aside."""
    settle_kept()
    units = [u for u in kept_units() if Path(u).exists()]
    for unit in units:
        _link_tree(Path(unit), KEEP_DIR / unit)
    if units:  # what was kept, read back by settle_kept (also after a kill, whatever the next sheet)
        (KEEP_DIR / MANIFEST).write_text(json.dumps(units))


def _incomplete(units):
    """The units Snakemake marks as incomplete (a job started on them and did not finish)."""
    try:
        persistence = workflow.persistence
        if hasattr(persistence, "_clear_cache"):
            persistence._clear_cache()
        return set(persistence._filter_incomplete_keys(units))
    except Exception:  # another Snakemake's persistence: every missing output counts as interrupted
        return {u for u in units if not Path(u).exists()}


def previous_path(unit):
    """Where an earlier output is kept when a rerun replaced it by a failure."""
    rel = Path(unit).relative_to("results") if unit.startswith("results/") else Path(unit)
    if rel.parts[:1] == ("patients",) and len(rel.parts) > 2:
        return Path("results", *rel.parts[:2], "previous", *rel.parts[2:])
    return Path("results", "previous", *rel.parts)


def move_to_previous(src, unit):
    dst = previous_path(unit)
    _remove(dst)
    dst.parent.mkdir(parents=True, exist_ok=True)
    os.replace(src, dst)
    return dst


def settle_kept():
    """onsuccess/onerror: put back, move to previous/ or drop each kept output (see the top)."""
    if not KEEP_DIR.is_dir():
        return
    try:  # the units kept by the run that made KEEP_DIR (its sheet may differ from this one's)
        units = [u for u in json.loads((KEEP_DIR / MANIFEST).read_text()) if (KEEP_DIR / u).exists()]
    except (OSError, ValueError):  # killed before the manifest was written: nothing was removed yet
        units = []
    incomplete = _incomplete(units)
    restored, moved, failed_now = [], [], {}
    replaced = [u for u in units if u not in incomplete and Path(u).exists() and not _same(Path(u), KEEP_DIR / u)]
    for u in replaced:
        if is_failure(u) and _patient_of(u):
            failed_now[_patient_of(u)] = u
    for u in units:
        kept, out = KEEP_DIR / u, Path(u)
        if u in incomplete:  # interrupted: the earlier output goes back in place
            _remove(out)
            out.parent.mkdir(parents=True, exist_ok=True)
            os.replace(kept, out)
            restored.append(u)
        elif not out.exists():  # its job failed: Snakemake removed the output and its record
            moved.append(str(move_to_previous(kept, u)))
        elif u in replaced and _patient_of(u) in failed_now and not is_failure(kept):
            moved.append(str(move_to_previous(kept, u)))
    shutil.rmtree(KEEP_DIR, ignore_errors=True)
    if restored:
        more = f" and {len(restored) - 1} more" if len(restored) > 1 else ""
        print(
            f"vcs-atlas: {len(restored)} output(s) of interrupted jobs put back as they were before this run "
            f"({restored[0]}{more}); the next run recomputes them",
            file=sys.stderr,
        )
    if moved:
        more = f" and {len(moved) - 1} more" if len(moved) > 1 else ""
        who = ", ".join(f"{pid} ({u})" for pid, u in sorted(failed_now.items()))
        print(
            f"vcs-atlas: {len(moved)} earlier output(s) replaced by a failure in this run kept in previous/ "
            f"({moved[0]}{more})" + (f"; failed: {who}" if who else ""),
            file=sys.stderr,
        )
