"""Every option of every command line the project ships says what it does (``--help``)."""

from __future__ import annotations

import argparse
from collections.abc import Callable

import pytest

from shelf_env.cli import demo, evaluate, train
from shelf_env.evaluation import report, traces
from shelf_env.privileged import dataset
from shelf_env.training import distill, model_card, ship, zoo

COMMANDS: dict[str, Callable[[list[str]], object]] = {
    "shelf-demo": demo.main, "shelf-evaluate": evaluate.main, "shelf-train": train.main,
    "python -m shelf_env.evaluation.report": report.main, "python -m shelf_env.evaluation.traces": traces.main,
    "python -m shelf_env.privileged.dataset": dataset.main, "python -m shelf_env.training.model_card": model_card.main,
    "python -m shelf_env.training.ship": ship.main, "python -m shelf_env.training.zoo": zoo.main,
    "python -m shelf_env.training.distill": distill.main,
}


class Parsed(Exception):
    pass


def parsers_of(main: Callable[[list[str]], object], monkeypatch: pytest.MonkeyPatch) -> list[argparse.ArgumentParser]:
    """The parser ``main`` builds (and its sub-commands' parsers), caught at its first parse."""
    caught: list[argparse.ArgumentParser] = []

    def catch(self: argparse.ArgumentParser, *args: object, **kwargs: object) -> None:
        caught.append(self)
        raise Parsed

    monkeypatch.setattr(argparse.ArgumentParser, "parse_args", catch)
    monkeypatch.setattr(argparse.ArgumentParser, "parse_known_args", catch)
    with pytest.raises(Parsed):
        main([])
    found = list(caught)
    for parser in caught:
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                found += list(action.choices.values())
    return found


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_every_option_has_help(command: str, monkeypatch: pytest.MonkeyPatch) -> None:
    missing = [f"{p.prog}: {'/'.join(a.option_strings) or a.dest}" for p in parsers_of(COMMANDS[command], monkeypatch)
               for a in p._actions
               if not isinstance(a, (argparse._HelpAction, argparse._SubParsersAction)) and not a.help]
    assert missing == []
