"""The project's one atomic file writer: a file on disk is its old version or the complete new one.

Checkpoints, replay buffers, evaluation cells, results and plots are written by long jobs that may
be killed at any moment (the machine goes, the session ends). Each is written to a hidden
``.<name>.partial`` file beside the target and moved over it with `os.replace`, which is atomic
on POSIX and Windows; a failed write leaves no partial file behind.
"""

from __future__ import annotations

import json
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


def write_text_atomically(path: str | os.PathLike, text: str) -> pathlib.Path:
    """`write_atomically` for a text file (UTF-8)."""
    return write_atomically(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


def copy_atomically(src: str | os.PathLike, dst: str | os.PathLike) -> pathlib.Path:
    """Copy the file ``src`` to ``dst`` (contents only), atomically."""
    data = pathlib.Path(src).read_bytes()
    return write_atomically(dst, lambda tmp: tmp.write_bytes(data))


def write_json_atomically(path: str | os.PathLike, data: Any, indent: int | None = 1) -> pathlib.Path:
    """`write_atomically` for JSON (NaN allowed, as Python's json writes it)."""
    return write_text_atomically(path, json.dumps(data, indent=indent, allow_nan=True))
