"""The pre-imported job worker: jobs forked from it give the outputs, logs and exit codes of
plain processes, and a job that dies or is killed takes nothing else with it."""

from __future__ import annotations

import json
import os
import pwd
import re
import shutil
import signal
import socket
import stat
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from lidarfield.cli.worker_client import recv_message, send_message
from lidarfield.runner.launch import THREAD_VARS
from lidarfield.storage.stage_ids import canonical_json
from lidarfield.study.config import validate_config

pytestmark = pytest.mark.slow

TINY_SENSOR = {"name": "tiny-16", "elevation_deg": [-22 + 2 * i for i in range(16)], "azimuth_resolution_deg": 1.0}
SIMULATE = {"scene": "paper-intersection", "sensor": TINY_SENSOR, "pose1": [0, 0, 3, 0, 0, 0]}
# What Snakemake sets for a job of one thread; the workflow starts its worker with it too.
SNAKEMAKE_ENV = {name: "1" for name in THREAD_VARS}
GRID = {"azimuth_bins": 18, "elevation_deg": [-25, 12.5], "elevation_bins": 5, "min_points": 5}

# A plugin hypothesis that hangs: it writes its process id where the test can read it.
SLEEPER = """import os, time
from pathlib import Path


def remove(pair, params):
    Path(params["pid_file"]).write_text(str(os.getpid()))
    time.sleep(120)
    return pair.xyz1[:, 2] > 0, pair.xyz2[:, 2] > 0
"""


def study(hypothesis: dict, base_dir: Path):
    config = {
        "pairs": {"shift": {"simulate": {**SIMULATE, "pose2": [1, 1, 3, 0, 0, 0.05]}, "register": "truth"}},
        "grid": dict(GRID),
        "hypotheses": [hypothesis],
    }
    return validate_config(config, base_dir=base_dir)


def pair_jobs(hypothesis: dict, base_dir: Path) -> list[list[list[str]]]:
    """The workflow's jobs for one pair and a one-hypothesis stack, in waves that can run at
    once (paths relative to ``base_dir``, the jobs' working directory)."""
    s = study(hypothesis, base_dir)
    pair = s.pairs["shift"]
    stages = s.stage_ids("shift")
    scans = [
        ["simulate", "--spec", canonical_json(scan.spec), "--out", f"scans/{scan.id}.parquet"]
        for scan in (pair.scan1, pair.scan2)
    ]
    register = [
        "register",
        "--scan1",
        f"scans/{pair.scan1.id}.parquet",
        "--scan2",
        f"scans/{pair.scan2.id}.parquet",
        "--settings",
        canonical_json(pair.register),
        "--out",
        "registered.parquet",
    ]

    def changes(up_to: int) -> list[str]:
        return [
            "--registered",
            "registered.parquet",
            "--stage-changes",
            *[f"{d}/changes.parquet" for d in stages[1:up_to]],
        ]

    def mitigate(level: int) -> list[str]:
        step = canonical_json(s.hypotheses[level - 1])
        return [
            "mitigate",
            *changes(level),
            "--step",
            step,
            "--stage",
            stages[level],
            "--level",
            str(level),
            "--changes-out",
            f"{stages[level]}/changes.parquet",
            "--removed-out",
            f"{stages[level]}/removed.parquet",
        ]

    def field(level: int) -> list[str]:
        d = stages[level]
        return [
            "field",
            *changes(level + 1),
            "--stage",
            stages[level],
            *(["--removed", f"{d}/removed.parquet"] if level else []),
            "--grid",
            canonical_json(s.grid_section),
            "--pair",
            "shift",
            "--field-out",
            f"{d}/field.parquet",
            "--stats-out",
            f"{d}/stats.json",
        ]

    return [scans, [register], [field(0), mitigate(1)], [field(1)]]


def start_job(argv: list[str], cwd: Path, worker: str, log: Path) -> subprocess.Popen:
    """``lidarfield job ARGV`` as a workflow rule runs it: output and errors into its log."""
    env = {**os.environ, **SNAKEMAKE_ENV, "LIDARFIELD_WORKER": worker}
    with open(log, "w") as f:
        return subprocess.Popen(
            [sys.executable, "-m", "lidarfield", "job", *argv], cwd=cwd, env=env, stdout=f, stderr=subprocess.STDOUT
        )


def run_waves(waves, cwd: Path, worker: str) -> None:
    for i, wave in enumerate(waves):
        jobs = [start_job(argv, cwd, worker, cwd / f"job-{i}-{j}.log") for j, argv in enumerate(wave)]
        for j, job in enumerate(jobs):
            assert job.wait(timeout=120) == 0, (cwd / f"job-{i}-{j}.log").read_text()


def rounded(value):
    """JSON-like ``value`` with floats to 12 significant digits: Open3D's registration
    statistics vary in their last digits from run to run, with or without the worker."""
    if isinstance(value, float):
        return f"{value:.12g}"  # NaN compares equal as text
    if isinstance(value, dict):
        return {k: rounded(v) for k, v in value.items()}
    if isinstance(value, list):
        return [rounded(v) for v in value]
    return value


class Frame:
    """A table that equals another with the same columns and values, NaN where it has NaN."""

    def __init__(self, frame):
        self.frame = frame

    def __eq__(self, other):
        return self.frame.equals(other.frame)

    def __repr__(self):
        return repr(self.frame)


def content(path: Path):
    if path.suffix == ".parquet":
        table = pq.read_table(path)
        meta = {
            k.decode(): json.loads(v) if k == b"lidarfield" else v for k, v in (table.schema.metadata or {}).items()
        }
        return Frame(table.to_pandas()), rounded(meta)
    return path.read_bytes()


def outputs(folder: Path) -> dict[str, object]:
    """Every file a job wrote under ``folder`` (logs and inputs aside), by relative path."""
    files = sorted(p for p in folder.rglob("*") if p.is_file() and p.suffix not in (".log", ".py"))
    return {str(p.relative_to(folder)): content(p) for p in files}


def wait_for(predicate, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.05)


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # A zombie (killed, not yet reaped by the worker) counts as gone.
    return Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z" if Path(f"/proc/{pid}").exists() else True


def start_worker(path: Path, log, *options: str) -> subprocess.Popen:
    """A worker on the socket ``path``, logging to the open file ``log``, with this test as
    its parent; returned once it listens."""
    command = [sys.executable, "-m", "lidarfield.runner.server", str(path), "--parent-pid", str(os.getpid()), *options]
    proc = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT, env={**os.environ, **SNAKEMAKE_ENV})
    wait_for(path.exists, timeout=30)
    return proc


def serving_worker(folder: Path, *options: str):
    """A worker serving on a socket in ``folder``, stopped after the test."""
    path = folder / "w.sock"
    with open(folder / "worker.log", "w") as log:
        proc = start_worker(path, log, *options)
        yield proc, str(path)
        proc.terminate()
        proc.wait(timeout=30)
    assert not path.exists(), "the worker leaves no socket behind"


@pytest.fixture
def worker(tmp_path):
    yield from serving_worker(tmp_path)


@pytest.fixture
def warming_worker(tmp_path):
    yield from serving_worker(tmp_path, "--warm-up")


def test_killed_job_leaves_other_jobs_and_the_worker_sound(tmp_path, worker):
    proc, sock = worker
    plain, forked = tmp_path / "plain", tmp_path / "forked"
    for folder in (plain, forked):
        folder.mkdir()
        (folder / "sleeper.py").write_text(SLEEPER)
    waves = pair_jobs({"field_of_view": {}}, forked)
    run_waves(waves, plain, "off")

    run_waves(waves[:2], forked, sock)
    sleeper_stage = pair_jobs({"plugin": {"file": "sleeper.py", "params": {"pid_file": "sleeper.pid"}}}, forked)[2][1]
    sleeper = start_job(sleeper_stage, forked, sock, forked / "sleeper.log")
    wait_for(lambda: (forked / "sleeper.pid").exists() and (forked / "sleeper.pid").read_text())
    child = int((forked / "sleeper.pid").read_text())
    assert child not in (sleeper.pid, proc.pid), "the job runs in a child forked from the worker"
    others = [start_job(argv, forked, sock, forked / f"other-{j}.log") for j, argv in enumerate(waves[2])]
    os.kill(child, signal.SIGKILL)

    assert sleeper.wait(timeout=60) == -signal.SIGKILL, "the client dies of its job's signal"
    for j, job in enumerate(others):
        assert job.wait(timeout=120) == 0, (forked / f"other-{j}.log").read_text()
    run_waves(waves[3:], forked, sock)  # the worker still serves after the kill
    assert proc.poll() is None

    sleeper_dir = forked / sleeper_stage[sleeper_stage.index("--stage") + 1]
    assert not sleeper_dir.exists() or not any(p.suffix == ".parquet" for p in sleeper_dir.iterdir())
    (forked / "sleeper.pid").unlink()
    # Byte for byte what the same jobs write as plain processes, logs aside.
    assert outputs(forked) == outputs(plain)
    assert len(outputs(plain)) == 9  # 2 scans, registered pair, stage 0's field and stats, stage 1's 4 files
    # The job's log is written as by a plain process (clock times aside).
    logs = [re.sub(r"\d\d:\d\d:\d\d", "T", log.read_text()) for log in (plain / "job-2-1.log", forked / "other-1.log")]
    assert logs[0] == logs[1] and "removed" in logs[0]


def test_a_failing_job_reports_the_same_exit_code_and_message_on_both_paths(tmp_path, worker):
    _, sock = worker
    argv = [
        "field",
        "--registered",
        "missing.parquet",
        "--stage",
        "01-crop-00000000",
        "--removed",
        "missing.parquet",
        "--grid",
        json.dumps(GRID),
        "--pair",
        "p",
        "--field-out",
        "f.parquet",
        "--stats-out",
        "s.json",
    ]
    logs = {}
    for mode in ("off", sock):
        log = tmp_path / f"{'plain' if mode == 'off' else 'forked'}.log"
        assert start_job(argv, tmp_path, mode, log).wait(timeout=60) == 2
        logs[mode] = log.read_text()
    assert logs["off"] == logs[sock]
    assert logs[sock].startswith("lidarfield job: error: ") and "missing.parquet" in logs[sock]
    assert start_job(["field", "--no-such-flag"], tmp_path, sock, tmp_path / "usage.log").wait(timeout=60) == 2
    assert "usage:" in (tmp_path / "usage.log").read_text()
    assert not (tmp_path / "f.parquet").exists()


def test_a_killed_client_takes_its_job_with_it(tmp_path, worker):
    _, sock = worker
    (tmp_path / "sleeper.py").write_text(SLEEPER)
    waves = pair_jobs({"plugin": {"file": "sleeper.py", "params": {"pid_file": "sleeper.pid"}}}, tmp_path)
    run_waves(waves[:2], tmp_path, sock)
    client = start_job(waves[2][1], tmp_path, sock, tmp_path / "sleeper.log")
    wait_for(lambda: (tmp_path / "sleeper.pid").exists() and (tmp_path / "sleeper.pid").read_text())
    child = int((tmp_path / "sleeper.pid").read_text())
    client.kill()
    client.wait()
    wait_for(lambda: not alive(child), timeout=10)


def test_without_a_reachable_worker_the_job_runs_in_process(tmp_path):
    stale = tmp_path / "stale.sock"
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    listener.bind(str(stale))
    listener.close()  # the socket file stays, nobody listens: as after a killed worker
    for worker in (str(stale), str(tmp_path / "absent.sock")):
        log = tmp_path / "plotly.log"
        assert start_job(["plotly-js", "--out", "plotly.min.js"], tmp_path, worker, log).wait(timeout=60) == 0, (
            log.read_text()
        )
        assert (tmp_path / "plotly.min.js").stat().st_size > 1_000_000
        (tmp_path / "plotly.min.js").unlink()


def test_the_workers_socket_is_private_to_its_user_whatever_the_umask(tmp_path, monkeypatch):
    """0600 in a new 0700 folder of the results folder, also under a group-shared cluster's umask
    (002); the folder is removed when the worker stops."""
    from lidarfield.runner import launch

    monkeypatch.delenv("LIDARFIELD_WORKER", raising=False)
    umask = os.umask(0o002)
    try:
        assert launch.start(tmp_path / "results") is not None
    finally:
        os.umask(umask)
    try:
        sock = Path(os.environ["LIDARFIELD_WORKER"]).absolute()
        folder = sock.parent
        assert stat.S_ISSOCK(sock.stat().st_mode)
        assert stat.S_IMODE(sock.stat().st_mode) == 0o600
        assert stat.S_IMODE(folder.lstat().st_mode) == 0o700 and folder.lstat().st_uid == os.getuid()
        assert folder.parent == tmp_path / "results"
    finally:
        launch.stop()
    assert sorted(p.name for p in (tmp_path / "results").iterdir()) == ["logs"]


def test_a_working_folder_too_deep_for_a_socket_gets_its_worker_in_the_temporary_folder(tmp_path, monkeypatch):
    """A results folder too deep for a Unix socket's path (107 bytes) puts the socket in a
    private folder of the system's temporary folder, by an absolute path that jobs reach from
    any working directory; the folder is removed when the worker stops."""
    from lidarfield.runner import launch

    deep = tmp_path / ("a-deep-working-folder-" * 5)
    deep.mkdir()
    monkeypatch.chdir(deep)
    monkeypatch.delenv("LIDARFIELD_WORKER", raising=False)
    assert launch.start("results") is not None
    try:
        sock = os.environ["LIDARFIELD_WORKER"]
        folder = Path(sock).parent
        assert Path(sock).is_absolute() and len(os.fsencode(sock)) <= 107
        assert folder.parent == Path(tempfile.gettempdir()) and folder.name.startswith(launch.TEMP_RUN_STEM)
        assert stat.S_IMODE(folder.lstat().st_mode) == 0o700 and folder.lstat().st_uid == os.getuid()
        log = tmp_path / "plotly.log"
        assert start_job(["plotly-js", "--out", "plotly.min.js"], tmp_path, sock, log).wait(timeout=60) == 0
        wait_for(lambda: "plotly-js: {'exit': 0}" in (deep / "results" / "logs" / "worker.log").read_text())
    finally:
        launch.stop()
    assert not folder.exists()
    assert sorted(p.name for p in (deep / "results").iterdir()) == ["logs"]


def connect_as(user: pwd.struct_passwd, sock: str, argv: list[str], cwd: Path) -> int:
    """Send a job request to the worker on ``sock`` from a forked child running as ``user``:
    0 when the worker closed the connection without starting the job, 1 when it started it,
    2 when the child could not connect at all."""
    pid = os.fork()
    if pid == 0:
        status = 3
        try:
            os.setgroups([])
            os.setgid(user.pw_gid)
            os.setuid(user.pw_uid)
            client = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            try:
                client.connect(sock)
            except OSError:
                os._exit(2)
            try:
                socket.send_fds(client, [b"J"], [0, 1, 2])
                send_message(client, {"argv": argv, "cwd": str(cwd), "env": dict(os.environ)})
                recv_message(client)
                status = 1
            except (OSError, EOFError):
                status = 0
        finally:
            os._exit(status)
    return os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1])


@pytest.mark.skipif(os.getuid() != 0, reason="needs root, to connect as another user")
def test_the_worker_refuses_another_users_requests(tmp_path):
    """Even with its socket opened to everyone (a folder and socket anyone may use), the worker
    serves no other user: it checks the peer's user id before reading the request."""
    nobody = pwd.getpwnam("nobody")
    shared = Path(tempfile.mkdtemp(prefix="lidarfield-shared-"))  # outside pytest's 0700 folders
    try:
        shared.chmod(0o777)
        sock = shared / "w.sock"
        with open(tmp_path / "worker.log", "w") as log:
            proc = start_worker(sock, log)
        try:
            sock.chmod(0o666)
            request = ["job", "plotly-js", "--out", str(shared / "theirs.js")]
            assert connect_as(nobody, str(sock), request, shared) == 0
            assert not (shared / "theirs.js").exists()
            wait_for(lambda: "refused" in (tmp_path / "worker.log").read_text(), timeout=30)
            assert (
                f"refused a connection from another user (uid {nobody.pw_uid}," in (tmp_path / "worker.log").read_text()
            )
            # The worker's own user is served as before.
            log = tmp_path / "ours.log"
            assert start_job(["plotly-js", "--out", "ours.js"], shared, str(sock), log).wait(timeout=60) == 0
            assert re.search(r"job \d+ plotly-js: \{'exit': 0\}", (tmp_path / "worker.log").read_text())
        finally:
            proc.terminate()
            proc.wait(timeout=30)
    finally:
        shutil.rmtree(shared)


def test_the_client_imports_none_of_the_numeric_libraries(tmp_path, worker):
    _, sock = worker
    code = (
        "import sys; from lidarfield.cli import main; status = main(['job', 'plotly-js', '--out', 'p.js']); "
        "print(status, [m for m in ('numpy', 'pyarrow', 'pandas', 'matplotlib', 'open3d', 'yaml', 'argparse') if m in "
        "sys.modules])"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code],
        cwd=tmp_path,
        env={**os.environ, "LIDARFIELD_WORKER": sock},
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.stdout.strip() == "0 []", proc.stderr
    assert (tmp_path / "p.js").stat().st_size > 1_000_000


def test_the_worker_stops_when_its_workflow_is_gone(tmp_path):
    path = tmp_path / "w.sock"
    # A parent that starts the worker and exits at once, as a killed Snakemake would.
    starter = (
        "import os, subprocess, sys; "
        f"p = subprocess.Popen([sys.executable, '-m', 'lidarfield.runner.server', {str(path)!r}, '--parent-pid', "
        f"str(os.getpid())]); "
        "print(p.pid)"
    )
    pid = int(subprocess.run([sys.executable, "-c", starter], capture_output=True, text=True, check=True).stdout)
    wait_for(lambda: not alive(pid), timeout=60)
    assert not path.exists()


def test_a_worker_stopped_while_importing_exits_at_once(tmp_path):
    """Stopped at any moment of its imports (a dry run ends), the worker exits and removes its
    socket; stopped inside a compiled module's import, it once took the stop for that import
    failing and went on to serve."""
    for i, delay in enumerate([0.2 * k for k in range(1, 9)]):
        path = tmp_path / f"w{i}.sock"
        log = tmp_path / f"w{i}.log"
        with open(log, "w") as out:
            proc = start_worker(path, out)
            time.sleep(delay)
            proc.terminate()
            assert proc.wait(timeout=30) == 0, log.read_text()
        assert not path.exists()
        assert "stopped" in log.read_text()


def test_a_run_with_nothing_to_do_stops_the_worker_it_started(tmp_path):
    """Snakemake starts the worker as it plans a run (lidarfield.runner.launch.spawn_when_planning);
    a run with nothing to do never points a job at it, and stops it at exit: no worker process
    and no socket are left. (A dry run starts none: tests/workflow/test_command_line.py.)"""
    from helpers.workflow import snakemake, tiny_study, write_study

    write_study(tmp_path, tiny_study())
    # Everything omitted: the run plans the study, then has nothing to do.
    proc = snakemake(tmp_path, "--cores", "1", "--omit-from", "simulate", "plotly_js", "report_js")
    assert "Nothing to be done" in proc.stdout + proc.stderr
    assert (tmp_path / "results" / "logs" / "worker.log").exists()  # spawned (it may not have logged yet)
    workers = [
        cmdline
        for cmdline in (p.read_bytes() for p in Path("/proc").glob("[0-9]*/cmdline") if p.exists())
        if b"lidarfield.runner.server" in cmdline and str(tmp_path).encode() in cmdline
    ]
    assert workers == []
    assert not list((tmp_path / "results").glob(".worker-*"))


def test_no_worker_when_jobs_run_in_their_own_software_environments(tmp_path):
    """With --sdm conda each job must run in its rule's environment, not with the worker's
    imports: no worker is started (whether or not conda is installed to run the study)."""
    from helpers.workflow import snakemake, tiny_study, write_study

    write_study(tmp_path, tiny_study())
    # Everything omitted: the run plans the study (then, without conda, fails or has nothing to do).
    proc = snakemake(tmp_path, "--cores", "1", "--sdm", "conda", "--omit-from", "simulate", "plotly_js", check=False)
    assert "Building DAG of jobs" in proc.stdout + proc.stderr
    assert not (tmp_path / "results" / "logs" / "worker.log").exists()


def test_the_figure_warm_up_draws_every_figure_and_leaves_no_folder(tmp_path, monkeypatch):
    import tempfile

    from lidarfield.runner.warm_up import WARM_UP_FIGURES, warm_up_steps

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    assert list(warm_up_steps()) == ["simulated pair", *WARM_UP_FIGURES, "field_3d"]
    assert list(tmp_path.iterdir()) == []
    steps = warm_up_steps()
    next(steps)
    assert len(list(tmp_path.iterdir())) == 1
    steps.close()  # as the worker does when it stops mid-way
    assert list(tmp_path.iterdir()) == []


def test_figures_drawn_after_the_warm_up_are_those_of_a_plain_process(tmp_path, warming_worker):
    """The warm-up leaves matplotlib's caches filled, not its settings changed: a stage's
    figures forked from the warmed-up worker are byte for byte those of a plain process."""
    from helpers.synthetic_study import write_synthetic_pair

    _, sock = warming_worker
    wait_for(lambda: "figure warm-up done" in (tmp_path / "worker.log").read_text(), timeout=120)
    stages = write_synthetic_pair(tmp_path / "pair", "pair", levels=2, n=6000)
    figures = {}
    for mode in ("off", sock):
        out = tmp_path / ("plain" if mode == "off" else "forked")
        argv = [
            "plot-stage",
            "--registered",
            str(tmp_path / "pair" / "registered.parquet"),
            "--stage-changes",
            *[str(stage / "changes.parquet") for stage in stages],
            "--stage-dir",
            str(stages[1]),
            f"--previous={stages[0]}",
            "--plots",
            json.dumps({"top_k": 5}),
            "--out",
            str(out),
        ]
        assert start_job(argv, tmp_path, mode, tmp_path / f"{out.name}.log").wait(timeout=120) == 0
        figures[mode] = {p.name: p.read_bytes() for p in sorted(out.glob("*.png"))}
    assert len(figures["off"]) == 6
    assert figures["off"] == figures[sock]


def test_the_workflow_warms_the_worker_up_only_for_studies_with_many_figures(tmp_path, monkeypatch):
    from lidarfield.runner import launch

    commands = []

    class Spawned:
        def __init__(self, command, **kwargs):
            commands.append(command)

        def terminate(self):
            pass

        def wait(self, timeout=None):
            return 0

    monkeypatch.setattr(launch.subprocess, "Popen", Spawned)
    monkeypatch.delenv("LIDARFIELD_WORKER", raising=False)
    threshold = launch.WARM_UP_MIN_FIGURE_JOBS
    for figure_jobs in (0, threshold - 1, threshold, 27):
        launch.spawn(tmp_path / "results", figure_jobs=figure_jobs)
        launch.stop()
    assert ["--warm-up" in command for command in commands] == [False, False, True, True]


def test_the_workers_log_in_a_shared_folder_is_its_users_own_file(tmp_path):
    """In an allocation the log lies in the node's shared temporary folder: created 0600, and a
    symlink or another user's file placed at its name is never written through (no worker)."""
    from lidarfield.runner.launch import open_private_log

    umask = os.umask(0o002)
    try:
        with open_private_log(tmp_path / "new.log") as log:
            log.write("started\n")
    finally:
        os.umask(umask)
    assert stat.S_IMODE((tmp_path / "new.log").stat().st_mode) == 0o600
    victim = tmp_path / "victim.txt"
    victim.write_text("kept\n")
    (tmp_path / "link.log").symlink_to(victim)
    assert open_private_log(tmp_path / "link.log") is None
    assert victim.read_text() == "kept\n"
    if os.getuid() == 0:  # a file that another user made
        theirs = tmp_path / "theirs.log"
        theirs.write_text("")
        os.chown(theirs, pwd.getpwnam("nobody").pw_uid, -1)
        assert open_private_log(theirs) is None
