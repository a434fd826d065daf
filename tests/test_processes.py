"""A pool worker ends with the process that started it (a killed evaluation leaves no worker running)."""

from __future__ import annotations

import os
import pathlib
import signal
import subprocess
import sys
import time

import pytest

from shelf_env.processes import exit_with_parent

# a parent that starts a spawned pool worker (the initializer under test), prints the worker's pid,
# then waits to be killed
PARENT = """
import multiprocessing as mp, os, sys, time
from concurrent.futures import ProcessPoolExecutor
from shelf_env.processes import worker_initializer

if __name__ == "__main__":
    with ProcessPoolExecutor(1, mp_context=mp.get_context("spawn"), initializer=worker_initializer,
                             initargs=(os.getpid(),)) as pool:
        print(pool.submit(os.getpid).result(), flush=True)
        time.sleep(120)
"""


def alive(pid: int) -> bool:
    """The process exists and is not a zombie (a container's init may not reap the orphans it adopts)."""
    try:
        state = pathlib.Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state != "Z"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_a_killed_parent_takes_its_pool_worker_with_it(tmp_path: pathlib.Path) -> None:
    script = tmp_path / "parent.py"
    script.write_text(PARENT)
    env = {**os.environ, "PYTHONPATH": str(pathlib.Path(__file__).resolve().parents[1])}
    parent = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True, env=env)
    try:
        assert parent.stdout is not None
        worker = int(parent.stdout.readline())
        assert alive(worker)
        time.sleep(1.5)
        assert alive(worker)  # the watcher leaves a worker whose parent lives alone
        parent.send_signal(signal.SIGKILL)  # no shutdown runs: the pool cannot stop its worker itself
        parent.wait(timeout=30)
        deadline = time.monotonic() + 15
        while alive(worker) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert not alive(worker)
    finally:
        parent.kill()


def test_an_orphan_ends_at_once_and_the_interval_is_checked() -> None:
    code = ("import os, time\nfrom shelf_env.processes import exit_with_parent\n"
            "exit_with_parent(os.getppid() + 1, interval=0.05)\ntime.sleep(30)\n")
    env = {**os.environ, "PYTHONPATH": str(pathlib.Path(__file__).resolve().parents[1])}
    started = time.monotonic()
    done = subprocess.run([sys.executable, "-c", code], env=env, timeout=60)
    assert done.returncode == 1 and time.monotonic() - started < 25
    with pytest.raises(ValueError, match="interval must be > 0"):
        exit_with_parent(os.getpid(), interval=0)
