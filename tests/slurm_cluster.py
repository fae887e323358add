"""A throw-away, REAL one-node SLURM cluster for tests.

It starts a private ``munged`` plus ``slurmctld`` and ``slurmd`` (all as
root) from a generated, cgroup-free ``slurm.conf`` that names this machine
(``hostname``), waits until ``sinfo`` reports the node idle and tears
everything down again afterwards.

Nothing system-wide is touched:

* ``munged`` gets its own key, socket, pid/log/seed files in a private dir
  (``AuthInfo=socket=...`` points slurm at it), so a system munged -- or a
  stale one from an earlier run -- does not matter;
* ``slurmctld``/``slurmd`` use free TCP ports chosen at start, and keep
  StateSaveLocation, SlurmdSpoolDir, logs and pid files in the work dir;
* clients (sbatch, squeue, sinfo, scontrol, srun, and Snakemake's SLURM
  executor plugin) find the cluster through ``SLURM_CONF`` in ``cluster.env``;
* exception: while the cluster runs, ``/run/slurm/conf`` is a symlink to the
  run dir (only created if neither it nor /etc/slurm/slurm.conf exists),
  because Snakemake's jobstep executor strips SLURM_CONF before its nested
  ``srun`` inside each job (see ``_link_client_conf``).

Usage::

    from slurm_cluster import running_cluster
    with running_cluster(tmp_path) as cluster:
        subprocess.run(["sbatch", "--wrap", "hostname"], env=cluster.env)
        # Snakemake: the shipped profiles/slurm with this cluster's overrides
        profile = cluster.snakemake_profile(tmp_path / "profile")  # --profile <profile>

or, in pytest, the session-scoped fixture ``slurm_cluster`` (yields the
SlurmCluster; pass ``env=slurm_cluster.env`` to subprocesses). Import it into
a conftest.py (tests/ is not a package, so put it on sys.path)::

    import sys, pathlib
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
    from slurm_cluster import slurm_cluster  # noqa: E402,F401

Importing it in several places is harmless: one reference-counted cluster.  The fixture skips (``pytest.skip``) when the
slurm/munge binaries are missing or we are not root, and fails with the
daemon log tails when the cluster does not come up.

Daemons are children of the test process (``-D`` foreground mode), get
``PR_SET_PDEATHSIG`` so they die with it, are recorded in a registry file so
that a later run kills leftovers of a crashed run (by pid, after checking
their command line), and are stopped by ``stop_cluster``/atexit.
"""

from __future__ import annotations

import atexit
import contextlib
import ctypes
import fcntl
import os
import shutil
import signal
import socket
import subprocess
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

PARTITION = "debug"
CLUSTER_NAME = "vcstest"
# Leftover daemons of earlier (crashed) runs are listed here: "pid marker" lines.
REGISTRY = Path(tempfile.gettempdir()) / "vcs-slurm-test-daemons.txt"
# Every daemon's command line contains this string (it is part of the run dir name).
MARKER = "vcs-slurm-"

REQUIRED_BINARIES = ("slurmctld", "slurmd", "munged", "sbatch", "squeue", "sinfo", "scontrol", "srun")

# What this throw-away cluster needs beyond profiles/slurm (which is for a real cluster), for
# snakemake-executor-plugin-slurm 2.8.0: no accounting (sacct fails without slurmdbd, so status
# comes from squeue, which needs MinJobAge >= 3 * init-seconds-before-status-checks: 300 >= 6), no
# accounts (submit without -A; validating an account via sacctmgr would fail), and its one
# partition (merged into the profile's default-resources by SlurmCluster.snakemake_profile).
TEST_PROFILE_OVERRIDES = {
    "slurm-status-command": "squeue",
    "slurm-no-account": True,
    "slurm-init-seconds-before-status-checks": 2,
}
REPO = Path(__file__).resolve().parents[1]


class SlurmClusterError(RuntimeError):
    """The cluster could not be started (the message carries the daemon logs)."""


@dataclass
class SlurmCluster:
    workdir: Path
    rundir: Path  # short private dir: munge socket, slurmd spool (unix socket path limit)
    conf: Path
    env: dict
    nodename: str
    partition: str = PARTITION
    cpus: int = 1
    real_memory_mb: int = 0
    procs: dict = field(default_factory=dict)  # name -> Popen
    logs: dict = field(default_factory=dict)  # name -> Path

    conf_link: Path | None = None  # /run/slurm/conf link we created (see _link_client_conf)
    nested_srun_problem: str | None = None  # why srun inside jobs cannot reach us

    def procs_ids(self) -> list[int]:
        return [p.pid for p in self.procs.values()]

    def run(self, *args: str, timeout: float = 30, check: bool = True) -> subprocess.CompletedProcess:
        """Run a slurm client command against this cluster."""
        return subprocess.run(list(args), env=self.env, capture_output=True, text=True, timeout=timeout, check=check)

    def snakemake_profile(self, dest: Path, base: Path = REPO / "profiles" / "slurm") -> Path:
        """A Snakemake profile for this cluster in ``dest``: the shipped ``base`` profile (groups,
        per-rule resources, ...) with :data:`TEST_PROFILE_OVERRIDES` and this cluster's partition.
        Returns the profile folder (for ``--profile``)."""
        import yaml

        profile = yaml.safe_load((Path(base) / "config.yaml").read_text())
        profile.update(TEST_PROFILE_OVERRIDES)
        profile["default-resources"] = {**profile.get("default-resources", {}), "slurm_partition": self.partition}
        dest.mkdir(parents=True, exist_ok=True)
        (dest / "config.yaml").write_text(yaml.safe_dump(profile, sort_keys=False))
        return dest

    def log_tails(self, n: int = 30) -> str:
        out = []
        for name, path in self.logs.items():
            try:
                lines = Path(path).read_text(errors="replace").splitlines()[-n:]
            except OSError:
                lines = ["<no log>"]
            out.append(f"----- {name} ({path}) -----\n" + "\n".join(lines))
        return "\n".join(out)


# ---------------------------------------------------------------- availability


def _which(name: str) -> str | None:
    """shutil.which, also looking in the sbin dirs (daemons live in /usr/sbin)."""
    path = os.pathsep.join([os.environ.get("PATH", ""), "/usr/local/sbin", "/usr/sbin", "/sbin"])
    return shutil.which(name, path=path)


def missing_requirements() -> str | None:
    """Reason why no cluster can be started here, or None."""
    missing = [b for b in REQUIRED_BINARIES if _which(b) is None]
    if missing:
        return "slurm/munge binaries missing: " + ", ".join(missing) + " (Debian: apt-get install -y slurm-wlm munge)"
    if os.geteuid() != 0:
        return "starting slurmctld/slurmd needs root (SlurmUser=root)"
    return None


# ---------------------------------------------------------------- helpers


def _free_ports(n: int) -> list[int]:
    """n distinct currently free TCP ports (avoids clashes with any other slurm)."""
    socks = []
    try:
        for _ in range(n):
            s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            socks.append(s)
            s.bind(("0.0.0.0", 0))
        return [s.getsockname()[1] for s in socks]
    finally:
        for s in socks:
            s.close()


def _node_hardware(nodename: str) -> tuple[str, int, int]:
    """(topology string for NodeName=, cpus, real memory MB minus a margin)."""
    cpus = os.cpu_count() or 1
    topo = f"CPUs={cpus}"
    mem_mb = None
    try:
        out = subprocess.run([_which("slurmd") or "slurmd", "-C"], capture_output=True, text=True, timeout=20).stdout
        fields = dict(tok.split("=", 1) for tok in out.split() if "=" in tok)
        if "CPUs" in fields:
            cpus = int(fields["CPUs"])
            keys = ("CPUs", "Boards", "SocketsPerBoard", "CoresPerSocket", "ThreadsPerCore")
            topo = " ".join(f"{k}={fields[k]}" for k in keys if k in fields)
        if "RealMemory" in fields:
            mem_mb = int(fields["RealMemory"])
    except (OSError, subprocess.SubprocessError, ValueError):
        pass
    if mem_mb is None:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemTotal:"):
                    mem_mb = int(line.split()[1]) // 1024
                    break
    mem_mb = mem_mb or 1024
    # slurmd drains the node when RealMemory exceeds what it detects -> keep a margin.
    real = max(256, min(int(mem_mb * 0.9), mem_mb - 256))
    return topo, cpus, real


def _pdeathsig():
    """preexec_fn: the daemon gets SIGTERM when the test process dies."""
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except OSError:
        pass


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


def _kill_pid(pid: int, marker: str, timeout: float = 10) -> None:
    """Kill one process, but only if its command line still contains `marker`."""
    if not marker or marker not in _cmdline(pid):
        return
    for sig, wait in ((signal.SIGTERM, timeout), (signal.SIGKILL, 5)):
        try:
            os.kill(pid, sig)
        except ProcessLookupError:
            return
        deadline = time.monotonic() + wait
        while time.monotonic() < deadline:
            if marker not in _cmdline(pid):  # gone (or pid reused)
                return
            with contextlib.suppress(ChildProcessError, OSError):
                os.waitpid(pid, os.WNOHANG)
            time.sleep(0.1)


_registry_lock = threading.Lock()


@contextlib.contextmanager
def _registry_locked():
    """Thread + inter-process lock around the registry file."""
    with _registry_lock, open(f"{REGISTRY}.lock", "a") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def _registry_read() -> list[tuple[int, int, str]]:
    """Entries (daemon pid, owner pid = the test process, marker = run dir)."""
    entries = []
    with contextlib.suppress(OSError):
        for line in REGISTRY.read_text().splitlines():
            parts = line.split(" ", 2)
            if len(parts) == 3 and parts[0].isdigit() and parts[1].isdigit():
                entries.append((int(parts[0]), int(parts[1]), parts[2]))
    return entries


def _registry_write(entries) -> None:
    with contextlib.suppress(OSError):
        if entries:
            REGISTRY.write_text("".join(f"{p} {o} {m}\n" for p, o, m in entries))
        else:
            REGISTRY.unlink(missing_ok=True)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def kill_stale_daemons() -> None:
    """Kill daemons that a previous, now dead, test process left behind.

    Daemons of a concurrently running test process (owner alive) are kept.
    Only processes listed in the registry whose command line still contains
    their run dir are signalled.
    """
    with _registry_locked():
        keep = []
        for pid, owner, marker in _registry_read():
            if owner != os.getpid() and _alive(owner):
                keep.append((pid, owner, marker))
                continue
            if owner == os.getpid() and any(pid in c.procs_ids() for c in _ACTIVE.values()):
                keep.append((pid, owner, marker))
                continue
            _kill_pid(pid, marker)
            if marker.startswith(f"/tmp/{MARKER}"):  # its run dir is garbage now
                shutil.rmtree(marker, ignore_errors=True)
        _registry_write(keep)


def _register(pid: int, marker: str) -> None:
    with _registry_locked():
        _registry_write(_registry_read() + [(pid, os.getpid(), marker)])


def _unregister(pids) -> None:
    pids = set(pids)
    with _registry_locked():
        _registry_write([e for e in _registry_read() if e[0] not in pids])


# Slurm clients without SLURM_CONF look at /etc/slurm/slurm.conf, then at
# /run/slurm/conf/slurm.conf (the configless-slurmd cache link). The Snakemake
# jobstep executor (snakemake-executor-plugin-slurm-jobstep 0.6.1) drops every
# SLURM_* variable except job identity ones -- SLURM_CONF included -- before its
# nested `srun`, so inside a job srun would find no config. Hence, while the
# cluster runs, /run/slurm/conf points at our run dir (only if no real slurm
# config exists on this machine).
CLIENT_CONF_LINK = Path("/run/slurm/conf")
SYSTEM_CONF = Path("/etc/slurm/slurm.conf")


def _link_client_conf(cluster: SlurmCluster) -> None:
    with _registry_locked():
        if SYSTEM_CONF.exists():
            cluster.nested_srun_problem = (
                f"{SYSTEM_CONF} exists: srun inside Snakemake SLURM jobs (which loses "
                "SLURM_CONF) would talk to that cluster, not the test cluster"
            )
            return
        link = CLIENT_CONF_LINK
        if link.is_symlink():
            target = os.readlink(link)
            if target.startswith(f"/tmp/{MARKER}") and not Path(target, "slurm.conf").exists():
                link.unlink()  # left behind by a crashed run
        if link.exists() or link.is_symlink():
            cluster.nested_srun_problem = (
                f"{link} is in use (another test cluster or a configless slurmd): "
                "srun inside Snakemake SLURM jobs cannot find this cluster's config"
            )
            return
        link.parent.mkdir(parents=True, exist_ok=True)
        link.symlink_to(cluster.rundir)
        cluster.conf_link = link


def _unlink_client_conf(cluster: SlurmCluster) -> None:
    link = cluster.conf_link
    if link is None:
        return
    with _registry_locked():
        with contextlib.suppress(OSError):
            if link.is_symlink() and os.readlink(link) == str(cluster.rundir):
                link.unlink()
        with contextlib.suppress(OSError):
            link.parent.rmdir()  # only if empty
    cluster.conf_link = None


def _munge_key(path: Path) -> None:
    """A private key for our munged (the system /etc/munge/munge.key is never touched)."""
    if path.exists():
        return
    if _which("mungekey"):
        subprocess.run(
            [_which("mungekey"), "--create", "--keyfile", str(path)], check=True, capture_output=True, timeout=30
        )
    else:  # old munge without mungekey (create-munge-key only writes /etc/munge)
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "wb") as fh:
            fh.write(os.urandom(1024))
    path.chmod(0o600)


def _client_env(conf: Path) -> dict:
    env = {
        k: v
        for k, v in os.environ.items()
        if not k.startswith(("SLURM_", "SBATCH_", "SRUN_", "SALLOC_", "SQUEUE_", "SINFO_"))
    }
    env["SLURM_CONF"] = str(conf)
    return env


SLURM_CONF_TEMPLATE = """\
# Generated by tests/slurm_cluster.py -- a private one-node test cluster.
ClusterName={cluster_name}
SlurmctldHost={nodename}(127.0.0.1)
SlurmctldPort={ctld_port}
SlurmdPort={slurmd_port}
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket={munge_socket}
StateSaveLocation={state_dir}
SlurmdSpoolDir={spool_dir}
SlurmctldPidFile={workdir}/slurmctld.pid
SlurmdPidFile={workdir}/slurmd.pid
SlurmctldLogFile={workdir}/slurmctld.log
SlurmdLogFile={workdir}/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
PlugStackConfig={workdir}/plugstack.conf
# cgroup-free: works in containers / sandboxes
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
MpiDefault=none
SwitchType=switch/none
# no accounting (no slurmdbd): sacct does NOT work, query status with squeue
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU_Memory
ReturnToService=2
# finished jobs stay visible to squeue for 5 min; the Snakemake SLURM plugin
# falls back to sacct when MinJobAge < 3 * init-seconds-before-status-checks
MinJobAge=300
KillWait=5
InactiveLimit=0
SlurmctldTimeout=30
SlurmdTimeout=60
NodeName={nodename} NodeAddr=127.0.0.1 {topology} RealMemory={real_memory} State=UNKNOWN
PartitionName={partition} Nodes=ALL Default=YES MaxTime=INFINITE State=UP
"""


# ---------------------------------------------------------------- start / stop


def start_cluster(workdir: Path, timeout: float = 90) -> SlurmCluster:
    """Start munged + slurmctld + slurmd; return once the node is idle.

    Raises SlurmClusterError (with log tails) if it does not come up in
    `timeout` seconds; the partially started daemons are stopped then.
    """
    reason = missing_requirements()
    if reason:
        raise SlurmClusterError(reason)
    kill_stale_daemons()

    workdir = Path(workdir).resolve()
    workdir.mkdir(parents=True, exist_ok=True)
    # Unix sockets (munge, slurmstepd in the spool dir) have a ~108 byte path
    # limit: keep them in a short private dir. Its name is also the marker
    # identifying our daemons' command lines.
    rundir = Path(tempfile.mkdtemp(prefix=MARKER, dir="/tmp"))
    rundir.chmod(0o700)
    nodename = socket.gethostname().split(".")[0]
    topology, cpus, real_memory = _node_hardware(nodename)
    state_dir = workdir / "state"
    spool_dir = rundir / "spool"
    for d in (state_dir, spool_dir, rundir / "munge"):
        d.mkdir(parents=True, exist_ok=True)
        d.chmod(0o700)
    munge_dir = rundir / "munge"
    munge_socket = munge_dir / "munge.socket"
    (workdir / "plugstack.conf").write_text("")
    conf = workdir / "slurm.conf"
    # the conf lives in workdir; add a copy in rundir so the marker is in the daemons' argv
    ctld_port, slurmd_port = _free_ports(2)
    conf_text = SLURM_CONF_TEMPLATE.format(
        cluster_name=CLUSTER_NAME,
        nodename=nodename,
        ctld_port=ctld_port,
        slurmd_port=slurmd_port,
        munge_socket=munge_socket,
        state_dir=state_dir,
        spool_dir=spool_dir,
        workdir=workdir,
        topology=topology,
        real_memory=real_memory,
        partition=PARTITION,
    )
    conf.write_text(conf_text)
    run_conf = rundir / "slurm.conf"
    run_conf.write_text(conf_text)

    cluster = SlurmCluster(
        workdir=workdir,
        rundir=rundir,
        conf=run_conf,
        env=_client_env(run_conf),
        nodename=nodename,
        cpus=cpus,
        real_memory_mb=real_memory,
        logs={
            "munged": munge_dir / "munged.log",
            "slurmctld": workdir / "slurmctld.log",
            "slurmd": workdir / "slurmd.log",
        },
    )
    _ACTIVE[id(cluster)] = cluster
    try:
        key = munge_dir / "munge.key"
        _munge_key(key)
        _spawn(
            cluster,
            "munged",
            [
                "munged",
                "--foreground",
                "--force",
                f"--socket={munge_socket}",
                f"--key-file={key}",
                f"--pid-file={munge_dir / 'munged.pid'}",
                f"--log-file={munge_dir / 'munged.log'}",
                f"--seed-file={munge_dir / 'munged.seed'}",
            ],
        )
        _wait(cluster, lambda: munge_socket.exists(), 15, "munged socket")
        _spawn(cluster, "slurmctld", ["slurmctld", "-D", "-i", "-f", str(run_conf)])
        _wait(
            cluster,
            lambda: "UP" in cluster.run("scontrol", "ping", check=False, timeout=10).stdout,
            timeout,
            "slurmctld answering 'scontrol ping'",
        )
        _spawn(cluster, "slurmd", ["slurmd", "-D", "-f", str(run_conf), "-N", nodename])
        _wait_node_idle(cluster, timeout)
        _link_client_conf(cluster)
    except Exception:
        tails = cluster.log_tails()
        stop_cluster(cluster)
        raise SlurmClusterError(f"SLURM test cluster did not start:\n{tails}") from None
    except BaseException:  # KeyboardInterrupt & co: clean up, re-raise as is
        stop_cluster(cluster)
        raise
    return cluster


def _spawn(cluster: SlurmCluster, name: str, argv: list[str]) -> None:
    out = open(cluster.workdir / f"{name}.stdout", "ab")
    argv = [_which(argv[0]) or argv[0], *argv[1:]]
    proc = subprocess.Popen(
        argv,
        stdin=subprocess.DEVNULL,
        stdout=out,
        stderr=subprocess.STDOUT,
        env=cluster.env,
        preexec_fn=_pdeathsig,
        start_new_session=True,
        close_fds=True,
    )
    out.close()
    cluster.procs[name] = proc
    cluster.logs.setdefault(f"{name}.stdout", cluster.workdir / f"{name}.stdout")
    _register(proc.pid, str(cluster.rundir))


def _check_alive(cluster: SlurmCluster) -> None:
    for name, proc in cluster.procs.items():
        if proc.poll() is not None:
            raise SlurmClusterError(f"{name} exited with status {proc.returncode}")


def _wait(cluster: SlurmCluster, predicate, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while True:
        _check_alive(cluster)
        try:
            if predicate():
                return
        except (OSError, subprocess.SubprocessError):
            pass
        if time.monotonic() > deadline:
            raise SlurmClusterError(f"timeout ({timeout:.0f}s) waiting for {what}")
        time.sleep(0.5)


def node_state(cluster: SlurmCluster) -> str:
    r = cluster.run("sinfo", "-h", "-N", "-n", cluster.nodename, "-o", "%t", check=False, timeout=10)
    return r.stdout.strip().lower() if r.returncode == 0 else ""


def _wait_node_idle(cluster: SlurmCluster, timeout: float) -> None:
    deadline = time.monotonic() + timeout
    last_resume = 0.0
    state = ""
    while time.monotonic() < deadline:
        _check_alive(cluster)
        state = node_state(cluster)
        if state.rstrip("*~#!%$@^-") in ("idle", "mix", "alloc"):
            return
        # DOWN/DRAIN (e.g. stale state or a reboot flag): resume it, at most every 5 s.
        if any(s in state for s in ("down", "drain", "fail", "inval")) and time.monotonic() - last_resume > 5:
            cluster.run("scontrol", "update", f"nodename={cluster.nodename}", "state=resume", check=False, timeout=10)
            last_resume = time.monotonic()
        time.sleep(0.5)
    raise SlurmClusterError(
        f"timeout ({timeout:.0f}s) waiting for node {cluster.nodename} to become idle (last sinfo state: {state!r})"
    )


def stop_cluster(cluster: SlurmCluster, timeout: float = 15) -> None:
    """Cancel remaining jobs, stop slurmd, slurmctld, munged; remove the run dir."""
    if cluster.procs.get("slurmctld") and cluster.procs["slurmctld"].poll() is None:
        with contextlib.suppress(Exception):
            cluster.run("scancel", "--full", "--partition", cluster.partition, check=False, timeout=10)
            deadline = time.monotonic() + 10  # let slurmd end the job steps
            while (
                time.monotonic() < deadline
                and cluster.run("squeue", "-h", "-t", "PD,R,CG", "-o", "%i", check=False, timeout=10).stdout.strip()
            ):
                time.sleep(0.5)
    for name in ("slurmd", "slurmctld", "munged"):
        proc = cluster.procs.get(name)
        if proc is None:
            continue
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                proc.kill()
                with contextlib.suppress(subprocess.TimeoutExpired):
                    proc.wait(timeout=5)
    # slurmstepd of jobs still running would hold the spool dir; kill those by marker
    for pid_dir in Path("/proc").glob("[0-9]*"):
        pid = int(pid_dir.name)
        if pid != os.getpid() and str(cluster.rundir) in _cmdline(pid):
            _kill_pid(pid, str(cluster.rundir), timeout=5)
    _unlink_client_conf(cluster)
    _unregister([p.pid for p in cluster.procs.values()])
    cluster.procs.clear()
    _ACTIVE.pop(id(cluster), None)
    shutil.rmtree(cluster.rundir, ignore_errors=True)


_ACTIVE: dict[int, SlurmCluster] = {}


@atexit.register
def _stop_all() -> None:
    for cluster in list(_ACTIVE.values()):
        with contextlib.suppress(Exception):
            stop_cluster(cluster)


@contextlib.contextmanager
def running_cluster(workdir: Path, timeout: float = 90):
    cluster = start_cluster(workdir, timeout=timeout)
    try:
        yield cluster
    finally:
        stop_cluster(cluster)


# ---------------------------------------------------------------- pytest fixture

# Shared between every place the fixture is collected from (conftest and/or a
# test module importing it): one cluster per process, reference counted.
_SHARED: dict = {"cluster": None, "refs": 0}

try:
    import pytest
except ImportError:  # pragma: no cover - module usable without pytest
    pytest = None

if pytest is not None:

    @pytest.fixture(scope="session")
    def slurm_cluster(tmp_path_factory):
        """Session-wide one-node SLURM cluster; yields a SlurmCluster (use .env)."""
        reason = missing_requirements()
        if reason:
            pytest.skip(reason)
        if _SHARED["cluster"] is None:
            try:
                _SHARED["cluster"] = start_cluster(tmp_path_factory.mktemp("slurm"))
            except SlurmClusterError as exc:
                pytest.fail(str(exc), pytrace=False)
        _SHARED["refs"] += 1
        try:
            yield _SHARED["cluster"]
        finally:
            _SHARED["refs"] -= 1
            if _SHARED["refs"] == 0 and _SHARED["cluster"] is not None:
                stop_cluster(_SHARED["cluster"])
                _SHARED["cluster"] = None
