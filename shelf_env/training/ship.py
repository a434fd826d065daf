"""Ship the models: ``examples/pretrained/`` and its card, from the committed runs and a distillation.

    python -m shelf_env.training.ship                     # every model whose run is over (s, v1/p_s)
    python -m shelf_env.training.ship --distilled runs/distill_scaling/NAME.zip \\
        --results results/models_v2 results/models    # a distilled P+S as p_s.zip, the cards' tables
    python -m shelf_env.training.ship --geometry-risk results/fall_geometry/filter/p_s_geo10.geometry_risk.pt \\
        --geometry-label p_s_geo10+geometry-filter+pick-guard+loop-breaker --results ...   # p_s.zip, filtered
    bash scripts/ship_models.sh                  # the same, with the evaluations when there are some

The shelf holds the P+S to use, ``p_s.zip``: since 2026-12-04 a P+S distilled from the teacher dataset
(``python -m shelf_env.training.distill``) with its report beside it (``p_s.distill.json``); ``s.zip``,
the pick-only S trained with PixelDoubleDQN; and ``v1/p_s.zip``, the P+S trained with PixelDoubleDQN
that was ``p_s.zip`` until then (the model every result before that date calls ``p_s``, and the one the
distillation started from). Nothing shipped is lost: a distilled ``p_s.zip`` that a new one replaces
moves, with its report, to the first free ``v<k>/`` (k >= 2), and keeps its card there.

A distilled ``p_s.zip`` may ship with a camera-only pick filter beside it (``--geometry-risk``: a
`shelf_env.fall_filter.GeometryRisk`, copied as ``p_s.geometry_risk.pt``, with ``p_s.geometry_risk.json`` saying where
it came from and under which label evaluations played it, ``--geometry-label``): the policy to use is then
``p_s.zip`` under the filter and the wrappers after it that the label names (since 2026-12-05
``p_s.zip+geometry-filter+pick-guard+loop-breaker``, `shelf_env.policies`), and the card says so with that policy's
evaluation. The filter was evaluated with those Q-maps, so it moves with them to ``v<k>/`` when a new
``p_s.zip`` replaces them.

A run ships once its curriculum is over (``finished`` in ``results/training/<model>/progress.json``: the
last stage has trained its ``max_stage_timesteps``), never mid-run; a model named on the command line
whose run is not over is refused by name, and nothing is written. A distilled model ships with the
report its distillation wrote beside it (``NAME.distill.json``); without one it is refused. Each zip is
checked before it is copied (atomically): at most ``MAX_MB``, loadable with ``PixelDoubleDQN.load(path)``
and no other file, and of the model's layout (P+S: pick and both pushes; S: pick only). The card,
``README.md`` on the shelf, covers every shipped model (`shelf_env.training.model_card`), each with its
evaluation table from the first ``--results`` folder that evaluated it (a distilled model under the name
its distillation gave it).
"""

from __future__ import annotations

import argparse
import csv
import json
import pathlib
from typing import Any

from sb3_pixeldqn import PixelDoubleDQN
from shelf_env.evaluation.protocol import checkpoint_primitives
from shelf_env.fall_filter import GEOMETRY_FILTER, GeometryRisk, geometry_risk_path
from shelf_env.files import copy_atomically, write_json_atomically, write_text_atomically
from shelf_env.pick_guard import PICK_GUARD
from shelf_env.policies import LOOP_BREAKER
from shelf_env.training.config import PRESETS
from shelf_env.training.distill import report_path
from shelf_env.training.model_card import (
    WRAPPER_HOME,
    WRAPPER_NAME,
    distilled_card,
    filter_wrappers,
    filtered_name,
    model_card,
    model_cards,
    spoken_list,
)

#: The runs that ship, by the name of their preset and run (the preset gives the layout's primitives), and
#: where each goes on the shelf: the RL-trained P+S was ``p_s.zip`` until the distilled one replaced it.
MODELS = {"p_s": "v1/p_s.zip", "s": "s.zip"}
#: Where a distilled P+S goes, and its distillation report beside it (what its card is written from).
DISTILLED = "p_s.zip"
DISTILLED_REPORT = report_path(DISTILLED).name
MAX_MB = 20.0
COMMAND = "bash scripts/train_model.sh {model}"
DISTILL_COMMAND = "bash results/distill_scaling/run.sh"
HEAD = ("`p_s.zip` {what}: distilled from the teacher dataset into the Q-maps of `v1/p_s.zip`, the P+S "
        "trained with PixelDoubleDQN that was `p_s.zip` until 2026-12-04 (every result before that date calls it "
        "`p_s`). Each model was made by the command in its card and copied here with `bash scripts/ship_models.sh` "
        "(which also writes this file).")
#: The geometry pick filter a distilled P+S may ship with, beside it, and what says where it came from.
FILTER_RISK = geometry_risk_path(DISTILLED).name
FILTER_INFO = pathlib.Path(FILTER_RISK).with_suffix(".json").name
FILTER_COMMAND = "bash results/fall_geometry/run.sh"
#: What the head adds when earlier distilled P+S are on the shelf (``v<k>/``, k >= 2).
ARCHIVE_HEAD = (" The distilled P+S that `p_s.zip` replaced stay here, each in `v<k>/` with its report and card ({}); "
                "results name each distilled model by its distillation's name.")


def filtered_head(label: str) -> str:
    """The head when the shelf's p_s.zip ships with its filter, played as ``label`` says: the policy to use is that."""
    parts = [f"a camera-only pick filter (`{FILTER_RISK}`, `shelf_env.fall_filter`)"]
    parts += [f"{WRAPPER_NAME[w]} ({WRAPPER_HOME[w]})" for w in filter_wrappers(label)[1:]]
    return (f"`{filtered_name(DISTILLED, label)}` is the P+S to use: the Q-maps of `p_s.zip` played under "
            f"{spoken_list(parts)}. ")


def archived(out: pathlib.Path) -> list[int]:
    """The versions ``k >= 2`` of the earlier distilled P+S on the shelf (``v<k>/p_s.zip`` and its report),
    newest first."""
    folders = [report.parent.name.removeprefix("v") for report in out.glob(f"v*/{DISTILLED_REPORT}")]
    return sorted((k for k in map(int, filter(str.isdigit, folders)) if k >= 2), reverse=True)


def shelf_label(report: pathlib.Path) -> str:
    """The label a distilled model's results carry: the file stem its distillation wrote (the report's ``out``)."""
    return pathlib.Path(json.loads(report.read_text())["out"]).stem


def replaced_version(out: pathlib.Path, distilled: pathlib.Path) -> int | None:
    """The ``v<k>`` the shelf's distilled ``p_s.zip`` moves to when ``distilled`` replaces it (None: nothing to
    move, or the same bytes); a ValueError when the shelf's ``p_s.zip`` has no report, so its card would be lost."""
    current = out / DISTILLED
    if not current.is_file() or current.read_bytes() == distilled.read_bytes():
        return None
    if not (out / DISTILLED_REPORT).is_file():
        raise ValueError(f"{current} has no distillation report beside it ({DISTILLED_REPORT}), so it cannot move "
                         "to v<k>/ with its card; move it off the shelf first")
    return max([*archived(out), 1]) + 1


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


def check_geometry_risk(path: pathlib.Path, checkpoint: pathlib.Path) -> None:
    """Raise ValueError unless ``path`` is a `GeometryRisk` fitted on ``checkpoint``'s observations."""
    risk = GeometryRisk.load(path)  # its errors name the file
    expected = tuple(PixelDoubleDQN.load(checkpoint, device="cpu").observation_space.shape)
    if tuple(risk.info["obs_shape"]) != expected:
        raise ValueError(f"{path} was fitted on observations of shape {tuple(risk.info['obs_shape'])}; {checkpoint}'s "
                         f"are {expected}")


def evaluated_policies(folder: pathlib.Path) -> set[str]:
    """The policy labels of an evaluation folder's ``results.csv``."""
    with open(folder / "results.csv", newline="") as f:
        return {row["policy"] for row in csv.DictReader(f)}


def results_with(folders: list[tuple[pathlib.Path, set[str]]], label: str) -> pathlib.Path:
    """The first of the ``(folder, its policies)`` that evaluated ``label``; a ValueError naming them if none."""
    for folder, policies in folders:
        if label in policies:
            return folder
    raise ValueError(f"{', '.join(str(f / 'results.csv') for f, _ in folders)} has no rows of [{label!r}]; "
                     "evaluate it or leave out --results")


def ship(models: list[str] | None, training: pathlib.Path, out: pathlib.Path,
         results: list[pathlib.Path] | None = None, distilled: pathlib.Path | None = None,
         geometry_risk: pathlib.Path | None = None, geometry_label: str | None = None) -> list[pathlib.Path]:
    """Copy the finished runs' checkpoints (and ``distilled``) to ``out`` and write the card; returns the zips
    shipped now.

    ``models`` None ships every run that is over; named models must be over. ``geometry_risk`` ships beside the
    distilled ``p_s.zip`` (shipped now or on the shelf), played under the label ``geometry_label`` in ``results``.
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
    if distilled is not None:
        if not report_path(distilled).is_file():
            raise ValueError(f"{distilled} has no distillation report beside it ({report_path(distilled).name}): "
                             "ship what python -m shelf_env.training.distill wrote")
        check_checkpoint(distilled, "p_s")
    if geometry_risk is not None:
        target = distilled if distilled is not None else out / DISTILLED
        if not (out / DISTILLED_REPORT).is_file() and distilled is None:
            raise ValueError(f"a geometry risk ships beside a distilled {DISTILLED}; {out} holds none (ship one with "
                             "--distilled)")
        if not geometry_label:
            raise ValueError("--geometry-risk needs --geometry-label: the label its evaluations gave the filtered "
                             f"policy (e.g. NAME{GEOMETRY_FILTER}{PICK_GUARD}{LOOP_BREAKER})")
        filter_wrappers(geometry_label)
        check_geometry_risk(geometry_risk, target)
    replaced = replaced_version(out, distilled) if distilled is not None else None
    versions = ([replaced] if replaced else []) + archived(out)  # the earlier distilled P+S, newest first
    report = report_path(distilled) if distilled is not None else out / DISTILLED_REPORT
    # (name on the shelf, its source (a distilled model's: its report's copy on the shelf), its label in results,
    # and for a distilled P+S its version: the RL P+S is v1, so the first distilled one is v2)
    cards: list[tuple[str, pathlib.Path, str, int]] = []
    if report.is_file():
        cards.append((DISTILLED, out / DISTILLED_REPORT, shelf_label(report), max([*versions, 1]) + 1))
    for k in versions:
        source = out / DISTILLED_REPORT if k == replaced else out / f"v{k}" / DISTILLED_REPORT
        cards.append((f"v{k}/{DISTILLED}", out / f"v{k}" / DISTILLED_REPORT, shelf_label(source), k))
    cards += [(MODELS[m], training / m, m, 1) for m in MODELS if m in models or (out / MODELS[m]).exists()]
    # the filter each distilled P+S ships with (what shipped it): the new one's, else the file beside its Q-maps now
    # (a replaced p_s.zip's is still beside p_s.zip; it moves with them to v<k>/ below)
    beside = {f"v{k}/{DISTILLED}": out / ("" if k == replaced else f"v{k}") / FILTER_INFO for k in versions}
    if replaced is None:
        beside[DISTILLED] = out / FILTER_INFO
    filters: dict[str, dict[str, Any]] = {name: json.loads(info.read_text()) for name, info in beside.items()
                                          if info.is_file()}
    if geometry_risk is not None:
        filters[DISTILLED] = {"source": geometry_risk.as_posix(), "command": FILTER_COMMAND, "label": geometry_label}
    # checked before anything is written: the card needs every shipped model's (and filtered policy's) rows
    evaluations = [(folder, evaluated_policies(folder)) for folder in results or []]
    folders = [results_with(evaluations, label) if results else None for _, _, label, _ in cards]
    filter_folders = {name: results_with(evaluations, info["label"]) if results else None
                      for name, info in filters.items()}
    shipped = [copy_atomically(training / m / "model.zip", out / MODELS[m]) for m in models]
    if distilled is not None:
        if replaced:  # the P+S it replaces keeps its place on the shelf, with its report (and its filter)
            copy_atomically(out / DISTILLED_REPORT, out / f"v{replaced}" / DISTILLED_REPORT)
            copy_atomically(out / DISTILLED, out / f"v{replaced}" / DISTILLED)
            for name in (FILTER_RISK, FILTER_INFO):
                if (out / name).is_file():
                    copy_atomically(out / name, out / f"v{replaced}" / name)
                    (out / name).unlink()
        copy_atomically(report_path(distilled), out / DISTILLED_REPORT)
        shipped.insert(0, copy_atomically(distilled, out / DISTILLED))
    if geometry_risk is not None:
        shipped.append(copy_atomically(geometry_risk, out / FILTER_RISK))
        write_json_atomically(out / FILTER_INFO, filters[DISTILLED])
    texts = []
    for (name, source, _, k), folder in zip(cards, folders):
        if source.name == DISTILLED_REPORT:
            # a report names its starting model where it was then: p_s.zip then is the version before it now
            moved = {(out / DISTILLED).as_posix(): (out / f"v{k - 1}" / DISTILLED).as_posix()}
            played = (filters[name], filter_folders[name]) if name in filters else None
            texts.append((name, distilled_card(source, out / name, folder, DISTILL_COMMAND, name, moved, played)))
        else:
            texts.append((name, model_card(source, out / name, folder, COMMAND.format(model=source.name), name)))
    if texts:
        head = ""
        if cards[0][0] == DISTILLED:
            filtered = DISTILLED in filters
            head = (filtered_head(filters[DISTILLED]["label"]) if filtered else "") \
                + HEAD.format(what="holds its Q-maps" if filtered else "is the P+S to use")
            head += ARCHIVE_HEAD.format(", ".join(f"`v{k}/`" for k in versions)) if versions else ""
        write_text_atomically(out / "README.md", model_cards(texts, head))
    return shipped


PROG = "python -m shelf_env.training.ship"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog=PROG, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("models", nargs="*", help=f"runs to ship, of {list(MODELS)} (default: every run that is over)")
    p.add_argument("--distilled", type=pathlib.Path, default=None,
                   help=f"a distilled P+S to ship as {DISTILLED} (its NAME.distill.json beside it)")
    p.add_argument("--training", type=pathlib.Path, default=pathlib.Path("results/training"),
                   help="where the runs' committed mirrors are")
    p.add_argument("--out", type=pathlib.Path, default=pathlib.Path("examples/pretrained"),
                   help="where the shipped zips and their card go")
    p.add_argument("--results", type=pathlib.Path, nargs="+", default=None,
                   help="evaluations of the shipped models (each card's table: the first that has the model)")
    p.add_argument("--geometry-risk", type=pathlib.Path, default=None,
                   help=f"a GeometryRisk to ship beside the distilled {DISTILLED} as {FILTER_RISK} "
                        "(python -m research.fall_geometry export)")
    p.add_argument("--geometry-label", default=None,
                   help="the label evaluations gave the filtered policy (its rows in --results)")
    args = p.parse_args(argv)
    try:
        shipped = ship(args.models or None, args.training, args.out, args.results, args.distilled,
                       args.geometry_risk, args.geometry_label)
    except (OSError, KeyError, ValueError) as err:
        print(f"ship: error: {err}", flush=True)
        return 2
    print("shipped: " + (", ".join(str(z) for z in shipped) or "nothing (no run is over)"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
