"""The scaling curve of distillation: greedy fall rate per action and SR against the states distilled.

Reads a results folder holding the distillation reports (``*.distill.json``, `shelf_env.training.distill`)
and the fall measurements (``falls.json``, `shelf_env.evaluation.falls`) of the distilled models, the
starting model and reference policies, and writes a Markdown table and a PNG (two panels: invalid
and fallen actions per greedy action at each N; SR at each N; reference policies as dashed lines).

The fall measurement plays 10 scenes per N, too few for SR: with ``--evaluation FOLDER`` (a ``shelf-evaluate``
folder of the same models, e.g. the §V scenes of three seeds) it adds a second table and a third panel, each
model's SR per N over every scene of that folder it played and its margin over the best of ``--heuristics``
on exactly those scenes (`margins`), averaged over the N; a distilled model that folder played but the fall
measurement did not (a replicate distilled again at another seed) is a row of that table only. The trend line
under it gives the slope's standard error and how far apart models distilled from the same states land.

    python research/scaling_curve.py results/distill_scaling --out results/distill_scaling/report.md \\
        --png results/distill_scaling/scaling.png
    python research/scaling_curve.py results/distill_test --reports results/distill_scaling ...   # held-out scenes
    python research/scaling_curve.py results/distill_test --reports results/distill_scaling \\
        --evaluation results/distill_test --heuristics h-d h-a ...                            # + SR on its cells
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib
from typing import Any

from shelf_env.evaluation.falls import FallEpisode, cell_summary
from shelf_env.evaluation.protocol import EpisodeRecord, by_scene, common_scenes, load_cells, margin_over_best
from shelf_env.files import write_text_atomically


def load(folder: pathlib.Path, reports_folder: pathlib.Path | None = None,
         falls_file: str = "falls.json") -> tuple[dict[str, dict[str, Any]], list[dict[str, Any]]]:
    """The distillation reports by model stem (in ``reports_folder``, default ``folder``), and the fall cells
    of ``folder`` (its ``falls_file``)."""
    reports = {p.name.removesuffix(".distill.json"): json.loads(p.read_text())
               for p in sorted((reports_folder or folder).glob("*.distill.json"))}
    cells = list(json.loads((folder / falls_file).read_text()).values())
    for cell in cells:  # the summary of this version (cells measured before it lack the newer numbers)
        cell.update(cell_summary([FallEpisode(**e) for e in cell.get("per_episode", [])]) if "per_episode" in cell
                    else {})
    if not cells:
        raise ValueError(f"{folder}/{falls_file} holds no cells")
    return reports, cells


#: The epochs of the results' distillations; a report with other epochs says so in its recipe.
EPOCHS = 8


def recipe(report: dict[str, Any]) -> str:
    """A distillation's recipe in words, from its report (older reports lack the later options): the options
    that differ from the defaults, epochs other than `EPOCHS`, and whether shards of the DAgger series (every
    series after s00, each driven by a later learner) were distilled: which of those series is data, not recipe, so
    models distilled from a dataset that grew into a new series stay on one curve."""
    parts = ["augmented" if report.get("augment") else "as stored",
             "teacher over allowed actions" if report.get("masks") else "teacher over labels"]
    if report.get("progress"):
        parts.append("progress")
    if report.get("anchor"):
        parts.append(f"anchor {report['anchor']:g}")
    if report.get("teacher_radius"):
        parts.append(f"teacher radius {report['teacher_radius']}")
    if report.get("teacher_weight", 1.0) != 1.0:
        parts.append(f"teacher weight {report['teacher_weight']:g}")
    if report.get("progress_radius"):
        parts.append(f"progress radius {report['progress_radius']}")
    if report.get("progress_weight", 1.0) != 1.0:
        parts.append(f"progress weight {report['progress_weight']:g}")
    if report.get("teacher_temperature"):
        parts.append(f"teacher cross-entropy at {report['teacher_temperature']:g}")
    if report.get("epochs", EPOCHS) != EPOCHS:
        parts.append(f"{report['epochs']} epochs")
    if report.get("average_last", 1) > 1:
        parts.append(f"weights averaged over the last {report['average_last']} epochs")
    if {name[:3] for name in report.get("shards", [])} - {"s00"}:
        parts.append("+ DAgger series")
    return ", ".join(parts)


def final_val_loss(report: dict[str, Any]) -> float:
    """The validation loss of the model a distillation saved: its weights' average where it averaged, else the
    last epoch's."""
    return (report.get("averaged") or {}).get("val", report["history"][-1]["val"])["loss"]


def from_report(report: dict[str, Any]) -> dict[str, Any]:
    """A distilled model's row fields read from its distillation report: training states, validation loss, recipe."""
    return {"states": report["train_states"], "val_loss": final_val_loss(report), "recipe": recipe(report)}


def order(row: dict[str, Any]) -> tuple[bool, str, int, bool]:
    """The rows' order: per recipe by training states, a wrapped model after its plain one, references last."""
    return row["states"] is None, row["recipe"] or "", row["states"] or 0, row["wrapped"]


def rows(reports: dict[str, dict[str, Any]], cells: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per policy: its training states (0 for the starting model, None for a reference), its
    distillation's recipe and last validation loss, and per N the fall cell's numbers. A distilled
    model under a test-time wrapper (``zip+loop-breaker``) is a row of its own, off the curves; a zip with
    no distillation report (e.g. a fine-tune of a distilled model) is in the table only."""
    starts = {r["init"] for r in reports.values()}
    out: dict[str, dict[str, Any]] = {}
    for cell in cells:
        policy = cell["policy"]
        name, _, wrapper = policy.partition("+")
        stem = pathlib.Path(name).stem if name.endswith(".zip") else name
        row = out.setdefault(policy, {"policy": stem + (f"+{wrapper}" if wrapper else ""), "states": None,
                                      "val_loss": None, "recipe": None, "wrapped": bool(wrapper),
                                      "zip": name.endswith(".zip"), "by_n": {}})
        if stem in reports:
            row.update(from_report(reports[stem]))
        elif name in starts:
            row["states"] = 0
            first = next(r for r in reports.values() if r["init"] == name)["history"][0]
            row["val_loss"] = first["val"]["loss"]
        row["by_n"][cell["num_objects"]] = cell
    return sorted(out.values(), key=order)


def add_evaluated(data: list[dict[str, Any]], reports: dict[str, dict[str, Any]],
                  records: list[EpisodeRecord]) -> list[dict[str, Any]]:
    """``data`` with a row (no fall cells) for every distilled model that ``records`` (an evaluation) played but the
    fall measurement did not, such as a replicate distilled again at another seed; in `rows`' order."""
    known = {r["policy"] for r in data}
    for label in sorted({r.policy for r in records} - known):
        if label in reports:
            data.append({"policy": label, **from_report(reports[label]), "wrapped": False, "zip": True, "by_n": {}})
    return sorted(data, key=order)


def table(data: list[dict[str, Any]]) -> str:
    data = [r for r in data if r["by_n"]]  # the rows with fall cells
    ns = sorted({n for r in data for n in r["by_n"]})
    head = ["policy", "states distilled", "recipe", "val loss"] + \
        [f"invalid / fell per action (episodes with one), N = {n}" for n in ns] + [f"SR N = {n}" for n in ns]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in data:
        cells = [r["policy"], "-" if r["states"] is None else str(r["states"]),
                 r["recipe"] or "-",
                 "-" if r["val_loss"] is None else f"{r['val_loss']:.2f}"]
        for n in ns:
            c = r["by_n"].get(n)
            cells.append("-" if c is None else f"{100 * c['invalid_rate']:.1f} % / {100 * c['fall_rate']:.1f} % "
                                               f"({c['invalid']}/{c['decisions']}; "
                                               f"{c.get('episodes_invalid', '?')}/{c['episodes']} ep.)")
        for n in ns:
            c = r["by_n"].get(n)
            cells.append("-" if c is None else f"{c['sr']:.0f} % ({c['episodes']})")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def margins(data: list[dict[str, Any]], records: list[EpisodeRecord], heuristics: list[str]) -> None:
    """Add to each row of ``data`` that has episodes in ``records`` (matched by its label, a checkpoint's stem)
    ``sr_by_n``: per N, its SR (%) over every scene (seed, run) it played there that every heuristic also played,
    the better heuristic's SR on exactly those scenes, their difference (``margin``, SR points) and the number
    of scenes; and ``mean_margin``, the margin averaged over the N where the row has one (None where it has
    none). Each model is compared with the heuristics on its own scenes, so rows with other scene counts are
    each fair, not comparable with one another to the point. ``ValueError`` naming a heuristic the records
    lack, or when no row has a scene in common with the heuristics."""
    index = by_scene(records)
    for name in heuristics:
        if not any(policy == name for policy, _ in index):
            raise ValueError(f"the evaluation cells hold no episode of the heuristic {name!r}")
    for row in data:
        row["sr_by_n"] = {}
        if row["policy"] in heuristics:
            continue
        for n in sorted(n for policy, n in index if policy == row["policy"]):
            scenes = common_scenes(index, [row["policy"], *heuristics], n)
            paired = margin_over_best(index, row["policy"], n, scenes, heuristics)  # None without a common scene
            if paired is not None:
                row["sr_by_n"][n] = {"sr": paired["sr"], "best_heuristic": paired["best"],
                                     "margin": paired["margin"], "scenes": len(scenes)}
        found = [c["margin"] for c in row["sr_by_n"].values()]
        row["mean_margin"] = sum(found) / len(found) if found else None
    if not any(row["sr_by_n"] for row in data):
        raise ValueError("the evaluation cells hold no episode of a policy on the curve on the heuristics' scenes")


def margin_table(data: list[dict[str, Any]], heuristics: list[str]) -> str:
    """The rows with `margins`: per N "SR (margin; scenes)" and the mean margin."""
    shown = [r for r in data if r.get("sr_by_n")]
    ns = sorted({n for r in shown for n in r["sr_by_n"]})
    best = " / ".join(heuristics)
    head = ["policy", "states distilled"] + [f"SR N = {n} (margin over best of {best}; scenes)" for n in ns] + \
        ["margin averaged over N (points)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in shown:
        cells = [r["policy"], "-" if r["states"] is None else str(r["states"])]
        for n in ns:
            c = r["sr_by_n"].get(n)
            cells.append("-" if c is None else f"{c['sr']:.1f} % ({c['margin']:+.1f}; {c['scenes']})")
        cells.append(f"{r['mean_margin']:+.1f}" + ("" if len(r["sr_by_n"]) == len(ns) else
                                                    f" (N = {', '.join(map(str, sorted(r['sr_by_n'])))})"))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def trend(data: list[dict[str, Any]], targets: tuple[float, ...] = (0.0, 15.0)) -> list[str]:
    """For every recipe with three or more distilled models whose margins cover the same N with as many scenes
    each (`margins`; a curve mixing 30- and 90-scene points is left out), the
    least-squares line of the averaged margin against log2 of the training states: points per doubling of the
    data and, where it rises, the states at which the line reaches each of ``targets`` (SR points over the best
    heuristic). An extrapolation of a few noisy points, printed as such, not a measurement."""
    lines = []
    for name in sorted({r["recipe"] for r in data if r["recipe"] is not None and not r["wrapped"]}):
        pts = [r for r in data if r["recipe"] == name and not r["wrapped"] and r.get("mean_margin") is not None]
        if len({frozenset((n, c.get("scenes")) for n, c in r["sr_by_n"].items()) for r in pts}) != 1 \
                or len({r["states"] for r in pts}) < 3:
            continue
        x = [math.log2(r["states"]) for r in pts]
        y = [r["mean_margin"] for r in pts]
        mx, my = sum(x) / len(x), sum(y) / len(y)
        sxx = sum((a - mx) ** 2 for a in x)
        slope = sum((a - mx) * (b - my) for a, b in zip(x, y)) / sxx
        residual = sum((b - my - slope * (a - mx)) ** 2 for a, b in zip(x, y))
        line = (f"- {name}: {len(pts)} models ({', '.join(str(r['states']) for r in pts)} states), margin averaged "
                f"over N = {', '.join(map(str, sorted(pts[0]['sr_by_n'])))}: {slope:+.1f} points per doubling of the "
                f"training states (least squares in log2 of the states; standard error "
                f"{math.sqrt(residual / (len(pts) - 2) / sxx):.1f})")
        if slope > 0:
            reach = [f"{t:+g} at ~{2 ** (mx + (t - my) / slope):,.0f} states" for t in targets]
            line += "; extrapolated, the line reaches " + ", ".join(reach)
        twins: dict[int, list[float]] = {}
        for r in pts:
            twins.setdefault(r["states"], []).append(r["mean_margin"])
        repeated = {k: v for k, v in twins.items() if len(v) > 1}
        if repeated:  # the same data distilled again (another seed): how far apart one point's models land
            line += "; models distilled from the same states: " + "; ".join(
                f"{k}: {', '.join(f'{m:+.1f}' for m in v)}" for k, v in sorted(repeated.items()))
        lines.append(line + ".")
    return lines


def plot(data: list[dict[str, Any]], png: pathlib.Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ns = sorted({n for r in data for n in r["by_n"]})
    start = [r for r in data if r["states"] == 0 and not r["wrapped"]]
    counts: dict[str, int] = {}
    for r in data:
        if r["recipe"] is not None and not r["wrapped"]:
            counts[r["recipe"]] = counts.get(r["recipe"], 0) + 1
    recipes = sorted(name for name, k in counts.items() if k >= 2)  # curves; single models: the table only
    extra = [r for r in data if r["wrapped"] and r["states"] is not None]
    refs = [r for r in data if r["states"] is None and not r["zip"]]  # named policies (the heuristics)
    evaluated = any(r.get("sr_by_n") for r in data)
    fig, axes = plt.subplots(1, 3 if evaluated else 2, figsize=(16.5 if evaluated else 11, 5))
    ax_f, ax_s = axes[0], axes[1]
    styles = ["o-", "s--", "^:", "d-."]
    for i, n in enumerate(ns):
        colour = f"C{i}"
        for j, name in enumerate(recipes):  # each recipe's curve starts at the starting model
            curve = start + [r for r in data if r["recipe"] == name and not r["wrapped"]]
            pts = [(r["states"], r["by_n"][n]) for r in curve if n in r["by_n"]]
            if len(pts) < 2:
                continue
            ax_f.plot([p[0] for p in pts], [100 * c["invalid_rate"] for _, c in pts], styles[j % 4], color=colour)
            ax_s.plot([p[0] for p in pts], [c["sr"] for _, c in pts], styles[j % 4], color=colour)
            if evaluated:  # the margin on the evaluation's scenes, where two or more of the curve have one
                held = [(r["states"], r["sr_by_n"][n]["margin"]) for r in curve if n in r.get("sr_by_n", {})]
                if len(held) >= 2:
                    axes[2].plot([h[0] for h in held], [h[1] for h in held], styles[j % 4], color=colour)
        ax_f.plot([], [], "-", color=colour, label=f"N = {n}")
        for r in extra:
            if n in r["by_n"]:
                ax_f.plot([r["states"]], [100 * r["by_n"][n]["invalid_rate"]], "*", ms=12, color=colour)
                ax_s.plot([r["states"]], [r["by_n"][n]["sr"]], "*", ms=12, color=colour)
        for ref in refs:
            if n in ref["by_n"]:
                ax_f.axhline(100 * ref["by_n"][n]["invalid_rate"], color=colour, ls="--", lw=1)
                ax_s.axhline(ref["by_n"][n]["sr"], color=colour, ls="--", lw=1)
    for j, name in enumerate(recipes):
        ax_s.plot([], [], styles[j % 4], color="black", label=name)
    ax_f.set(xlabel="training states distilled", ylabel="greedy actions ending the episode invalid (%)",
             title="invalid actions per greedy action")
    ax_s.set(xlabel="training states distilled", ylabel="SR (%)", title="greedy SR")
    if evaluated:
        axes[2].axhline(0.0, color="black", lw=1)
        axes[2].set(xlabel="training states distilled", ylabel="SR minus the best heuristic's (points)",
                    title="margin over the best heuristic, evaluation scenes")
    names = ", ".join(r["policy"] for r in refs)
    title = "distillation scaling" + (f" (horizontal: {names})" if refs else "") + \
        (f" (stars: {', '.join(sorted({r['policy'].partition('+')[2] for r in extra}))})" if extra else "")
    fig.suptitle(title)
    ax_f.legend(fontsize=8)
    ax_s.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.15))
    fig.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    tmp = png.with_name(f".{png.name}.partial")
    fig.savefig(tmp, format="png", dpi=100)
    tmp.replace(png)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("folder", type=pathlib.Path)
    p.add_argument("--out", type=pathlib.Path, default=None, help="write the Markdown table here")
    p.add_argument("--png", type=pathlib.Path, default=None, help="write the plot here")
    p.add_argument("--reports", type=pathlib.Path, default=None, help="the folder of the distillation reports "
                   "(default: the results folder), e.g. the held-out measurements of models distilled elsewhere")
    p.add_argument("--evaluation", type=pathlib.Path, default=None, help="a shelf-evaluate folder of the same "
                   "models and the heuristics: adds each model's SR and margin over the best heuristic on its scenes")
    p.add_argument("--falls", default="falls.json", help="the fall measurement's file in the folder (default "
                   "falls.json; e.g. another number of scenes per N)")
    p.add_argument("--heuristics", nargs="+", default=["h-d", "h-a"], help="the policies the margin is taken "
                   "over (default: h-d h-a)")
    args = p.parse_args(argv)
    reports, cells = load(args.folder, args.reports, args.falls)
    data = rows(reports, cells)
    text = table(data)
    if args.evaluation is not None:
        records = load_cells(args.evaluation)
        data = add_evaluated(data, reports, records)
        margins(data, records, args.heuristics)
        text += "\n" + margin_table(data, args.heuristics)
        fits = trend(data)
        if fits:
            text += "\nThe trend (an extrapolation, not a measurement):\n\n" + "\n".join(fits) + "\n"
    print(text)
    if args.out is not None:
        write_text_atomically(args.out, text)
    if args.png is not None:
        plot(data, args.png)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
