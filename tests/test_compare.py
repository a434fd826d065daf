"""The paired comparison of two policies on the same scenes: counts, McNemar's exact p, pooling, bad input."""

import dataclasses
import json

import pytest

from shelf_env.evaluation import compare
from shelf_env.evaluation.protocol import EpisodeRecord


def rec(policy, n, seed, run, success):
    return EpisodeRecord(policy, "ycb", n, seed, run, success, 10 if success else 40, 0 if success else 2, False)


def write_cells(folder, records):
    (folder / "cells").mkdir(parents=True)
    for i, r in enumerate(records):
        (folder / "cells" / f"c{i:03d}.json").write_text(json.dumps([dataclasses.asdict(r)]))


def test_mcnemar_exact_on_hand_computed_values():
    assert compare.mcnemar_exact(0, 0) == 1.0
    assert compare.mcnemar_exact(0, 6) == pytest.approx(2 / 2**6)  # all six discordant scenes one way
    assert compare.mcnemar_exact(6, 0) == compare.mcnemar_exact(0, 6)
    assert compare.mcnemar_exact(2, 8) == pytest.approx(2 * (1 + 10 + 45) / 2**10)
    assert compare.mcnemar_exact(5, 5) == 1.0  # an even split: capped at 1
    with pytest.raises(ValueError, match="discordant counts must be >= 0"):
        compare.mcnemar_exact(-1, 2)


def test_pairs_read_only_the_scenes_both_played_and_pool(tmp_path, capsys):
    # N = 3: a sorts runs 0, 1, 2; b sorts 0 and 3; run 4 only a played (left out of the pair)
    records = [rec("a", 3, 0, r, r in (0, 1, 2)) for r in range(5)] + [rec("b", 3, 0, r, r in (0, 3))
                                                                     for r in range(4)]
    # N = 5: a sorts nothing, b sorts run 1; a second pair c/d at N = 3 only
    records += [rec("a", 5, 0, r, False) for r in range(2)] + [rec("b", 5, 0, r, r == 1) for r in range(2)]
    records += [rec("c", 3, 1, r, True) for r in range(2)] + [rec("d", 3, 1, r, False) for r in range(2)]
    write_cells(tmp_path, records)
    out = tmp_path / "cmp.md"
    assert compare.main([str(tmp_path), "--pair", "a", "b", "--pair", "c", "d", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert out.read_text() + "\n" == text
    # a vs b at N = 3 over runs 0..3: 3 sorted vs 2, a only {1, 2}, b only {3}
    assert "| 3 | 4 | 75.0 % | 50.0 % | +25.0 | 2 | 1 | 1.000 |" in text
    assert "| 5 | 2 | 0.0 % | 50.0 % | -50.0 | 0 | 1 | 1.000 |" in text
    assert "| pooled | 6 | 50.0 % | 50.0 % | +0.0 | 2 | 2 | 1.000 |" in text
    # both pairs pooled: at N = 3, 4 + 2 scenes, a/c sorted 5, b/d 2, discordant 4 against 1
    assert "**All 2 pairs pooled**" in text
    assert "| 3 | 6 | 83.3 % | 33.3 % | +50.0 | 4 | 1 | 0.375 |" in text
    assert "| pooled | 8 | 62.5 % | 37.5 % | +25.0 | 4 | 2 | 0.688 |" in text
    c = compare.compare(compare.by_scene(compare.load_cells(tmp_path)), [("c", "d")])[("c", "d")][3]
    assert (c.difference, c.p_value) == (100.0, 0.5)


def test_bad_pairs_are_refused_naming_the_policies(tmp_path, capsys):
    write_cells(tmp_path, [rec("a", 3, 0, 0, True), rec("b", 5, 0, 0, True)])
    assert compare.main([str(tmp_path), "--pair", "a", "b"]) == 2
    assert "a and b share no scene at N = 3 (policies played there: a)" in capsys.readouterr().err
    assert compare.main([str(tmp_path), "--pair", "x", "y", "--out", str(tmp_path / "o.md")]) == 2
    assert "neither x nor y is in the evaluation (its policies: a, b)" in capsys.readouterr().err
    assert not (tmp_path / "o.md").exists()
    assert compare.main([str(tmp_path / "none"), "--pair", "a", "b"]) == 2
    assert "has no evaluation cells" in capsys.readouterr().err
