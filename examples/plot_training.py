"""Plot a training run's success curve and curriculum stage from its ``episodes.csv``.

    python examples/plot_training.py runs/curriculum --png docs/training_curve.png

Top: success rate over the last 50 training episodes (ε-greedy, as the curriculum sees it)
against env steps, with the number of objects N on the right axis. Bottom: N against wall-clock
minutes. Also prints one line per curriculum stage (first step, minute, episodes, success).

A run on a mix of sizes (its config's ``min_num_objects``: each episode draws its own N) has no
stage line to draw: the top shows each episode's N as a dot and the rolling success of its lower
and upper sizes apart, the bottom the success rate per N in the first and the second half of its
episodes (what it learned, or forgot, over the run). The printed lines are then one per N.
"""

from __future__ import annotations

import argparse
import csv
import json
import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from shelf_env.files import write_atomically  # noqa: E402


def read_episodes(path: pathlib.Path) -> dict[str, np.ndarray]:
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise ValueError(f"{path} has no episodes yet")
    return {key: np.array([float(r[key]) for r in rows]) for key in rows[0]}


def run_config(run: pathlib.Path) -> dict:
    """The run's stored configuration (``progress.json``'s, {} when it has none)."""
    progress = run / "progress.json"
    return json.loads(progress.read_text()).get("config", {}) if progress.exists() else {}


def layout_name(config: dict) -> str:
    """"P+S" or "S" from a run's stored configuration (P+S when it has none)."""
    return "P+S" if "push" in config.get("primitives", ["pick", "push"]) else "S"


def rolling_mean(x: np.ndarray, window: int) -> np.ndarray:
    c = np.cumsum(np.insert(x, 0, 0.0))
    n = np.minimum(np.arange(1, len(x) + 1), window)
    return (c[1:] - c[np.arange(1, len(x) + 1) - n]) / n


def stage_summary(ep: dict[str, np.ndarray]) -> list[str]:
    lines = []
    for n in np.unique(ep["num_objects"]).astype(int):
        sel = ep["num_objects"] == n
        lines.append(
            f"N={n}: from step {int(ep['timestep'][sel][0])} ({ep['wall_seconds'][sel][0] / 60:.1f} min), "
            f"{int(sel.sum())} episodes, success {100 * ep['success'][sel].mean():.0f} %, "
            f"mean actions {ep['actions'][sel].mean():.1f}"
        )
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run", type=pathlib.Path, help="the --out folder of examples/train.py")
    parser.add_argument("--png", type=pathlib.Path, default=None, help="default: <run>/training_curve.png")
    parser.add_argument("--window", type=int, default=50)
    args = parser.parse_args()
    ep = read_episodes(args.run / "episodes.csv")
    png = args.png or args.run / "training_curve.png"

    config = run_config(args.run)
    if config.get("min_num_objects") is not None:
        plot_mixed(ep, args.window, png, layout_name(config))
        return
    fig, (ax1, ax3) = plt.subplots(2, 1, figsize=(8, 6), height_ratios=[2, 1])
    ax1.plot(ep["timestep"], 100 * rolling_mean(ep["success"], args.window), color="tab:green",
             label=f"success, last {args.window} episodes")
    ax1.axhline(90, color="grey", lw=0.8, ls="--", label="curriculum threshold (90 %)")
    ax1.set_xlabel("env steps")
    ax1.set_ylabel("success rate (%)")
    ax1.set_ylim(0, 102)
    ax2 = ax1.twinx()
    ax2.step(ep["timestep"], ep["num_objects"], where="post", color="tab:blue", label="N")
    ax2.set_ylabel("objects N", color="tab:blue")
    ax2.set_ylim(0, max(ep["num_objects"]) + 1)
    ax1.legend(loc="lower left", fontsize=8)
    ax3.step(ep["wall_seconds"] / 60, ep["num_objects"], where="post", color="tab:blue")
    ax3.set_xlabel("wall-clock minutes")
    ax3.set_ylabel("objects N")
    ax3.set_ylim(0, max(ep["num_objects"]) + 1)
    fig.suptitle(f"PixelDoubleDQN ({layout_name(config)}) curriculum on ShelfSort-v0")
    save(fig, png, ep)


def save(fig: plt.Figure, png: pathlib.Path, ep: dict[str, np.ndarray]) -> None:
    """Write ``fig`` to ``png`` atomically and print the lines per N of ``ep``."""
    fig.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    write_atomically(png, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    print("\n".join(stage_summary(ep)))
    print(f"wrote {png}")


def plot_mixed(ep: dict[str, np.ndarray], window: int, png: pathlib.Path, layout: str) -> None:
    """The curve of a run on a mix of sizes (see the module docstring)."""
    n = ep["num_objects"].astype(int)
    split = (n.min() + n.max()) // 2
    fig, (ax1, ax3) = plt.subplots(2, 1, figsize=(8, 6), height_ratios=[2, 1])
    for sel, colour, label in ((n <= split, "tab:green", f"N <= {split}"), (n > split, "tab:red", f"N > {split}")):
        if sel.any():
            ax1.plot(ep["timestep"][sel], 100 * rolling_mean(ep["success"][sel], window), color=colour,
                     label=f"success at {label}, last {window} such episodes")
    ax1.set_xlabel("env steps")
    ax1.set_ylabel("success rate (%)")
    ax1.set_ylim(0, 102)
    ax2 = ax1.twinx()
    ax2.plot(ep["timestep"], n, ".", ms=2, color="tab:blue", alpha=0.5)
    ax2.set_ylabel("objects N of each episode", color="tab:blue")
    ax2.set_ylim(0, n.max() + 1)
    ax1.legend(loc="lower left", fontsize=8)
    sizes = np.unique(n)
    half = len(n) // 2
    for offset, part, label in ((-0.2, slice(0, half), "first half"), (0.2, slice(half, None), "second half")):
        rates = [100 * ep["success"][part][n[part] == k].mean() if (n[part] == k).any() else np.nan for k in sizes]
        ax3.bar(sizes + offset, rates, width=0.4, label=f"{label} of the episodes")
    ax3.set_xlabel("objects N")
    ax3.set_ylabel("success (%)")
    ax3.set_ylim(0, 102)
    ax3.set_xticks(sizes)
    ax3.legend(fontsize=8)
    fig.suptitle(f"PixelDoubleDQN ({layout}) on a mix of sizes, ShelfSort-v0")
    save(fig, png, ep)


if __name__ == "__main__":
    main()
