"""The camera-only pick filter (shelf_env.fall_filter): each named feature as a crafted scene's geometry says,
a filter that masks exactly the risky picks, a geometry risk that scores every object cell with its model and
survives a save, and the shipped policy name ``<zip>+geometry-filter+loop-breaker``."""

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from pixel_envs import ScoresPolicy

from sb3_pixeldqn import PixelDoubleDQN
from sb3_pixeldqn.loop_breaker import LoopBreaker
from shelf_env import fall_filter as ff
from shelf_env import params, policies
from shelf_env.baselines.heuristics import object_blobs
from shelf_env.camera.heightmap import CLASS_RGB, OCCLUDED_RGB, REGION_RGB, observed_height
from shelf_env.conditions.safe_picks import Z_CARRY


def paint(obs, rows, cols, rgb, height=None):
    obs[:3, rows, cols] = np.asarray(rgb, np.uint8)[:, None, None]
    if height is not None:
        obs[3, rows, cols] = int(round(height / params.CABINET_HEIGHT * 255))


def crafted():
    """40 x 60 cells (1 cm): class 0's region at the front left; object A (class 0, 10 cm tall) at the back with
    grey cells behind it, object B (class 1, 12 cm) in front of it, overlapping its columns."""
    obs = np.full((4, 40, 60), 255, np.uint8)
    obs[3] = 0
    paint(obs, slice(30, 40), slice(0, 20), REGION_RGB[0])
    paint(obs, slice(5, 10), slice(10, 15), CLASS_RGB[0], 0.10)
    paint(obs, slice(20, 23), slice(12, 17), CLASS_RGB[1], 0.12)
    paint(obs, slice(0, 5), slice(10, 15), OCCLUDED_RGB)
    return obs


def test_each_feature_is_the_crafted_scene_s_geometry():
    obs = crafted()
    height = observed_height(obs)
    a, b = height[7, 12], height[21, 14]
    cells = np.array([7 * 60 + 12, 21 * 60 + 14, 35 * 60 + 50, 5 * 60 + 10])
    x = ff.geometry_features(obs, cells)
    assert x.shape == (4, len(ff.FEATURES)) and x.dtype == np.float32
    f = [dict(zip(ff.FEATURES, row)) for row in x.astype(float)]
    first = f[0]
    assert first["on_object"] == 1 and first["cell_height"] == pytest.approx(a)
    assert first["object_area"] == 25 and first["object_rows"] == 5 and first["object_cols"] == 5
    assert first["object_back_row"] == 5 and first["object_front_row"] == 30 and first["wall_distance"] == 10
    assert first["offset_rows"] == 0 and first["offset_cols"] == 0 and first["edge_distance"] == 3
    # B stands in A's corridor to the opening: 3 rows x its 3 columns that A's columns cover
    assert first["corridor_cells"] == 9
    for name in ("carry_margin_05", "carry_margin_15", "carry_margin_30"):
        assert first[name] == pytest.approx(Z_CARRY - a - b, abs=1e-6)
    assert first["nearest_other"] == 11 and first["tallest_near"] == 0  # B is 11 cells away, beyond 3 cm
    assert first["grey_behind"] == 25 and first["grey_near"] == 5  # the grey row next to A's back edge
    assert first["in_region"] == 0 and first["region_free"] == 1 and first["region_tallest"] == 0
    assert first["scene_objects"] == 2 and first["scene_grey"] == pytest.approx(25 / 2400)
    second = f[1]  # B: nothing in front of it, no region of its class on the map
    assert second["corridor_cells"] == 0 and second["carry_margin_05"] == pytest.approx(Z_CARRY - b, abs=1e-6)
    assert second["object_front_row"] == 17 and second["region_free"] == 0
    assert second["grey_behind"] == 15  # the grey cells behind A that lie in B's columns too
    assert second["offset_cols"] == pytest.approx(0) and second["edge_distance"] == 2  # B is 3 rows deep
    off = f[2]  # on no object: its height and the scene only
    assert off["on_object"] == 0 and off["object_area"] == 0 and off["carry_margin_05"] == 0
    assert off["scene_objects"] == 2
    corner = f[3]  # A's back left corner: on the edge, behind and left of the centre
    assert corner["edge_distance"] == 1 and corner["offset_rows"] == pytest.approx(-2 / 5)
    assert corner["offset_cols"] == pytest.approx(2 / 5)
    # B moved into A's region: A is no longer in front of anything, and the region is less free
    moved = obs.copy()
    paint(moved, slice(20, 23), slice(12, 17), (255, 255, 255), 0.0)
    paint(moved, slice(32, 35), slice(2, 5), CLASS_RGB[1], 0.12)
    y = dict(zip(ff.FEATURES, ff.geometry_features(moved, cells[:1])[0].astype(float)))
    assert y["corridor_cells"] == 0 and y["region_free"] == pytest.approx(191 / 200)
    assert y["region_tallest"] == pytest.approx(b)
    mirrored = ff.geometry_features(obs[:, :, ::-1].copy(), np.array([7 * 60 + 59 - 12]))
    assert np.allclose(mirrored, x[:1])  # the features are symmetric under the left-right mirror
    # round two: B blocks A's carry (its 12 cm top is above A's bottom, Z_CARRY - 10 cm)
    both = ff.geometry_features(obs, cells[:2], blockers=True)
    assert np.array_equal(both[:, :len(ff.FEATURES)], x[:2])  # round one's columns unchanged
    blocked = dict(zip(ff.BLOCKER_FEATURES, both[0, len(ff.FEATURES):].astype(float)))
    assert blocked["blockers"] == 1 and blocked["blocker_gap"] == 10 and blocked["blocker_to_opening"] == 17
    assert blocked["blocker_rows"] == 3 and blocked["blocker_cols"] == 5 and blocked["blocker_area"] == 15
    assert blocked["blocker_in_corridor"] == pytest.approx(3 / 5) and blocked["blockers_area"] == 15
    assert blocked["blocker_stopped"] == 0 and blocked["carry_bottom"] == pytest.approx(Z_CARRY - a, abs=1e-6)
    free = dict(zip(ff.BLOCKER_FEATURES, both[1, len(ff.FEATURES):].astype(float)))
    assert free["blockers"] == 0 and free["blocker_area"] == 0 and free["carry_bottom"] == pytest.approx(Z_CARRY - b)
    stopper = obs.copy()  # a low object in front of B, in B's columns but not A's: it may stop B
    paint(stopper, slice(26, 28), slice(16, 18), CLASS_RGB[2], 0.03)
    stopped = dict(zip(ff.feature_names(True), ff.geometry_features(stopper, cells[:1], blockers=True)[0]))
    assert stopped["blocker_stopped"] == 1 and stopped["blockers"] == 1 and stopped["corridor_cells"] == 9
    with pytest.raises(ValueError, match="one \\(4, H, W\\) observation"):
        ff.geometry_features(obs[:3], cells)
    with pytest.raises(ValueError, match="cells must lie in"):
        ff.geometry_features(obs, np.array([2400]))


MAPS, H, W = 2, 3, 4  # map 0: pick, map 1: push


def scored(scores):
    """A greedy pixel policy over ``scores`` on this file's observations."""
    return ScoresPolicy(scores, (4, H, W))


class FixedRisk:
    threshold = 0.5

    def __init__(self, risk):
        self.map = np.asarray(risk, float)

    def risk(self, obs):
        return self.map


def test_the_filter_masks_exactly_the_risky_picks():
    scores = np.arange(MAPS * H * W, dtype=float)[::-1].copy()  # best: pick (0, 0), then (0, 1), ...
    obs = np.zeros((4, H, W), np.uint8)
    risk = np.zeros((H, W))
    risk[0, 0] = 0.9  # the best pick is risky
    filt = ff.FallFilter(scored(scores), FixedRisk(risk), ("pick", "push"), H, W)
    masks = np.ones(MAPS * H * W, bool)
    assert int(filt.predict(obs, action_masks=masks)[0]) == 1  # the next-best pick
    assert filt.stats == {"masked": 1, "unfiltered": 0}
    masks[1] = False  # the caller's masks still hold
    assert int(filt.predict(obs, action_masks=masks)[0]) == 2
    everything = ff.FallFilter(scored(scores), FixedRisk(np.ones((H, W))), ("pick", "push"), H, W)
    assert int(everything.predict(obs, action_masks=np.ones(MAPS * H * W, bool))[0]) == H * W  # a push
    only_picks = np.zeros(MAPS * H * W, bool)
    only_picks[:H * W] = True
    assert int(everything.predict(obs, action_masks=only_picks)[0]) == 0  # nothing safe: unfiltered
    assert everything.stats == {"masked": 2, "unfiltered": 1}
    assert int(everything.predict(obs)[0]) == 0  # a policy without env masks, every pick risky: unfiltered
    safe = ff.FallFilter(scored(scores), FixedRisk(np.zeros((H, W))), ("pick", "push"), H, W)
    assert int(safe.predict(obs, action_masks=np.ones(MAPS * H * W, bool))[0]) == 0
    with pytest.raises(ValueError, match="pick map"):
        ff.FallFilter(scored(scores), FixedRisk(risk), ("push", "pull"), H, W)
    with pytest.raises(ValueError, match="shape"):
        filt.predict(np.zeros((1, 4, H, W), np.uint8))
    other = FixedRisk(risk)
    other.info = {"obs_shape": [4, 2 * H, 2 * W]}
    with pytest.raises(ValueError, match=r"trained on observations of shape \(4, 6, 8\)"):
        ff.FallFilter(scored(scores), other, ("pick", "push"), H, W)


def test_a_geometry_risk_scores_each_object_cell_with_its_model_and_survives_a_save(tmp_path):
    obs = crafted()
    th.manual_seed(0)
    names = ff.feature_names(True)
    model = ff.FeatureModel(np.linspace(0, 1, len(names)), np.linspace(1, 2, len(names)), hidden=8)
    model.eval()
    risk = ff.GeometryRisk(model, blockers=True, threshold=0.3, obs_shape=obs.shape)
    on = np.flatnonzero(object_blobs(obs).reshape(-1) >= 0)
    per_cell = risk.risk(obs)
    assert per_cell.shape == (40, 60) and len(on) == 25 + 15
    assert np.allclose(per_cell.reshape(-1)[on], model.risk(ff.geometry_features(obs, on, blockers=True)))
    assert (np.delete(per_cell.reshape(-1), on) == 0).all()  # nothing to drop where no object is
    risk.save(tmp_path / "r.geometry_risk.pt")
    back = ff.GeometryRisk.load(tmp_path / "r.geometry_risk.pt")
    assert back.threshold == 0.3 and back.blockers and back.hidden == 8 and back.info["obs_shape"] == [4, 40, 60]
    assert np.array_equal(back.risk(obs), per_cell)
    with pytest.raises(ValueError, match="threshold must be in"):
        ff.GeometryRisk(model, True, 0.0, obs.shape)
    with pytest.raises(ValueError, match="does not exist"):
        ff.GeometryRisk.load(tmp_path / "missing.pt")
    (tmp_path / "junk.pt").write_bytes(b"not a model")
    with pytest.raises(ValueError, match="junk.pt is not a readable geometry risk model"):
        ff.GeometryRisk.load(tmp_path / "junk.pt")
    assert ff.geometry_risk_path("a/b/p_s.zip") == ff.pathlib.Path("a/b/p_s.geometry_risk.pt")


def test_the_product_plays_a_checkpoint_under_its_geometry_filter_and_the_loop_breaker(tmp_path):
    """``<zip>+geometry-filter+loop-breaker`` (the shipped P+S's name) is known to the product's registry without
    any experiment imported: refused without its model or for a named policy, then a `LoopBreaker` around a
    `FallFilter` whose every played pick is one the risk keeps."""
    env = gym.make("ShelfSort-v0", pixel_size=0.02)
    zip_path = tmp_path / "p.zip"
    PixelDoubleDQN("FCNPolicy", env, policy_kwargs=dict(maps=[("pick", 0), ("push", 0), ("push", 180)],
                                                        widths=(4, 8, 8)), seed=0).save(zip_path)
    name = f"{zip_path}+geometry-filter+loop-breaker"
    with pytest.raises(ValueError, match="no geometry risk model at .*p.geometry_risk.pt"):
        policies.check_policy(name)
    with pytest.raises(ValueError, match="not a checkpoint"):
        policies.check_policy("h-d+geometry-filter")
    names = ff.feature_names(True)
    model = ff.FeatureModel(np.zeros(len(names)), np.ones(len(names)), hidden=0)
    with th.no_grad():  # risk rises with the pick cell's height: the tall objects' picks are masked
        model.net.weight.zero_()
        model.net.weight[0, names.index("cell_height")] = 100.0
        model.net.bias.fill_(-5.0)
    ff.GeometryRisk(model, True, 0.5, env.observation_space.shape).save(ff.geometry_risk_path(zip_path))
    assert policies.check_policy(name) == ("pick", "push")
    assert policies.policy_label(name) == "p+geometry-filter+loop-breaker"
    assert ff.geometry_risk_path(zip_path) in policies.policy_files(name)
    policy = policies.make_policy(name, env)
    assert isinstance(policy, LoopBreaker) and isinstance(policy.policy, ff.FallFilter)
    obs, _ = env.reset(seed=3)
    risky = policy.policy.risk.risk(obs) >= 0.5
    assert risky.any() and not risky.all()
    masks = env.unwrapped.action_masks()
    for _ in range(3):
        action = int(policy.predict(obs, deterministic=True, action_masks=masks)[0])
        if action < risky.size and (masks[:risky.size] & ~risky.reshape(-1)).any():
            assert not risky.reshape(-1)[action]  # a pick it plays is one the filter keeps
    env.close()
