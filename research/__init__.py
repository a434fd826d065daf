"""Experiments that led nowhere (yet), kept reproducible: they may import the product (``shelf_env``,
``sb3_pixeldqn``); the product never imports them. Not installed: run from the repository root
(``python -m research.<module>``). Their pages are in docs/experiments/.
"""

from __future__ import annotations

import pathlib
import sys
from collections.abc import Callable

from shelf_env.files import write_text_atomically


def print_or_write(text: str, out: pathlib.Path | None) -> None:
    """An experiment's table or page: printed where ``out`` is None, else written to ``out`` atomically."""
    if out is None:
        print(text, end="" if text.endswith("\n") else "\n")
    else:
        write_text_atomically(out, text)


def table_command(make: Callable[[], str], out: pathlib.Path | None) -> int:
    """An experiment CLI's body: the text ``make`` returns, printed or written (`print_or_write`); a `ValueError` it
    raises is one ``error:`` line on stderr and exit status 2, with nothing written."""
    try:
        text = make()
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print_or_write(text, out)
    return 0
