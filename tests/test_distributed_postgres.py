"""Tuning on several machines: ``sb3-denfac-zoo train -optimize --storage postgresql://...`` against a real PostgreSQL.

A module fixture starts a throwaway PostgreSQL server from the system's binaries (Debian's ``postgresql`` package:
``/usr/lib/postgresql/<version>/bin``) on a free port of 127.0.0.1, with its data directory and unix socket in a temp
dir; it is stopped and deleted afterwards. As root, the server runs as the ``postgres`` system user (PostgreSQL refuses
to run as root). Without the binaries the tests skip, unless ``SB3_DENFAC_REQUIRE_POSTGRES=1`` (set by ``.ci/run``)
turns the skip into a failure.

Each worker is a separate ``sb3-denfac-zoo`` process, as on separate machines; they meet only in the database.
"""

from __future__ import annotations

import glob
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import NoReturn

import optuna
import pytest
from optuna.trial import TrialState

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[1]
REQUIRE = os.environ.get("SB3_DENFAC_REQUIRE_POSTGRES") == "1"
# The driver of the distributed extra: SQLAlchemy >= 2.1 (Optuna's RDB storage) opens postgresql:// URLs with psycopg 3.
if REQUIRE:
    import psycopg  # a missing driver is an error, not a skip
else:
    psycopg = pytest.importorskip("psycopg", reason="the PostgreSQL driver psycopg 3 (pip install -e '.[distributed]')")
SERVICE_USER = "postgres"  # the system user of Debian's package, who runs the server when the tests run as root

# A tuning run of DENFAC on Pendulum, as cheap as the zoo allows: 2 episodes per trial, one evaluation of one episode,
# random sampling, no pruning (about a second per trial).
TUNE = ["train", "--algo", "denfac", "--env", "Pendulum-v1", "-n", "400", "-optimize", "--n-evaluations", "1"]
TUNE += ["--eval-episodes", "1", "--sampler", "random", "--pruner", "none", "--no-optim-plots", "--verbose", "0"]
FINISHED = re.compile(r"Trial (\d+) finished with value")  # Optuna's log line, one per trial the process completed


def _postgres_bin() -> Path | None:
    """The directory of ``initdb``/``pg_ctl``: on the PATH, else Debian's newest ``/usr/lib/postgresql/<v>/bin``."""
    initdb = shutil.which("initdb")
    if initdb:
        return Path(initdb).resolve().parent  # the real bin directory (where pg_ctl is), not a symlink's
    found = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"), key=lambda p: int(Path(p).parts[-3].split(".")[0]))
    return Path(found[-1]).parent if found else None


def _unavailable(reason: str) -> NoReturn:
    if REQUIRE:
        pytest.fail(f"SB3_DENFAC_REQUIRE_POSTGRES=1 but {reason}", pytrace=False)
    pytest.skip(reason)


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@pytest.fixture(scope="module")
def postgres_url() -> Iterator[str]:
    """``postgresql://postgres@127.0.0.1:<port>/optuna``: a fresh server and database, stopped after the module."""
    bin_dir = _postgres_bin()
    if bin_dir is None:
        _unavailable("no PostgreSQL server binaries (initdb) on this machine (Debian: apt-get install postgresql)")
    as_root = os.geteuid() == 0
    if as_root:
        try:
            import pwd

            service = pwd.getpwnam(SERVICE_USER)
        except KeyError:
            _unavailable(f"running as root and there is no {SERVICE_USER!r} user to run the server as")
        runner = shutil.which("runuser")
        if runner is None:
            _unavailable("running as root and runuser is missing (the server must not run as root)")
        prefix = [runner, "-u", SERVICE_USER, "--"]
    else:
        prefix = []

    def run(*command: str | Path) -> None:
        subprocess.run([*prefix, *map(str, command)], check=True, capture_output=True, text=True, timeout=60)

    base = Path(tempfile.mkdtemp(prefix="sb3pg-"))  # short: the unix socket path must stay under ~100 characters
    if as_root:
        os.chown(base, service.pw_uid, service.pw_gid)
    data, log = base / "data", base / "server.log"
    started = False
    try:
        run(bin_dir / "initdb", "-D", data, "-U", "postgres", "--auth=trust", "-E", "UTF8", "--no-sync")
        for _ in range(3):  # a free port may be taken between the probe and the server's bind
            port = _free_port()
            options = f"-p {port} -k {base} -c listen_addresses=127.0.0.1 -c fsync=off -c full_page_writes=off"
            try:
                run(bin_dir / "pg_ctl", "-D", data, "-l", log, "-o", options, "-w", "-t", "30", "start")
            except subprocess.CalledProcessError:
                continue
            started = True
            break
        if not started:
            pytest.fail(f"PostgreSQL did not start; its log:\n{log.read_text() if log.exists() else '(none)'}")
        server = f"postgresql://postgres@127.0.0.1:{port}"
        with psycopg.connect(f"{server}/postgres", connect_timeout=10, autocommit=True) as connection:
            connection.execute("CREATE DATABASE optuna")  # autocommit: CREATE DATABASE cannot run in a transaction
        yield f"{server}/optuna"
    finally:
        if started:
            run(bin_dir / "pg_ctl", "-D", data, "-m", "immediate", "-w", "stop")  # a throwaway: no shutdown checkpoint
        shutil.rmtree(base, ignore_errors=True)


def _zoo_command() -> list[str]:
    script = Path(sys.executable).with_name("sb3-denfac-zoo")  # the console script, as a user runs it
    return [str(script)] if script.is_file() else [sys.executable, "-m", "sb3_denfac.zoo"]


def _start_worker(url: str, study: str, workdir: Path, *extra: str) -> subprocess.Popen:
    """One tuning worker (its own process and log folder, as on its own machine); Optuna's log goes to ``stderr``."""
    workdir.mkdir(parents=True, exist_ok=True)
    command = [*_zoo_command(), *TUNE, "-f", str(workdir / "logs"), "--storage", url, "--study-name", study, *extra]
    env = {**os.environ, "PYTHONPATH": str(REPO), "OMP_NUM_THREADS": "1"}
    with open(workdir / "stderr.txt", "w") as stderr:  # the child keeps its own descriptor
        return subprocess.Popen(command, cwd=workdir, env=env, stdout=subprocess.DEVNULL, stderr=stderr)


def _finished_numbers(workdir: Path) -> list[int]:
    """The trial numbers this worker reported finished (Optuna's ``Trial N finished with value`` lines)."""
    return [int(n) for n in FINISHED.findall((workdir / "stderr.txt").read_text())]


def _trial_states(url: str, study: str) -> dict[int, str]:
    """``{trial number: state}`` read with one plain SQL query (fast enough to poll); empty if the query fails."""
    try:
        with psycopg.connect(url, connect_timeout=5, autocommit=True) as connection:
            query = "SELECT t.number, t.state FROM trials t JOIN studies s ON s.study_id = t.study_id WHERE s.study_name = %s"
            return dict(connection.execute(query, (study,)).fetchall())
    except psycopg.Error:
        return {}


def _wait(workers: dict[Path, subprocess.Popen], timeout: float = 150) -> None:
    """Wait for the workers (by work dir) to end, kill any left (timeout, failure), and check that all succeeded."""
    deadline = time.monotonic() + timeout
    try:
        for process in workers.values():
            process.wait(timeout=max(deadline - time.monotonic(), 0.1))
    finally:
        for process in workers.values():
            if process.poll() is None:
                process.kill()
                process.wait()
    for workdir, process in workers.items():
        assert process.returncode == 0, f"worker {workdir.name} failed:\n{(workdir / 'stderr.txt').read_text()[-3000:]}"


def _create_study(url: str, study: str) -> None:
    """The documented first step, once per study: ``optuna create-study ... --direction maximize --skip-if-exists``.

    It creates Optuna's tables before any worker starts: workers started at the same moment on an empty database race
    to create them, and all but one die with ``IntegrityError`` (duplicate key in ``pg_type_typname_nsp_index``)."""
    cli = Path(sys.executable).with_name("optuna")
    command = (
        [str(cli)] if cli.is_file() else [sys.executable, "-c", "import sys; from optuna.cli import main; sys.exit(main())"]
    )
    command += ["create-study", "--storage", url, "--study-name", study, "--direction", "maximize", "--skip-if-exists"]
    subprocess.run(command, check=True, capture_output=True, timeout=120)


def test_two_workers_tune_one_study(postgres_url: str, tmp_path: Path) -> None:
    """Two zoo processes started at the same time share one study: each one's trials are in it, none is lost or
    counted twice."""
    study, per_worker = "denfac-pendulum-shared", 2
    _create_study(postgres_url, study)
    dirs = [tmp_path / "worker_a", tmp_path / "worker_b"]
    _wait(
        {
            workdir: _start_worker(postgres_url, study, workdir, "--n-trials", str(per_worker), "--seed", str(seed))
            for seed, workdir in enumerate(dirs, start=1)
        }
    )

    finished = [_finished_numbers(workdir) for workdir in dirs]
    assert [len(numbers) for numbers in finished] == [per_worker, per_worker]
    assert not set(finished[0]) & set(finished[1]), f"a trial number was handed to both workers: {finished}"

    assert optuna.get_all_study_names(storage=postgres_url) == [study]
    loaded = optuna.load_study(study_name=study, storage=postgres_url)
    assert loaded.direction == optuna.study.StudyDirection.MAXIMIZE  # the zoo maximises the return
    trials = loaded.trials
    assert sorted(t.number for t in trials) == list(range(2 * per_worker))  # no gap, no repeat
    complete = {t.number for t in trials if t.state == TrialState.COMPLETE}
    assert complete == set(finished[0]) | set(finished[1])
    assert all(t.value is not None and t.params for t in trials)


def test_killed_worker_leaves_its_trial_running_and_the_study_continues(postgres_url: str, tmp_path: Path) -> None:
    """SIGKILL a worker in the middle of a trial (after it completed one): the study loads, its completed trials are
    intact, the killed trial stays RUNNING (the zoo's storage has no heartbeat, so nothing ever fails it), a new worker
    carries on with new trial numbers, and ``study.tell(number, state=FAIL)`` clears the orphan."""
    study = "denfac-pendulum-killed"  # not created beforehand: the first worker starts alone and creates it
    doomed_dir = tmp_path / "doomed"
    doomed = _start_worker(postgres_url, study, doomed_dir, "--n-trials", "1000", "--seed", "1")
    running: list[int] = []
    try:
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline and doomed.poll() is None:
            states = _trial_states(postgres_url, study)
            running = [n for n, state in states.items() if state == "RUNNING"]
            if "COMPLETE" in states.values() and running:
                break
            time.sleep(0.1)
    finally:
        doomed.kill()  # SIGKILL
        doomed.wait()
    assert doomed.returncode == -signal.SIGKILL, f"the worker ended on its own:\n{(doomed_dir / 'stderr.txt').read_text()}"
    assert len(running) == 1, f"no trial in progress to kill: {_trial_states(postgres_url, study)}"
    (killed,) = running

    before = optuna.load_study(study_name=study, storage=postgres_url).trials
    states = {t.number: t.state for t in before}
    assert states[killed] == TrialState.RUNNING
    assert [n for n, state in states.items() if state != TrialState.COMPLETE] == [killed]
    completed_before = {t.number: t.value for t in before if t.state == TrialState.COMPLETE}
    assert completed_before and all(value is not None for value in completed_before.values())

    replacement_dir = tmp_path / "replacement"
    _wait({replacement_dir: _start_worker(postgres_url, study, replacement_dir, "--n-trials", "1", "--seed", "2")})
    loaded = optuna.load_study(study_name=study, storage=postgres_url)
    after = {t.number: t for t in loaded.trials}
    new = sorted(set(after) - set(states))
    assert new == _finished_numbers(replacement_dir) and len(new) == 1 and min(new) > max(states)
    assert all(after[n].state == TrialState.COMPLETE for n in new)
    assert {n: after[n].value for n in completed_before} == completed_before
    assert after[killed].state == TrialState.RUNNING  # still: a killed worker's trial is never failed automatically

    loaded.tell(killed, state=TrialState.FAIL)  # the clean-up the docs give (docs/several_machines.md)
    assert optuna.load_study(study_name=study, storage=postgres_url).trials[killed].state == TrialState.FAIL
