"""The ablation of docs/experiments/learning-recipe.md: the recipe, and every lever switched off one at a time.

    python research/ablation.py --minutes 30                     # every row not on disk yet (seed 0)
    python research/ablation.py --rows recipe no-masks --minutes 30
    python research/ablation.py --report                         # table + curves from the rows on disk

Each row trains `examples/train.py` with the recipe preset and the row's overrides for the same
wall-clock budget (one run after another, never two at once), from N = ``--start-objects`` (3;
the two gate rows start at 1) up to N = 3 with the row's curriculum gate, then evaluates the
greedy masked policy on held-out scenes: N = 3, ``--scenes`` scenes of training objects and of
YCB objects, from evaluation seed ``HELDOUT_SEED`` (`shelf_env.evaluation.protocol.scene_seed`), which no
training run or greedy check draws from. H-d plays the same scenes for the actions-per-success ratio.

Training runs live in ``runs/ablation/<row>_s<seed>/`` and resume if interrupted; a finished row
is ``results/learning/rows/<row>_s<seed>.json`` (configuration, env and gradient steps, wall time,
the greedy-check learning curve, the held-out metrics) and is skipped when run again.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import time
from typing import Any

import numpy as np

from shelf_env.cli import train
from shelf_env.evaluation import protocol as ev
from shelf_env.files import write_atomically, write_json_atomically, write_text_atomically
from shelf_env.training.config import PRESETS

HELDOUT_SEED = ev.HELDOUT_SEED
#: Row name -> (overrides of the recipe, description of what is switched off).
ROWS: dict[str, tuple[dict[str, Any], str]] = {
    "recipe": ({}, "the recipe"),
    "no-masks": ({"masked": False}, "argmax over all pixels (greedy and target); exploration still masked"),
    "no-demos": ({"demo_policy": None}, "no demonstrations, no margin loss"),
    "no-augment": ({"augment": ()}, "no mirror / class-permutation augmentation"),
    "noop-keep": ({"noop": "keep"}, "unchanged-observation steps stored as they are"),
    "noop-terminal": ({"noop": "terminal"}, "unchanged-observation steps: penalty and no bootstrap"),
    "polyak": ({"tau": 1e-3, "target_update_interval": 1}, "paper's Polyak beta = 1e-3 every step"),
    "lr-1e-4": ({"learning_rate": 1e-4}, "paper's learning rate 1e-4"),
    "batch-16": ({"batch_size": 16}, "batch 16"),
    "grad-2": ({"gradient_steps": 2}, "2 gradient steps per env step"),
    "px-5mm": ({"pixel_size": 0.005}, "5 mm cells (80 x 120)"),
    "px-7.5mm": ({"pixel_size": 0.0075}, "7.5 mm cells (53 x 80)"),
    # the gate only matters with stages to pass: these two start at N = 1 (the others at N = 3)
    "gate-greedy-from-1": ({"start_objects": 1}, "recipe from N = 1 with the greedy gate (compare the next row)"),
    "gate-training-from-1": ({"start_objects": 1, "gate": "training"},
                             "from N = 1 with the paper's rule (epsilon-greedy 50-episode window)"),
    "relabel-all": ({"relabel": "all"}, "paper's relabelling (no-op steps too)"),
    "relabel-off": ({"relabel": "off"}, "no hindsight relabelling"),
    # lever 9 switched on: the recipe's loop with the env stepped in an actor process
    "actor": ({"actor": True}, "acting in an actor process (1 core acts, 1 learns)"),
}


def row_key(row: str, seed: int) -> str:
    return f"{row}_s{seed}"


def run_row(row: str, seed: int, minutes: float, start_objects: int, scenes: int, runs_dir: pathlib.Path,
            out: pathlib.Path, threads: int) -> dict[str, Any]:
    """Train (or resume) one row to its budget, evaluate it on held-out scenes, write its JSON."""
    overrides, description = ROWS[row]
    run = runs_dir / row_key(row, seed)
    args = ["--out", str(run), "--preset", "recipe", "--hours", str(minutes / 60), "--seed", str(seed),
            "--threads", str(threads), "--start-objects", str(start_objects), "--max-objects", "3",
            "--checkpoint-minutes", "5"]
    for key, value in overrides.items():
        args += ["--set", f"{key}={json.dumps(list(value) if isinstance(value, tuple) else value)}"]
    if train.main(args) != 0:
        raise SystemExit(f"ablation row {row}: shelf-train refused its arguments {args}")
    progress = json.loads((run / "progress.json").read_text())
    from sb3_pixeldqn import PixelDoubleDQN

    model = PixelDoubleDQN.load(run / "model.zip", device="cpu")
    metrics: dict[str, Any] = {}
    for object_set in ("train", "ycb"):
        t0 = time.monotonic()
        records = ev.evaluate_cell(str(run / "model.zip"), 3, HELDOUT_SEED, scenes, object_set)
        metrics[object_set] = ev.episode_summary(records)
        metrics[object_set]["eval_seconds"] = round(time.monotonic() - t0, 1)
    result = {
        "buffer": buffer_stats(run),
        "row": row, "seed": seed, "description": description, "overrides": {k: v for k, v in overrides.items()},
        "config": progress["config"], "minutes": minutes, "wall_seconds": progress["wall_seconds"],
        "env_steps": int(model.num_timesteps), "demo_steps": int(getattr(model, "demo_timesteps", 0)),
        "gradient_steps": int(model._n_updates), "curriculum": progress["curriculum"], "heldout": metrics,
    }
    # the row's checkpoint stays in runs/; only its numbers are committed
    write_json_atomically(out / "rows" / f"{row_key(row, seed)}.json", result)
    return result


def buffer_stats(run: pathlib.Path) -> dict[str, int]:
    """What the run's replay buffer holds: transitions, relabelled twins, no-op steps, demonstrations."""
    from stable_baselines3.common.save_util import load_from_pkl

    buf = load_from_pkl(run / "replay.pkl")
    demos = buf.demonstrations
    return {"stored": int(buf.n_stored), "relabelled": int(buf.n_relabelled), "noop": int(buf.n_noop),
            "demonstrations": int(demos.n_stored) if demos is not None else 0}


def heuristic_metrics(out: pathlib.Path, scenes: int) -> dict[str, dict[str, float]]:
    """H-d on the held-out scenes, from the cells ``research/check_recipe.py`` shares (``<out>/cells/``)."""
    return {s: ev.episode_summary(ev.cached_cell(out, "h-d", 3, HELDOUT_SEED, scenes, s)) for s in ("train", "ycb")}


def report(out: pathlib.Path, scenes: int) -> str:
    """The markdown table of every row on disk, and ``learning_curves.png`` from their greedy checks."""
    rows = [json.loads(p.read_text()) for p in sorted((out / "rows").glob("*_s*.json"))]
    order = {name: i for i, name in enumerate(ROWS)}
    rows.sort(key=lambda r: (order.get(r["row"], 99), r["seed"]))
    hd = heuristic_metrics(out, scenes) if rows else {}
    lines = ["| row | seed | switched off | SR train % | SR YCB % | actions/success train (H-d) | "
             "unchanged-obs actions train / YCB | env steps (+demo) | gradient steps | N reached |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        tr, ycb = r["heldout"]["train"], r["heldout"]["ycb"]
        lines.append(
            f"| {r['row']} | {r['seed']} | {r['description']} | {tr['sr']:.0f} | {ycb['sr']:.0f} | "
            f"{tr['actions_per_success']:.2f} ({hd['train']['actions_per_success']:.2f}) | "
            f"{100 * tr['noop_share']:.1f} % / {100 * ycb['noop_share']:.1f} % | "
            f"{r['env_steps']} (+{r['demo_steps']}) | {r['gradient_steps']} | {r['curriculum']['value']} |"
        )
    if rows:
        lines.append(f"| H-d | - | heuristic | {hd['train']['sr']:.0f} | {hd['ycb']['sr']:.0f} | "
                     f"{hd['train']['actions_per_success']:.2f} | {100 * hd['train']['noop_share']:.1f} % / "
                     f"{100 * hd['ycb']['noop_share']:.1f} % | - | - | - |")
        plot_curves(rows, out / "learning_curves.png")
    table = "\n".join(lines)
    write_text_atomically(out / "ablation.md", table + "\n")
    update_doc(DOC, table)
    return table


DOC = pathlib.Path(__file__).resolve().parents[1] / "docs" / "experiments" / "learning-recipe.md"
BEGIN, END = "<!-- ablation table: python research/ablation.py --report -->", "<!-- end ablation table -->"


def update_doc(doc: pathlib.Path, table: str) -> None:
    """Replace the table between the markers of ``doc`` (docs/experiments/learning-recipe.md), if it has them."""
    if not doc.exists():
        return
    text = doc.read_text()
    if BEGIN not in text or END not in text:
        return
    head, rest = text.split(BEGIN, 1)
    write_text_atomically(doc, head + BEGIN + "\n" + table + "\n" + END + rest.split(END, 1)[1])


def plot_curves(rows: list[dict[str, Any]], png: pathlib.Path) -> None:
    """Greedy success of every row's periodic checks against wall-clock minutes (stage N marked)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 4.5))
    for i, r in enumerate(rows):
        history = r["curriculum"].get("greedy_history", [])
        if not history:
            continue
        steps = np.array([h[0] for h in history], dtype=float)
        rate = np.array([h[2] for h in history]) * 100
        n = np.array([h[1] for h in history])
        minutes = steps / max(1, r["env_steps"]) * r["wall_seconds"] / 60  # steps -> minutes, linearly
        # 20 colours, and dashes from the 11th row on, so that no two rows look alike
        (line,) = ax.plot(minutes, rate, marker=".", ms=3, label=f"{r['row']} s{r['seed']}",
                          color=plt.get_cmap("tab20")(i % 20), linestyle=("-", "--", ":")[(i // 10) % 3])
        at3 = n == 3
        ax.plot(minutes[at3], rate[at3], "o", ms=4, color=line.get_color())
    ax.set_xlabel("wall-clock minutes (approx., from steps)")
    ax.set_ylabel("greedy success on 20 fresh scenes (%)\n(big dots: at N = 3)")
    ax.set_ylim(-2, 102)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    write_atomically(png, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rows", nargs="+", default=list(ROWS), choices=list(ROWS))
    p.add_argument("--seeds", type=int, nargs="+", default=[0])
    p.add_argument("--minutes", type=float, default=30.0, help="wall-clock training budget per row")
    p.add_argument("--start-objects", type=int, default=3)
    p.add_argument("--scenes", type=int, default=50, help="held-out scenes per object set")
    p.add_argument("--runs-dir", type=pathlib.Path, default=pathlib.Path("runs/ablation"))
    p.add_argument("--out", type=pathlib.Path, default=pathlib.Path("results/learning"))
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--report", action="store_true", help="only write the table and the curves")
    args = p.parse_args(argv)
    assert set(PRESETS) >= {"recipe"}
    if not args.report:
        for row in args.rows:
            for seed in args.seeds:
                if (args.out / "rows" / f"{row_key(row, seed)}.json").exists():
                    print(f"{row_key(row, seed)}: on disk, skipped", flush=True)
                    continue
                result = run_row(row, seed, args.minutes, args.start_objects, args.scenes, args.runs_dir, args.out,
                                 args.threads)
                print(f"{row_key(row, seed)}: SR train {result['heldout']['train']['sr']:.0f} %, "
                      f"YCB {result['heldout']['ycb']['sr']:.0f} %", flush=True)
    print(report(args.out, args.scenes))


if __name__ == "__main__":
    main()
