"""Worker processes that end with the process that started them.

A killed evaluation or collection (SIGKILL, SIGTERM, a closed terminal) does not run its pool's
shutdown, so its spawned workers would go on for hours, reparented, eating the cores a rerun needs
(and discarding what they compute). `exit_with_parent` is the workers' initializer half of the fix:
a daemon thread that ends the worker as soon as its parent is gone."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable
from typing import Any

__all__ = ["exit_with_parent", "worker_initializer"]


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
