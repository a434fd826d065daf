"""Timing helpers the benchmark scripts share."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any


def seconds_per_call(call: Callable[[Any], Any], items: Sequence[Any]) -> float:
    """Mean wall seconds of ``call(item)`` over ``items``, after one warm-up call (imports, caches, allocations)."""
    call(items[0])
    start = time.perf_counter()
    for item in items:
        call(item)
    return (time.perf_counter() - start) / len(items)
