"""Compare evaluations made under different conditions (perception noise levels, closed loop off/on).

    # SR against the noise level, one panel per N (the robustness curves)
    python research/plot_conditions.py --metric sr --x condition --ns 5 8 \\
        --runs results/robustness/level_0:0 results/robustness/level_0.1:0.1 --out results/robustness/sr_vs_noise.png
    # fall rate against N, one line per (policy, condition)
    python research/plot_conditions.py --metric fell_rate --x n \\
        --runs results/closed_loop/off:off results/closed_loop/on:on --out results/closed_loop/falls.png

Each ``--runs`` item is ``FOLDER:LABEL`` for a ``shelf-evaluate --out FOLDER`` evaluation; with
``--x condition`` the labels must be numbers (the x axis). Prints the table it plots.
"""

from __future__ import annotations

import argparse
import csv
import pathlib

from shelf_env.files import write_atomically

METRICS = {"sr": ("sr_mean", "SR (%)"), "fell_rate": ("fell_rate", "episodes with a fall"),
           "ae": ("ae_mean", "AE"), "loop_rate": ("loop_rate", "episodes that loop")}


def read_runs(items: list[str]) -> list[tuple[str, list[dict[str, str]]]]:
    out = []
    for item in items:
        folder, sep, label = item.rpartition(":")
        if not sep or not folder:
            raise SystemExit(f"--runs items are FOLDER:LABEL, got {item!r}")
        path = pathlib.Path(folder) / "results.csv"
        if not path.is_file():
            raise SystemExit(f"no results.csv in {folder} (run shelf-evaluate --out {folder} first)")
        with open(path, newline="") as f:
            out.append((label, list(csv.DictReader(f))))
    return out


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--runs", nargs="+", required=True, metavar="FOLDER:LABEL")
    p.add_argument("--metric", choices=sorted(METRICS), default="sr")
    p.add_argument("--x", choices=["n", "condition"], default="n")
    p.add_argument("--ns", type=int, nargs="*", default=None, help="panels (--x condition) or N to keep (--x n)")
    p.add_argument("--object-set", default="ycb")
    p.add_argument("--out", type=pathlib.Path, required=True)
    args = p.parse_args(argv)
    key, name = METRICS[args.metric]
    runs = read_runs(args.runs)
    rows = [(label, r) for label, rs in runs for r in rs if r["object_set"] == args.object_set and key in r]
    if not rows:
        raise SystemExit(f"no {args.object_set} rows with {key} in these results")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    policies = sorted({r["policy"] for _, r in rows})
    if args.x == "condition":
        ns = args.ns or sorted({int(r["num_objects"]) for _, r in rows})
        fig, axes = plt.subplots(1, len(ns), figsize=(4.5 * len(ns), 3.6), squeeze=False)
        for ax, n in zip(axes[0], ns):
            for policy in policies:
                pts = sorted((float(label), float(r[key])) for label, r in rows
                             if r["policy"] == policy and int(r["num_objects"]) == n)
                if pts:
                    ax.plot(*zip(*pts), marker="o", label=policy)
                    print(f"N={n} {policy:>10s}: " + ", ".join(f"{x:g} -> {y:.3g}" for x, y in pts))
            ax.set_title(f"N = {n}")
            ax.set_xlabel("condition")
            ax.set_ylabel(name)
        axes[0][0].legend(fontsize=8)
    else:
        fig, ax = plt.subplots(figsize=(6.5, 3.8))
        for label, _ in runs:
            for policy in policies:
                keep = [r for lab, r in rows if lab == label and r["policy"] == policy]
                pts = sorted((int(r["num_objects"]), float(r[key])) for r in keep
                             if not args.ns or int(r["num_objects"]) in args.ns)
                if pts:
                    ax.plot(*zip(*pts), marker="o", label=f"{policy} ({label})")
                    print(f"{policy:>10s} ({label}): " + ", ".join(f"N={x}: {y:.3g}" for x, y in pts))
        ax.set_xlabel("number of objects N")
        ax.set_ylabel(name)
        ax.legend(fontsize=8)
    fig.tight_layout()
    write_atomically(args.out, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    plt.close(fig)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
