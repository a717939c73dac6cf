"""Sweeps on several machines: ``benchmarks.runner.sweep.sweep(..., ray_address=...)`` against a real Ray cluster.

A module fixture starts a cluster with the ``ray`` command line of this environment: a head node with no CPUs (so every
task must run elsewhere) and one worker node with one CPU, each ``ray start ... --block`` in its own process group, with
every port chosen free and the session files in a short temp dir. Teardown SIGKILLs those process groups and any
process left that names the temp dir: never ``ray stop``, which would stop every Ray instance on the machine.

Everything listens on 127.0.0.1 only. Ray binds its servers to the node's IP, and replaces ``127.0.0.1`` by the
machine's network address wherever it is given (node IP, ``--address``, ``ray.init(address=...)``); the documented
``RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0`` keeps the loopback address (for the head and the sweep's driver) but also
forbids ``ray start --address`` (a worker node); the worker node is therefore ``ray start`` with that one rewrite
turned off (``services.resolve_ip_for_localhost``). On real machines none of this applies: they use their own
addresses (docs/several_machines.md).
"""

from __future__ import annotations

import importlib.util
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest

if importlib.util.find_spec("ray") is None:
    pytest.skip("Ray is not installed (pip install -e '.[distributed]')", allow_module_level=True)

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[1]
_CLI = "from ray.scripts.scripts import main; sys.argv[0] = 'ray'; sys.exit(main())"
#: ``ray``, the command line of this environment.
RAY = [str(Path(sys.executable).with_name("ray"))]
if not Path(RAY[0]).is_file():
    RAY = [sys.executable, "-c", f"import sys; {_CLI}"]
#: ``ray`` with the rewrite of 127.0.0.1 to the machine's address turned off, for the worker node.
RAY_LOOPBACK = [
    sys.executable,
    "-c",
    f"import sys, ray._private.services as s; s.resolve_ip_for_localhost = lambda host: host; {_CLI}",
]
STARTED = "Ray runtime started."  # what ``ray start`` prints once the node is up (before --block waits)
#: Token authentication with this cluster's own token (not ~/.ray/auth_token, which Ray uses when it exists: the
#: cluster must not depend on what another Ray program left there); no usage stats; a dead node is noticed in about
#: 3 s (3 failed health checks 1 s apart; Ray's default: 5, 3 s apart), while a live node on a busy machine still has
#: 5 s to answer each check.
RAY_ENV = {
    "RAY_AUTH_MODE": "token",
    "RAY_AUTH_TOKEN": secrets.token_hex(32),
    "RAY_USAGE_STATS_ENABLED": "0",
    "RAY_health_check_initial_delay_ms": "0",
    "RAY_health_check_period_ms": "1000",
    "RAY_health_check_timeout_ms": "5000",
    "RAY_health_check_failure_threshold": "3",
    "OMP_NUM_THREADS": "1",
}
#: The head and the drivers keep 127.0.0.1 (see the module docstring).
LOOPBACK_ENV = {"RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0"}


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _node_ports() -> list[str]:
    """Every port of a node chosen free, so nothing collides with another Ray instance on this machine."""
    return [
        f"--node-manager-port={_free_port()}",
        f"--object-manager-port={_free_port()}",
        f"--dashboard-agent-listen-port={_free_port()}",
        f"--dashboard-agent-grpc-port={_free_port()}",
        f"--runtime-env-agent-port={_free_port()}",
        f"--metrics-export-port={_free_port()}",
    ]


@dataclass
class RayCluster:
    """A head (no CPUs) and worker nodes (one CPU each) on 127.0.0.1; ``address`` is ``127.0.0.1:<GCS port>``."""

    base: Path
    address: str = ""
    nodes: list[subprocess.Popen] = field(default_factory=list)

    def env(self, **extra: str) -> dict[str, str]:
        """Ray's settings over this environment; without a ``PYTHONPATH`` (a node needs only the installed package)."""
        env = {**os.environ, **RAY_ENV, **extra}
        env.pop("PYTHONPATH", None)
        return env

    def _start(self, name: str, command: list[str], env: dict[str, str]) -> subprocess.Popen:
        """A node: ``command`` in its own process group, run from the temp dir (not this checkout)."""
        log = self.base / f"{name}.out"
        with open(log, "w") as out:
            node = subprocess.Popen(
                command, cwd=self.base, env=env, stdout=out, stderr=subprocess.STDOUT, start_new_session=True
            )
        self.nodes.append(node)
        deadline = time.monotonic() + 90
        while STARTED not in log.read_text():
            if node.poll() is not None or time.monotonic() > deadline:
                pytest.fail(f"ray start ({name}) failed:\n{log.read_text()[-3000:]}")
            time.sleep(0.2)
        return node

    def start_head(self) -> None:
        port = _free_port()
        command = [*RAY, "start", "--head", f"--port={port}", "--num-cpus=0", "--include-dashboard=false"]
        command += [f"--ray-client-server-port={_free_port()}", f"--temp-dir={self.base}", *self._common()]
        self._start("head", command, self.env(**LOOPBACK_ENV))
        self.address = f"127.0.0.1:{port}"

    def start_worker(self) -> subprocess.Popen:
        command = [*RAY_LOOPBACK, "start", f"--address={self.address}", "--node-ip-address=127.0.0.1", "--num-cpus=1"]
        return self._start(f"worker{len(self.nodes)}", command + self._common(), self.env())

    @staticmethod
    def _common() -> list[str]:
        return [
            *_node_ports(),
            "--object-store-memory=80000000",
            "--disable-usage-stats",
            "--include-log-monitor=false",
            "--block",
        ]

    def kill(self, node: subprocess.Popen) -> None:
        """SIGKILL a node's whole process group (``ray start``, its raylet, agents and task workers): a machine lost."""
        try:
            os.killpg(node.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        node.wait()

    def stop(self) -> None:
        for node in self.nodes:
            self.kill(node)
        for pid in _pids_naming(str(self.base)):  # anything that left its node's process group
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass


def _pids_naming(text: str) -> list[int]:
    pids = []
    for proc in Path("/proc").iterdir():
        if proc.name.isdigit() and int(proc.name) != os.getpid():
            try:
                if text in (proc / "cmdline").read_bytes().decode(errors="replace"):
                    pids.append(int(proc.name))
            except OSError:
                pass
    return pids


@pytest.fixture(scope="module")
def ray_cluster() -> Iterator[RayCluster]:
    base = Path(tempfile.mkdtemp(prefix="sb3ray-"))  # short: Ray's unix socket paths must stay under ~107 characters
    cluster = RayCluster(base)
    try:
        cluster.start_head()
        cluster.start_worker()
        yield cluster
    finally:
        cluster.stop()
        shutil.rmtree(base, ignore_errors=True)


# ----- the sweep --------------------------------------------------------------------------------------------------------

#: CMA-ES on Pendulum (no gradient steps: about 0.1 CPU second an episode), one Ray task per seed.
ALGOS, ENVS, EPISODES = ["cmaes"], ["pendulum"], 10
SEEDS = [0, 1, 2, 3]


def _sweep_command(results: Path, seeds: list[int], ray_address: str) -> list[str]:
    command = [sys.executable, "-m", "benchmarks.run", "--algos", *ALGOS, "--envs", *ENVS, "--seeds", *map(str, seeds)]
    return command + ["--episodes", str(EPISODES), "--results", str(results), "--ray-address", ray_address, "--no-analysis"]


def _start_sweep(cluster: RayCluster, results: Path, seeds: list[int], log: Path) -> subprocess.Popen:
    """``python -m benchmarks.run ... --ray-address`` on the head's machine (its driver joins the head node)."""
    with open(log, "a") as out:
        return subprocess.Popen(
            _sweep_command(results, seeds, cluster.address),
            cwd=REPO,
            env={**cluster.env(**LOOPBACK_ENV), "PYTHONPATH": str(REPO)},
            stdout=out,
            stderr=subprocess.STDOUT,
        )


def _finish(sweep: subprocess.Popen, log: Path, timeout: float = 240) -> str:
    try:
        sweep.wait(timeout=timeout)
    finally:
        if sweep.poll() is None:
            sweep.kill()
            sweep.wait()
    text = log.read_text()
    assert sweep.returncode == 0, f"the sweep failed:\n{text[-4000:]}"
    return text


def _records(results: Path) -> list[dict]:
    """Every record of the runs file, in file order, duplicates included (``store.read_runs`` would hide them)."""
    from benchmarks.runner import store

    return list(store.read_records(results))


def _columns(records: list[dict]) -> dict[tuple[str, str, int], dict[str, list]]:
    """Per cell, the per-episode columns that depend only on the run (not on the machine or the clock)."""
    return {
        (r["algo"], r["env"], r["seed"]): {k: r["episodes"][k] for k in ("return", "performance", "length")} for r in records
    }


@pytest.fixture(scope="module")
def local_sweep(tmp_path_factory: pytest.TempPathFactory) -> dict[tuple[str, str, int], dict[str, list]]:
    """The same sweep run locally, in this process (``workers=0``): the reference for the runs on the cluster."""
    from benchmarks.runner import store
    from benchmarks.runner.sweep import sweep

    results = tmp_path_factory.mktemp("local")
    status = sweep(algos=ALGOS, envs=ENVS, seeds=SEEDS, episodes=EPISODES, results_dir=results, workers=0, verbose=0)
    assert len(status["done"]) == len(SEEDS) and not status["failed"]
    runs = store.read_runs(results)
    assert all(len(r["episodes"]["return"]) == EPISODES for r in runs)
    return _columns(runs)


def test_sweep_on_ray_matches_the_local_sweep(ray_cluster: RayCluster, local_sweep: dict, tmp_path: Path) -> None:
    """The runs go to the worker node (the head has no CPU) and come back identical to the local ones."""
    results, log = tmp_path / "results", tmp_path / "sweep.log"
    text = _finish(_start_sweep(ray_cluster, results, SEEDS[:2], log), log)
    assert "finished: 2 done, 0 skipped, 0 failed" in text
    records = _records(results)
    assert [r["status"] for r in records] == ["done", "done"]
    # exact: the same seed, code and kernels (one machine, one thread per process) repeat a run bit for bit
    assert _columns(records) == {cell: local_sweep[cell] for cell in [("cmaes", "pendulum", s) for s in SEEDS[:2]]}


def test_sweep_survives_a_lost_worker_node_and_a_lost_driver(
    ray_cluster: RayCluster, local_sweep: dict, tmp_path: Path
) -> None:
    """SIGKILL the worker node in the middle of a run: once a new node joins, Ray reruns the lost run there and the
    sweep goes on. SIGKILL the sweep itself after that: rerunning the same command does only the cells not in the
    runs file. In the end every cell is there once, with the records written before the kills unchanged, and every
    run equals its local twin."""
    results, log = tmp_path / "results", tmp_path / "sweep.log"
    cells = {("cmaes", "pendulum", s) for s in SEEDS}

    def wait_for_records(process: subprocess.Popen, more_than: int) -> list[dict]:
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline and process.poll() is None:
            records = _records(results)
            if len(records) > more_than:
                return records
            time.sleep(0.1)
        pytest.fail(f"no new run in the runs file (sweep exit code {process.poll()}):\n{log.read_text()[-4000:]}")

    first = _start_sweep(ray_cluster, results, SEEDS, log)
    try:
        before_node_loss = wait_for_records(first, 0)
        ray_cluster.kill(ray_cluster.nodes[-1])  # the worker node, in the middle of the next run
        ray_cluster.start_worker()
        before_driver_loss = wait_for_records(first, len(before_node_loss))  # the sweep went on, on the new node
    finally:
        first.kill()  # SIGKILL: the sweep's own machine is lost too
        first.wait()
    assert first.returncode == -signal.SIGKILL, "the sweep ended before it could be killed: use more or longer runs"
    after_kills = _records(results)
    assert after_kills[: len(before_driver_loss)] == before_driver_loss
    assert after_kills[: len(before_node_loss)] == before_node_loss
    assert len(after_kills) < len(SEEDS), "nothing left for the rerun: use more or longer runs"

    text = _finish(_start_sweep(ray_cluster, results, SEEDS, log), log)  # the same command again
    left = len(SEEDS) - len(after_kills)
    assert f"{left} runs to do, {len(after_kills)} already finished (skipped)" in text
    assert f"finished: {left} done, {len(after_kills)} skipped, 0 failed" in text
    records = _records(results)
    assert records[: len(after_kills)] == after_kills  # nothing finished was lost or rewritten
    assert [r["status"] for r in records] == ["done"] * len(SEEDS)
    assert sorted((r["algo"], r["env"], r["seed"]) for r in records) == sorted(cells)  # each cell once
    # exact: the same seed, code and kernels (one machine, one thread per process) repeat a run bit for bit
    assert _columns(records) == local_sweep
