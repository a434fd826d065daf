"""The atomic file writer of checkpoints and replay buffers: a file on disk is its old version or the
complete new one.

Checkpoints and replay buffers are written by long jobs that may be killed at any moment (the
machine goes, the session ends); an env's own tools can write through it too. Each is written to a
hidden ``.<name>.partial`` file beside the target and moved over it with `os.replace`, which is atomic
on POSIX and Windows; a failed write leaves no partial file behind.
"""

from __future__ import annotations

import os
import pathlib
from collections.abc import Callable
from typing import Any


def write_atomically(path: str | os.PathLike, write: Callable[[pathlib.Path], Any]) -> pathlib.Path:
    """Call ``write(tmp)`` to write a temporary file, then move it to ``path`` (parents created).

    ``write`` must write exactly the path it is given (for matplotlib, pass ``format=``: the
    temporary name ends in ``.partial``). Returns ``path``. If ``write`` raises, ``path`` is
    untouched and the temporary file is removed.
    """
    final = pathlib.Path(path)
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = final.with_name(f".{final.name}.partial")
    try:
        write(tmp)
        if not tmp.is_file():
            raise RuntimeError(f"the writer of {final} did not write its temporary file {tmp}")
        os.replace(tmp, final)
    finally:
        if tmp.exists():
            tmp.unlink()
    return final
