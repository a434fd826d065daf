"""A pool worker ends with the process that started it (a killed evaluation leaves no worker running)."""

from __future__ import annotations

import json
import os
import pathlib
import signal
import subprocess
import sys
import time

import pytest

import shelf_env.processes
from shelf_env.processes import autogroup_niceness, exit_with_parent, yield_cpu

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


YIELD = """
import json, os
from shelf_env.processes import autogroup_niceness, yield_cpu
before = autogroup_niceness()
now, set_to = yield_cpu(5)
print(json.dumps({"now": now, "set_to": set_to, "before": before, "after": autogroup_niceness()}))
"""


@pytest.mark.parametrize("leader", [False, True])
def test_yield_cpu_lowers_the_process_and_only_its_own_session_s_group(leader: bool) -> None:
    """The process's niceness rises by the amount asked; the session's CPU group (Linux autogroup) is lowered only
    where the process leads its own session (``setsid``), never a group it shares with the shell that started it."""
    done = subprocess.run([sys.executable, "-c", YIELD], capture_output=True, text=True, timeout=60,
                          start_new_session=leader, cwd=pathlib.Path(__file__).resolve().parents[1])
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout)
    assert out["now"] == min(19, os.nice(0) + 5)
    if not leader:
        assert out["set_to"] is None and out["after"] == out["before"]
    elif out["set_to"] is not None:  # written where this system lets a process change its group
        assert out["set_to"] == 5 and out["after"] == 5
    with pytest.raises(ValueError, match="niceness must be in 0..19, got 20"):
        yield_cpu(20)


@pytest.mark.parametrize(("text", "expected"), [("/autogroup-12 nice 5\n", 5), ("/autogroup-3 nice 0\n", 0),
                                                ("", None), ("/autogroup-3 nice ?\n", None)])
def test_autogroup_niceness_reads_the_kernel_s_line_and_none_where_there_is_no_group(
        tmp_path: pathlib.Path, monkeypatch: pytest.MonkeyPatch, text: str, expected: int | None) -> None:
    """An empty file is what a process outside any autogroup reads (a container's cgroup, CI): None, not a crash."""
    path = tmp_path / "autogroup"
    path.write_text(text)
    monkeypatch.setattr(shelf_env.processes, "AUTOGROUP", str(path))
    assert autogroup_niceness() == expected
    monkeypatch.setattr(shelf_env.processes, "AUTOGROUP", str(tmp_path / "absent"))
    assert autogroup_niceness() is None
