"""examples/plot_training.py: the curve of a staged run and of a run on a mix of sizes."""

import csv
import json
import pathlib
import runpy
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]


def write_run(run, sizes, successes, config):
    run.mkdir()
    (run / "progress.json").write_text(json.dumps({"config": config}))
    with open(run / "episodes.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["timestep", "wall_seconds", "num_objects", "success", "actions", "return", "fell"])
        for i, (n, ok) in enumerate(zip(sizes, successes)):
            w.writerow([10 * (i + 1), 6.0 * (i + 1), n, int(ok), 5, -4, 0])


def plot(run, png, monkeypatch, capsys) -> str:
    monkeypatch.setattr(sys, "argv", ["plot_training.py", str(run), "--png", str(png)])
    runpy.run_path(str(ROOT / "examples" / "plot_training.py"), run_name="__main__")
    return capsys.readouterr().out


@pytest.mark.parametrize("mixed", [False, True])
def test_plot_training_writes_the_curve_and_one_line_per_n(tmp_path, monkeypatch, capsys, mixed):
    sizes = [3, 5, 4, 3, 5, 4] * 5 if mixed else [1] * 10 + [2] * 20
    successes = [n < 5 for n in sizes] if mixed else [True] * 10 + [i % 2 == 0 for i in range(20)]
    write_run(tmp_path / "run", sizes, successes, {"primitives": ["pick", "push"],
                                                   "min_num_objects": 3 if mixed else None})
    out = plot(tmp_path / "run", tmp_path / "curve.png", monkeypatch, capsys)
    assert (tmp_path / "curve.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    lines = [line for line in out.splitlines() if line.startswith("N=")]
    if mixed:
        assert [line.split(":")[0] for line in lines] == ["N=3", "N=4", "N=5"]
        assert "success 100 %" in lines[0] and "success 0 %" in lines[2]
    else:
        assert "N=1: from step 10" in lines[0] and "N=2: from step 110" in lines[1] and "success 50 %" in lines[1]
