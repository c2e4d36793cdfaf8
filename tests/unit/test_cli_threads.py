"""The ``lidarfield`` command runs OpenBLAS with one thread unless the user chose how many
(``cli.one_blas_thread``): set before numpy loads, left alone when the user set it or numpy is
loaded already (a library caller's process is not changed behind its back)."""

from __future__ import annotations

import os
import subprocess
import sys

from lidarfield.cli import one_blas_thread

# A command that exits with its one error line (no dataset there), then the variable it ran with.
COMMAND = (
    "import os, sys\n"
    "from lidarfield.cli import main\n"
    "status = main(['info', sys.argv[1]])\n"
    "print(status, 'numpy' in sys.modules, os.environ.get('OPENBLAS_NUM_THREADS'))"
)


def run_command(folder, **env) -> list[str]:
    clean = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    out = subprocess.run(
        [sys.executable, "-c", COMMAND, str(folder)], capture_output=True, text=True, check=True, env={**clean, **env}
    )
    return out.stdout.split()


def test_the_command_runs_openblas_with_one_thread_unless_the_user_set_it(tmp_path):
    status, numpy_loaded, threads = run_command(tmp_path / "missing")
    assert status != "0" and numpy_loaded == "True" and threads == "1"
    assert run_command(tmp_path / "missing", OPENBLAS_NUM_THREADS="2")[2] == "2"


def test_a_process_with_numpy_loaded_is_left_as_it_is(monkeypatch):
    import numpy  # noqa: F401 (loaded: its OpenBLAS has read the variable already)

    monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    one_blas_thread()
    assert "OPENBLAS_NUM_THREADS" not in os.environ
