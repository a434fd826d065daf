"""Model cards for shipped checkpoints, written from what the run and the evaluation left on disk.

    python -m shelf_env.training.model_card results/training/p_s --zip examples/pretrained/p_s.zip \\
        --results results/models --command "bash scripts/train_model.sh p_s" --out examples/pretrained/p_s.md
    python -m shelf_env.training.model_card results/training/p_s results/training/s \\
        --zip examples/pretrained/p_s.zip examples/pretrained/s.zip --command "..." "..." \\
        --results results/models --out examples/pretrained/README.md     # both cards in one file

Reads the run's ``progress.json`` (configuration, steps, wall time, the sessions with their
machines, the curriculum's stages and greedy checks) and ``episodes.csv`` (when each stage was
reached in wall-clock time), and the evaluation's ``results.csv``. It writes markdown: how to load
the model, the command, the training (steps, wall time, hardware, stages reached and when) and the
evaluation table of the model beside every other policy evaluated on the same scenes.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import pathlib
from typing import Any

from shelf_env.files import write_text_atomically


def stage_times(run: pathlib.Path, history: list[list[int]]) -> list[tuple[int, int, float | None]]:
    """(N, first env step, wall-clock minutes) of every curriculum stage; minutes from episodes.csv."""
    minutes: dict[int, float] = {}
    episodes = run / "episodes.csv"
    if episodes.exists():
        with open(episodes, newline="") as f:
            for row in csv.DictReader(f):
                n = int(float(row["num_objects"]))
                minutes.setdefault(n, float(row["wall_seconds"]) / 60)
    return [(int(n), int(step), minutes.get(int(n))) for step, n in history]


def evaluation_table(results: pathlib.Path, label: str) -> str:
    """SR / AE / mAE per N of ``label`` and of the other policies of the same evaluation."""
    with open(results / "results.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    if not any(r["policy"] == label for r in rows):
        raise ValueError(f"{results}/results.csv has no rows of policy {label!r}")
    policies = [label] + sorted({r["policy"] for r in rows} - {label})
    sets = sorted({r["object_set"] for r in rows})
    lines = ["| objects | N | " + " | ".join(f"{p} SR %" for p in policies) + f" | {label} AE | {label} mAE |",
             "|---|---|" + "---|" * (len(policies) + 2)]
    by_key = {(r["policy"], r["object_set"], int(r["num_objects"])): r for r in rows}
    for object_set in sets:
        for n in sorted({int(r["num_objects"]) for r in rows if r["object_set"] == object_set}):
            cells = []
            for p in policies:
                r = by_key.get((p, object_set, n))
                cells.append("-" if r is None else f"{float(r['sr_mean']):.1f} ± {float(r['sr_std']):.1f}")
            own = by_key.get((label, object_set, n))
            ae = "-" if own is None or math.isnan(float(own["ae_mean"])) else f"{float(own['ae_mean']):.2f}"
            mae = "-" if own is None or math.isnan(float(own["mae_mean"])) else f"{float(own['mae_mean']):.2f}"
            lines.append(f"| {object_set} | {n} | " + " | ".join(cells) + f" | {ae} | {mae} |")
    return "\n".join(lines)


def model_card(run: pathlib.Path, zip_path: pathlib.Path, results: pathlib.Path | None, command: str) -> str:
    """The markdown card of the model trained in ``run`` and shipped as ``zip_path``."""
    progress: dict[str, Any] = json.loads((run / "progress.json").read_text())
    config = progress["config"]
    layout = "P+S (pick-and-place, push-left, push-right)" if "push" in config["primitives"] else "S (pick-and-place)"
    curriculum = progress.get("curriculum") or {}
    stages = stage_times(run, curriculum.get("history", []))
    greedy = curriculum.get("greedy_history", [])
    sessions = progress.get("sessions", [])
    machines = sorted({f"{s['machine']}, {s['torch_threads']} torch threads, {s['device']}"
                       + (f", {s['n_envs']} env processes" if s.get("n_envs", 1) > 1 else "") for s in sessions})
    size_mb = zip_path.stat().st_size / 2**20 if zip_path.exists() else float("nan")
    out = [f"# `{zip_path.name}`: PixelDoubleDQN, {layout}", "",
           "```python",
           "from sb3_pixeldqn import PixelDoubleDQN",
           f'model = PixelDoubleDQN.load("{zip_path.as_posix()}")   # {size_mb:.1f} MB, no other file needed',
           "```", "",
           f"Observation {config['pixel_size'] * 1000:g} mm cells (`gym.make(\"ShelfSort-v0\", "
           f"pixel_size={config['pixel_size']}, primitives={tuple(config['primitives'])})`); act greedily within "
           "the env's masks: `model.predict(obs, deterministic=True, action_masks=env.unwrapped.action_masks())`.", "",
           "## Training", "",
           f"- Command: `{command}` (resumable; `{run.as_posix()}` holds its progress, episodes and TensorBoard logs).",
           "- Preset: the learning recipe (docs/experiments/learning-recipe.md), curriculum "
           f"N = {config['start_objects']} -> "
           f"{config['max_objects']}, seed from `progress.json`.",
           f"- {progress['timesteps']} env steps, {progress['wall_seconds'] / 3600:.2f} h of wall clock "
           f"({progress.get('demo_seconds', 0) / 60:.1f} min of it collecting demonstrations), "
           f"{len(sessions)} session(s).",
           "- Hardware: " + ("; ".join(machines) if machines else "not recorded"), "",
           "| N | reached at env step | wall-clock minutes | reached by |", "|---|---|---|---|"]
    capped = set(curriculum.get("capped", []))
    cap = config.get("max_stage_timesteps", 0)
    for i, (n, step, minutes) in enumerate(stages):
        how = "start" if i == 0 else (f"stage cap ({cap} steps)" if step in capped else "greedy gate"
                                      if config["gate"] == "greedy" else "training gate")
        out.append(f"| {n} | {step} | {'-' if minutes is None else f'{minutes:.0f}'} | {how} |")
    if curriculum.get("finished") is not None:
        out += ["", f"The curriculum ended at env step {curriculum['finished']}, when N = {curriculum['value']} "
                f"had trained its {cap} steps (the stage cap bounds the last stage too)."]
    for change in progress.get("amendments", []):
        out += ["", f"Configuration amended from env step {change['timesteps']} (`shelf-train --amend`): "
                + ", ".join(f"`{k} = {v}`" for k, v in change["changes"].items()) + "."]
    if greedy:
        step, n, rate = greedy[-1]
        out += ["", f"Last greedy check (20 fresh scenes): {100 * rate:.0f} % at N = {int(n)}, step {int(step)}."]
    if results is not None:
        label = zip_path.stem
        out += ["", "## Evaluation", "",
                f"Greedy, masked, on held-out scenes (`{results.as_posix()}/results.csv`; the same scenes for "
                "every policy): success rate mean ± std over seeds, and this model's AE and mAE.", "",
                evaluation_table(results, label)]
    return "\n".join(out) + "\n"


def model_cards(models: list[tuple[pathlib.Path, pathlib.Path, str]], results: pathlib.Path | None) -> str:
    """One model's card, or several under one title (``examples/pretrained/README.md``), headings one level down."""
    cards = [model_card(run, zip_path, results, command) for run, zip_path, command in models]
    if len(cards) == 1:
        return cards[0]
    names = ", ".join(f"`{zip_path.name}`" for _, zip_path, _ in models)
    head = (f"# Pretrained models: {names}\n\nEach was trained by the command in its card, on the machines listed, "
            "and copied here with `bash scripts/ship_models.sh` (which also writes this file).\n")
    return "\n".join([head, *("\n".join("#" + line if line.startswith("#") else line for line in card.splitlines())
                               + "\n" for card in cards)])


PROG = "python -m shelf_env.training.model_card"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog=PROG, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("run", type=pathlib.Path, nargs="+", help="each model's run folder (or its committed mirror)")
    p.add_argument("--zip", type=pathlib.Path, nargs="+", required=True, help="each run's shipped checkpoint")
    p.add_argument("--results", type=pathlib.Path, default=None, help="an evaluation's output folder")
    p.add_argument("--command", nargs="+", default=None, help="each run's training command")
    p.add_argument("--out", type=pathlib.Path, required=True, help="the model card to write (a README.md)")
    args = p.parse_args(argv)
    commands = args.command if args.command is not None else [""] * len(args.run)
    try:
        if not len(args.run) == len(args.zip) == len(commands):
            raise ValueError(f"need one --zip and one --command per run: {len(args.run)} runs, {len(args.zip)} "
                             f"zips, {len(commands) if args.command is not None else 'no'} commands")
        text = model_cards(list(zip(args.run, args.zip, commands)), args.results)
    except (OSError, KeyError, ValueError) as err:
        print(f"model_card: error: {err}", flush=True)
        return 2
    write_text_atomically(args.out, text)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
