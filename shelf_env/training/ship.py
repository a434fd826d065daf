"""Ship the trained models: ``examples/pretrained/<model>.zip`` and their card, from the committed runs.

    python -m shelf_env.training.ship                     # every model whose run is over (p_s, s)
    python -m shelf_env.training.ship p_s --results results/models
    bash scripts/ship_models.sh                  # the same, with the evaluation when there is one

A model ships once its run's curriculum is over (``finished`` in ``results/training/<model>/
progress.json``: the last stage has trained its ``max_stage_timesteps``), never mid-run; a model
named on the command line whose run is not over is refused by name, and nothing is written. Each
zip is the run's final checkpoint, checked before it is copied (atomically): at most ``MAX_MB``,
loadable with ``PixelDoubleDQN.load(path)`` and no other file, and of the model's layout (P+S: pick
and both pushes; S: pick only). The card, ``README.md`` beside the zips, covers every shipped
model (`shelf_env.training.model_card.model_cards`), with the evaluation table when ``--results`` is given.
"""

from __future__ import annotations

import argparse
import csv
import json
import pathlib

from sb3_pixeldqn import PixelDoubleDQN
from shelf_env.evaluation.protocol import checkpoint_primitives
from shelf_env.files import copy_atomically, write_text_atomically
from shelf_env.training.config import PRESETS
from shelf_env.training.model_card import model_cards

#: The shipped models, by the name of their preset and run (the preset gives the layout's primitives).
MODELS = ("p_s", "s")
MAX_MB = 20.0
COMMAND = "bash scripts/train_model.sh {model}"


def run_is_over(run: pathlib.Path) -> bool:
    """Whether the run's curriculum is over (its state's ``finished`` is set)."""
    progress = json.loads((run / "progress.json").read_text())
    return (progress.get("curriculum") or {}).get("finished") is not None


def check_checkpoint(path: pathlib.Path, model: str) -> None:
    """Raise ValueError unless ``path`` is a shippable checkpoint of ``model``'s layout."""
    size_mb = path.stat().st_size / 2**20
    if size_mb > MAX_MB:
        raise ValueError(f"{path} is {size_mb:.1f} MB, over the {MAX_MB:g} MB a shipped model may weigh")
    loaded = PixelDoubleDQN.load(path, device="cpu")  # loads alone (its errors name the problem)
    expected = tuple(PRESETS[model].primitives)
    if checkpoint_primitives(path) != expected:
        raise ValueError(f"{path} has the maps {loaded.policy.maps}, not those of {model!r} (primitives {expected})")


def ship(models: list[str] | None, training: pathlib.Path, out: pathlib.Path,
         results: pathlib.Path | None = None) -> list[pathlib.Path]:
    """Copy the finished runs' checkpoints to ``out`` and write the card; returns the zips shipped now.

    ``models`` None ships every model whose run is over; named models must be over.
    """
    unknown = sorted(set(models or []) - set(MODELS))
    if unknown:
        raise ValueError(f"unknown models {unknown}; known: {list(MODELS)}")
    if models is None:
        models = [m for m in MODELS if (training / m / "progress.json").exists() and run_is_over(training / m)]
    for model in models:
        run = training / model
        if not (run / "progress.json").exists() or not (run / "model.zip").exists():
            raise ValueError(f"{run} holds no run (progress.json and model.zip): "
                             f"train it with {COMMAND.format(model=model)}")
        if not run_is_over(run):
            raise ValueError(f"the {model!r} run in {run} is not over (its curriculum has no 'finished'); "
                             f"go on with {COMMAND.format(model=model)}")
        check_checkpoint(run / "model.zip", model)
    on_shelf = [m for m in MODELS if m in models or (out / f"{m}.zip").exists()]
    if results is not None:  # checked before anything is written: the card needs every shipped model's rows
        with open(results / "results.csv", newline="") as f:
            evaluated = {row["policy"] for row in csv.DictReader(f)}
        missing = [m for m in on_shelf if m not in evaluated]
        if missing:
            raise ValueError(f"{results}/results.csv has no rows of {missing}; evaluate them or leave out --results")
    shipped = [copy_atomically(training / m / "model.zip", out / f"{m}.zip") for m in models]
    if on_shelf:
        cards = model_cards([(training / m, out / f"{m}.zip", COMMAND.format(model=m)) for m in on_shelf], results)
        write_text_atomically(out / "README.md", cards)
    return shipped


PROG = "python -m shelf_env.training.ship"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog=PROG, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("models", nargs="*", help=f"models to ship, of {list(MODELS)} (default: every run that is over)")
    p.add_argument("--training", type=pathlib.Path, default=pathlib.Path("results/training"),
                   help="where the runs' committed mirrors are")
    p.add_argument("--out", type=pathlib.Path, default=pathlib.Path("examples/pretrained"),
                   help="where the shipped zips and their card go")
    p.add_argument("--results", type=pathlib.Path, default=None, help="an evaluation of the shipped models")
    args = p.parse_args(argv)
    try:
        shipped = ship(args.models or None, args.training, args.out, args.results)
    except (OSError, KeyError, ValueError) as err:
        print(f"ship: error: {err}", flush=True)
        return 2
    print("shipped: " + (", ".join(str(z) for z in shipped) or "nothing (no run is over)"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
