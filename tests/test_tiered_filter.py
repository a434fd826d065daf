"""The tiered geometry filter (research.tiered_filter): picks at risk >= PREFER are masked only while an allowed pick
on a visible object stays below it; otherwise the risk's own threshold holds. And research.fall_sources' counts."""

import numpy as np
import pytest
from pixel_envs import ScoresPolicy
from test_fall_filter import crafted

from research import fall_sources, tiered_filter
from shelf_env.baselines.heuristics import object_blobs

H, W, MAPS = 40, 60, 2


class Risk:
    threshold = 0.1
    info: dict = {}

    def __init__(self, risk):
        self.map = np.asarray(risk, float)

    def risk(self, obs):
        return self.map


def scene():
    """The crafted scene (object A at rows 5-9, cols 10-14; B at rows 20-22, cols 12-16), its risk (A 0.07, B 0.02,
    0 elsewhere), and a policy that ranks A's picks first, then B's, then every push."""
    obs = crafted()
    blobs = object_blobs(obs)
    a, b = blobs[7, 12], blobs[21, 14]
    risk = np.where(blobs == a, 0.07, np.where(blobs == b, 0.02, 0.0))
    scores = np.zeros(MAPS * H * W)
    scores[:H * W] = np.where(blobs == a, 3.0, np.where(blobs == b, 2.0, 0.0)).reshape(-1)
    scores[H * W:] = 1.0
    return obs, blobs, a, b, risk, scores


def pick_blob(blobs, action):
    assert action < H * W, f"{action} is not a pick"
    return blobs.reshape(-1)[action]


def test_risky_picks_wait_while_a_safer_pick_exists():
    obs, blobs, a, b, risk, scores = scene()
    on_objects = np.zeros(MAPS * H * W, bool)
    on_objects[:H * W] = (blobs >= 0).reshape(-1)
    on_objects[H * W:] = True
    filt = tiered_filter.TieredFilter(ScoresPolicy(scores, (4, H, W)), Risk(risk), ("pick", "push"), H, W)
    assert pick_blob(blobs, int(filt.predict(obs, action_masks=on_objects)[0])) == b  # A (0.07) waits for B (0.02)
    assert filt.tightened == 1
    no_b = on_objects.copy()
    no_b[:H * W] &= (blobs != b).reshape(-1)  # B masked by the caller (the guard): nothing safer is left
    assert pick_blob(blobs, int(filt.predict(obs, action_masks=no_b)[0])) == a  # A is under the file's 0.1
    assert filt.tightened == 1
    empty_cell = no_b.copy()
    empty_cell[0] = True  # an allowed pick off every object (risk 0) is not a safer pick
    assert blobs[0, 0] < 0
    assert pick_blob(blobs, int(filt.predict(obs, action_masks=empty_cell)[0])) == a
    over = np.where(blobs == a, 0.2, risk)  # over the file's threshold: masked whatever is left
    strict = tiered_filter.TieredFilter(ScoresPolicy(scores, (4, H, W)), Risk(over), ("pick", "push"), H, W)
    assert int(strict.predict(obs, action_masks=no_b)[0]) >= H * W  # a push
    assert strict.stats["masked"] == 1


def test_the_tiered_filter_refuses_what_it_cannot_use():
    obs, _, _, _, risk, scores = scene()
    filt = tiered_filter.TieredFilter(ScoresPolicy(scores, (4, H, W)), Risk(risk), ("pick", "push"), H, W)
    with pytest.raises(ValueError, match="action masks"):
        filt.predict(obs)
    with pytest.raises(ValueError, match=r"prefer must be in \(0, 0.1\]"):
        tiered_filter.TieredFilter(ScoresPolicy(scores, (4, H, W)), Risk(risk), ("pick", "push"), H, W, prefer=0.2)


def test_fall_sources_counts_each_map_and_the_picks_by_risk_bin():
    decisions = [{"map": "pick", "risk": 0.01, "fell": False, "invalid": False},
                 {"map": "pick", "risk": 0.07, "fell": True, "invalid": True},
                 {"map": "pick", "risk": 0.05, "fell": False, "invalid": True},
                 {"map": "push_left", "risk": None, "fell": True, "invalid": True}]
    out = fall_sources.summary(decisions)
    assert out["decisions"] == 4 and out["fell"] == 2
    assert out["pick"] == {"decisions": 3, "fell": 1, "invalid": 2}
    assert out["push_left"] == {"decisions": 1, "fell": 1, "invalid": 1}
    assert [(b["decisions"], b["fell"]) for b in out["pick_risk_bins"]] == [(1, 0), (0, 0), (2, 1), (0, 0)]
    assert out["pick_risk_bins"][-1]["to"] is None
    assert "safest_cell" not in out  # no alternatives asked for


def test_fall_sources_compares_each_pick_with_its_object_s_safest_cell():
    base = {"map": "pick", "risk": 0.07, "alt_risk": 0.01}
    decisions = [{**base, "fell": True, "invalid": True, "sorted": 2, "alt_same": False, "alt_invalid": False,
                  "alt_fell": False, "alt_sorted": 2},  # a fall the safest cell would have kept valid
                 {**base, "fell": True, "invalid": True, "sorted": 2, "alt_same": False, "alt_invalid": True,
                  "alt_fell": True, "alt_sorted": 2},  # it falls there too
                 {**base, "fell": False, "invalid": False, "sorted": 3, "alt_same": False, "alt_invalid": False,
                  "alt_fell": False, "alt_sorted": 2},  # both valid; the safest cell sorts fewer
                 {**base, "fell": False, "invalid": False, "sorted": 3, "alt_same": True}]  # already the safest
    assert fall_sources.summary(decisions)["safest_cell"] == {
        "picks": 4, "already_safest": 1, "moved": 3, "fell": 2, "alt_fell": 1, "fell_alt_kept": 1, "valid_both": 1,
        "valid_both_alt_sorted_fewer": 1}
