"""Atomic writes of text, JSON and copies for the env's tools (evaluations, reports, training runs),
on top of the algorithm's one atomic writer (`sb3_pixeldqn.files.write_atomically`): a file on
disk is its old version or the complete new one, and a failed write leaves no partial file."""

from __future__ import annotations

import json
import os
import pathlib
from typing import Any

from sb3_pixeldqn.files import write_atomically

__all__ = ["copy_atomically", "write_atomically", "write_json_atomically", "write_text_atomically"]


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
