"""Model cards for shipped checkpoints, written from what the run and the evaluation left on disk.

    python -m shelf_env.training.model_card results/training/p_s --zip examples/pretrained/v1/p_s.zip \\
        --results results/models --command "bash scripts/train_model.sh p_s" --out examples/pretrained/p_s.md
    python -m shelf_env.training.model_card results/training/p_s results/training/s \\
        --zip examples/pretrained/v1/p_s.zip examples/pretrained/s.zip --command "..." "..." \\
        --results results/models --out examples/pretrained/README.md     # both cards in one file

Reads the run's ``progress.json`` (configuration, steps, wall time, the sessions with their
machines, the curriculum's stages and greedy checks) and ``episodes.csv`` (when each stage was
reached in wall-clock time), and the evaluation's ``results.csv``. It writes markdown: how to load
the model, the command, the training (steps, wall time, hardware, stages reached and when) and the
evaluation table of the model beside every other policy evaluated on the same scenes.

A distilled model (``python -m shelf_env.training.distill``) has no run: `distilled_card` writes its card
from the distillation's report (``<model>.distill.json``: the model it started from, the dataset's shards
and states, the recipe, the epochs, the validation losses).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import pathlib
from collections import Counter
from typing import Any

from shelf_env.fall_filter import GEOMETRY_FILTER, GeometryRisk, geometry_risk_path
from shelf_env.files import write_text_atomically
from shelf_env.pick_guard import PICK_GUARD
from shelf_env.policies import LOOP_BREAKER, checkpoint_pixel_size, checkpoint_primitives, policy_wrappers


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


def layout_name(primitives: tuple[str, ...]) -> str:
    """The paper's name of a layout: P+S with pushes, S with picks only."""
    return "P+S (pick-and-place, push-left, push-right)" if "push" in primitives else "S (pick-and-place)"


def usage(zip_path: pathlib.Path, title: str | None, how: str, pixel_size: float,
          primitives: tuple[str, ...]) -> list[str]:
    """A card's first lines: its title (``title``, default the file's name), how to load and play the model."""
    size_mb = zip_path.stat().st_size / 2**20 if zip_path.exists() else float("nan")
    return [f"# `{title or zip_path.name}`: PixelDoubleDQN, {how}", "",
            "```python",
            "from sb3_pixeldqn import PixelDoubleDQN",
            f'model = PixelDoubleDQN.load("{zip_path.as_posix()}")   # {size_mb:.1f} MB, no other file needed',
            "```", "",
            f"Observation {pixel_size * 1000:g} mm cells (`gym.make(\"ShelfSort-v0\", pixel_size={pixel_size}, "
            f"primitives={primitives})`); act greedily within the env's masks: "
            "`model.predict(obs, deterministic=True, action_masks=env.unwrapped.action_masks())`.", ""]


def evaluation_section(results: pathlib.Path, label: str, heading: str = "## Evaluation",
                       what: tuple[str, str] = ("this model", "this model's")) -> list[str]:
    """The card's evaluation: ``label``'s rows of ``results`` beside every other policy on the same scenes, under
    ``heading``, naming what is evaluated as ``what`` (subject, possessive)."""
    return ["", heading, "",
            f"Greedy, masked, on held-out scenes (`{results.as_posix()}/results.csv`; the same scenes for "
            f"every policy; {what[0]} is `{label}` there): success rate mean ± std over seeds, and {what[1]} "
            "AE and mAE.", "",
            evaluation_table(results, label)]


#: What each wrapper of a filtered policy does, as its card says it.
WRAPPER_TEXT = {
    PICK_GUARD: "`shelf_env.pick_guard.PickGuard` (it masks the picks of the objects that look sorted and of those "
                "the episode has already picked three times)",
    LOOP_BREAKER: "`sb3_pixeldqn.LoopBreaker` (it bans the cells the episode has acted at too often)",
}
WRAPPER_NAME = {GEOMETRY_FILTER: "the geometry pick filter", PICK_GUARD: "the pick guard",
                LOOP_BREAKER: "the loop breaker"}
WRAPPER_HOME = {PICK_GUARD: "`shelf_env.pick_guard`", LOOP_BREAKER: "`sb3_pixeldqn.LoopBreaker`"}


def spoken_list(items: list[str]) -> str:
    """``items`` as a sentence lists them: ``a``, ``a and b``, ``a, b and c``."""
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


def filter_wrappers(label: str) -> tuple[str, ...]:
    """The wrappers of a filtered policy's ``label`` in evaluations, innermost first: ``+geometry-filter``, then any of
    `WRAPPER_TEXT`'s; a `ValueError` naming the label otherwise."""
    _, wrappers = policy_wrappers(label)
    if not wrappers or wrappers[0] != GEOMETRY_FILTER or any(w not in WRAPPER_TEXT for w in wrappers[1:]):
        raise ValueError(f"{label!r} is not the label of a policy played under {GEOMETRY_FILTER} and then any of "
                         f"{', '.join(WRAPPER_TEXT)} (e.g. NAME{GEOMETRY_FILTER}{PICK_GUARD}{LOOP_BREAKER})")
    return wrappers


def filtered_name(zip_path: pathlib.Path | str, label: str) -> str:
    """The policy name a checkpoint is played as under the geometry pick filter beside it and the wrappers after it
    that ``label`` (that policy's label in evaluations) names: ``<zip>+geometry-filter+pick-guard+loop-breaker``."""
    return pathlib.PurePath(zip_path).as_posix() + "".join(filter_wrappers(label))


def filter_section(info: dict[str, Any], zip_path: pathlib.Path, results: pathlib.Path | None) -> list[str]:
    """The card's part on playing ``zip_path`` under the `shelf_env.fall_filter.GeometryRisk` beside it and the
    wrappers its label names, from what shipped it (``info``: the risk's ``source`` file, the ``command`` that made it
    and its ``label`` in evaluations), with that policy's evaluation rows from ``results``."""
    risk = geometry_risk_path(zip_path)
    threshold = GeometryRisk.load(risk).threshold
    wrappers = filter_wrappers(str(info["label"]))
    name = filtered_name(zip_path, str(info["label"]))
    after = "".join(f", then {WRAPPER_TEXT[w]}" for w in wrappers[1:])
    out = ["", f"## The policy to use: under {spoken_list([WRAPPER_NAME[w] for w in wrappers])}", "",
           "```python",
           "from shelf_env.policies import make_policy",
           f'policy = make_policy("{name}", env)   # env as above',
           "action, _ = policy.predict(obs, deterministic=True, action_masks=env.unwrapped.action_masks(),",
           "                           episode_start=np.array([first]))   # first: True on an episode's first step",
           "```", "",
           f"The Q-maps above with the pick cells whose predicted fall risk is at least {threshold:g} masked out "
           f"(`shelf_env.fall_filter.FallFilter`; the risk `{risk.as_posix()}` is a `GeometryRisk`: an MLP on named "
           f"carry geometry read from the camera observation alone){after}. The risk: `" + str(info["command"])
           + f"`, its line that writes `{info['source']}` (docs/experiments/fall-geometry.md). Evaluations and "
           f"`shelf-demo` name this policy `{name}`."]
    if results is not None:
        out += evaluation_section(results, str(info["label"]), "### Its evaluation", ("this policy", "its"))
    return out


def model_card(run: pathlib.Path, zip_path: pathlib.Path, results: pathlib.Path | None, command: str,
               title: str | None = None) -> str:
    """The markdown card of the model trained in ``run`` and shipped as ``zip_path`` (headed ``title``)."""
    progress: dict[str, Any] = json.loads((run / "progress.json").read_text())
    config = progress["config"]
    layout = layout_name(tuple(config["primitives"]))
    curriculum = progress.get("curriculum") or {}
    stages = stage_times(run, curriculum.get("history", []))
    greedy = curriculum.get("greedy_history", [])
    sessions = progress.get("sessions", [])
    machines = sorted({f"{s['machine']}, {s['torch_threads']} torch threads, {s['device']}"
                       + (f", {s['n_envs']} env processes" if s.get("n_envs", 1) > 1 else "") for s in sessions})
    out = [*usage(zip_path, title, layout, config["pixel_size"], tuple(config["primitives"])),
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
        out += evaluation_section(results, zip_path.stem)
    return "\n".join(out) + "\n"


def recipe_terms(report: dict[str, Any]) -> list[str]:
    """The distillation's loss terms and options as its report records them, in words."""
    side = 2 * int(report.get("teacher_radius") or 0) + 1
    square = f" on its {side} x {side}-cell square" if side > 1 else ""
    temperature = report.get("teacher_temperature")
    choice = ("the teacher's choice and every labelled action as good by the labels" if report.get("teacher_set")
              else "the teacher's choice")
    terms = ["a value and a ranking term on every labelled action's outcome",
             (f"a cross-entropy on {choice} (temperature {temperature:g}){square}" if temperature
              else f"a margin {report.get('margin', 1.0):g} on {choice}{square}")]
    if report.get("progress"):
        terms.append("the progress term")
    if report.get("anchor"):
        terms.append(f"the anchor to the starting model (weight {report['anchor']:g})")
    terms.append("augmentation " + ("on" if report.get("augment") else "off"))
    return terms


def distilled_card(report_path: pathlib.Path, zip_path: pathlib.Path, results: pathlib.Path | None, command: str,
                   title: str | None = None, moved: dict[str, str] | None = None,
                   played: tuple[dict[str, Any], pathlib.Path | None] | None = None) -> str:
    """The card of a model distilled from the teacher dataset, from its distillation report.

    Its evaluation rows are those of the label it was evaluated under: the file stem the distillation wrote
    (the report's ``out``), the same bytes as ``zip_path``. ``moved`` maps a starting model's path as the
    report names it to where that file is now.
    """
    report: dict[str, Any] = json.loads(report_path.read_text())
    primitives = checkpoint_primitives(zip_path)
    series = Counter(shard.split("_")[0] for shard in report["shards"])  # shards per series (s00, s01, ...)
    val = (report.get("averaged") or {}).get("val") or report["history"][-1]["val"]
    first = report["history"][0]["val"]
    averaged = (f"the mean of the last {report['average_last']} epochs' weights"
                if report.get("average_last") else "the last epoch's weights")
    init = f"`{report['init']}`"
    now = (moved or {}).get(report["init"])
    if now:
        init += f" as it was then (now `{now}`)"
    name = pathlib.Path(report["out"]).name
    out = [*usage(zip_path, title, f"{layout_name(primitives)}, distilled", checkpoint_pixel_size(zip_path),
                  primitives),
           "## Distillation", "",
           f"- Command: `{command}`, its line that writes `{name}` (`python -m shelf_env.training.distill`; "
           f"its report: `{report_path.as_posix()}`).",
           f"- Started from {init} and trained its Q-maps on "
           f"the teacher dataset `{report['data']}` (docs/experiments/teacher-dataset.md): "
           f"{len(report['shards'])} shards (" + ", ".join(f"{k}: {v}" for k, v in sorted(series.items()))
           + f"), {report['train_states']:,} training states with {report['train_labels']:,} labelled actions, "
           f"{report['val_states']:,} validation states.",
           f"- Recipe (docs/experiments/distill-scaling.md): {report['epochs']} epochs, seed {report['seed']}; "
           + "; ".join(recipe_terms(report)) + f"; shipped weights: {averaged}.",
           f"- Validation loss {first['loss']:.2f} -> {val['loss']:.2f}; {report['seconds'] / 60:.1f} min on one "
           "CPU thread."]
    if results is not None:
        out += evaluation_section(results, pathlib.Path(report["out"]).stem)
    if played is not None:
        out += filter_section(played[0], zip_path, played[1])
    return "\n".join(out) + "\n"


def model_cards(cards: list[tuple[str, str]], head: str = "") -> str:
    """One card, or several ``(name, card)`` under one title (``examples/pretrained/README.md``), their
    headings one level down, after ``head``."""
    if len(cards) == 1:
        return cards[0][1]
    names = ", ".join(f"`{name}`" for name, _ in cards)
    head = head or ("Each was trained by the command in its card, on the machines listed, and copied here with "
                    "`bash scripts/ship_models.sh` (which also writes this file).")
    return "\n".join([f"# Pretrained models: {names}\n\n{head}\n",
                      *("\n".join("#" + line if line.startswith("#") else line for line in card.splitlines())
                        + "\n" for _, card in cards)])


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
        text = model_cards([(z.name, model_card(run, z, args.results, command))
                            for run, z, command in zip(args.run, args.zip, commands)])
    except (OSError, KeyError, ValueError) as err:
        print(f"model_card: error: {err}", flush=True)
        return 2
    write_text_atomically(args.out, text)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
