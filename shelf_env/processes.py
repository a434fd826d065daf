"""Worker processes that end with the process that started them.

A killed evaluation or collection (SIGKILL, SIGTERM, a closed terminal) does not run its pool's
shutdown, so its spawned workers would go on for hours, reparented, eating the cores a rerun needs
(and discarding what they compute). `exit_with_parent` is the workers' initializer half of the fix:
a daemon thread that ends the worker as soon as its parent is gone.

`yield_cpu` lowers a background job's CPU priority so that it runs beside other work (the teacher dataset's
collection) without slowing it."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable
from typing import Any

__all__ = ["autogroup_niceness", "exit_with_parent", "worker_initializer", "yield_cpu"]

#: Linux's per-session CPU group of this process (``sched_autogroup``), absent on other systems.
AUTOGROUP = "/proc/self/autogroup"


def exit_with_parent(parent_pid: int, interval: float = 1.0) -> threading.Thread:
    """Start a daemon thread that ends this process (``os._exit(1)``) within ``interval`` seconds of
    its parent ``parent_pid`` ending; returns the thread. A process whose parent is already not
    ``parent_pid`` ends at once."""
    if interval <= 0:
        raise ValueError(f"interval must be > 0 seconds, got {interval}")

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(interval)
        os._exit(1)

    thread = threading.Thread(target=watch, name="exit-with-parent", daemon=True)
    thread.start()
    return thread


def worker_initializer(parent_pid: int, then: Callable[..., Any] | None = None, *args: Any) -> None:
    """A pool's ``initializer``: `exit_with_parent(parent_pid)`, then ``then(*args)`` if given."""
    exit_with_parent(parent_pid)
    if then is not None:
        then(*args)


def autogroup_niceness() -> int | None:
    """The niceness of this process's session CPU group (Linux ``sched_autogroup``), or None where it has none:
    another system, autogroups switched off, or a process in a group that is not an autogroup (a container's
    cgroup), where the kernel's file exists but reads empty."""
    try:
        with open(AUTOGROUP) as f:
            words = f.read().split()
        return int(words[-1]) if words else None
    except (OSError, ValueError):
        return None


def yield_cpu(niceness: int) -> tuple[int, int | None]:
    """Lower this process's CPU priority by ``niceness`` (0..19, ``os.nice``), and, where it leads its own session
    (started with ``setsid``) on a Linux with autogroups, its session's group's too; returns the process's niceness
    and the group's (None where it was left alone).

    Why the group: Linux shares the CPU between sessions' *autogroups* first and by niceness only within one, so a
    job started with ``setsid nice -n 10 ...`` still takes as much CPU as a training run started in another session
    (measured on 2 cores: a collector's worker at nice 10 got 56 % of a core beside a distillation's 56 %; with its
    group at nice 10 the distillation got 147 %). Only a session's leader changes its group, since the group may
    hold an interactive shell otherwise."""
    if not 0 <= niceness <= 19:
        raise ValueError(f"niceness must be in 0..19, got {niceness}")
    now = os.nice(niceness)
    group = None
    if niceness and os.getsid(0) == os.getpid() and os.path.exists(AUTOGROUP):
        try:
            with open(AUTOGROUP, "w") as f:
                f.write(str(niceness))
        except OSError:  # not permitted here (a container's /proc): the process's niceness stands
            pass
        else:
            group = autogroup_niceness()
    return now, group
