"""shelf_env/pick_guard.py: ``+pick-guard`` masks the picks of objects that look sorted and of objects the episode
has already picked ``max_picks`` times, remembers only the picks that were executed, forgets at an episode's
start, stands aside when nothing allowed is left, and composes with the geometry filter and the loop breaker."""

import numpy as np
import pytest
from pixel_envs import ScoresPolicy

from sb3_pixeldqn.loop_breaker import LoopBreaker
from shelf_env import params, policies
from shelf_env.camera.heightmap import CLASS_RGB, REGION_RGB
from shelf_env.pick_guard import PICK_GUARD, PickGuard

H, W, MAPS = 40, 60, 3


def paint(obs, rows, cols, rgb, height=0.05):
    obs[:3, rows, cols] = np.asarray(rgb, np.uint8)[:, None, None]
    obs[3, rows, cols] = int(round(height / params.CABINET_HEIGHT * 255))


def crafted():
    """Class 0's region at the front left holding object A (class 0: it looks sorted); object B (class 1) at the
    back right, in no region (unsorted)."""
    obs = np.full((4, H, W), 255, np.uint8)
    obs[3] = 0
    paint(obs, slice(28, 40), slice(0, 20), REGION_RGB[0], 0.0)
    paint(obs, slice(31, 36), slice(5, 10), CLASS_RGB[0])
    paint(obs, slice(5, 10), slice(40, 45), CLASS_RGB[1])
    return obs


def flat(m, row, col):
    return m * H * W + row * W + col


def scored(scores):
    """A greedy pixel policy over ``scores`` on this file's observations."""
    return ScoresPolicy(scores, (4, H, W))


def scores():
    """Best: a pick of A (sorted), then a pick of B, then a push at (20, 30); everything else lower."""
    s = np.zeros(MAPS * H * W)
    s[flat(0, 33, 7)] = 3.0
    s[flat(0, 7, 42)] = 2.0
    s[flat(1, 20, 30)] = 1.0
    return s


def test_the_guard_masks_sorted_objects_then_objects_picked_too_often_and_forgets_at_a_new_episode():
    obs, guard = crafted(), PickGuard(scored(scores()), ("pick", "push_left", "push_right"), H, W, max_picks=3)
    start, go_on = np.array([True]), np.array([False])
    assert int(guard.predict(obs, episode_start=start)[0]) == flat(0, 7, 42)  # A looks sorted: B's pick
    assert guard.stats == {"guarded": 1, "unguarded": 0}
    assert int(guard.predict(obs, episode_start=go_on)[0]) == flat(0, 7, 42)  # one pick of B so far
    assert int(guard.predict(obs, episode_start=go_on)[0]) == flat(0, 7, 42)  # two
    assert int(guard.predict(obs, episode_start=go_on)[0]) == flat(1, 20, 30)  # three: B is guarded too, a push
    assert int(guard.predict(obs, episode_start=go_on)[0]) == flat(1, 20, 30)  # a push is not counted
    assert int(guard.predict(obs, episode_start=start)[0]) == flat(0, 7, 42)  # a new episode forgets B's picks
    for _ in range(3):
        guard.predict(obs)
    guard.reset()  # so does reset, for a caller that passes no episode_start
    assert int(guard.predict(obs)[0]) == flat(0, 7, 42)
    only_a = np.zeros(MAPS * H * W, bool)
    only_a[flat(0, 33, 7)] = True
    assert int(guard.predict(obs, episode_start=start, action_masks=only_a)[0]) == flat(0, 33, 7)  # stands aside
    assert guard.stats["unguarded"] == 1
    masks = np.ones(MAPS * H * W, bool)
    masks[flat(0, 7, 42)] = False  # the caller's masks still hold
    assert int(guard.predict(obs, episode_start=start, action_masks=masks)[0]) != flat(0, 7, 42)


def test_under_the_loop_breaker_both_answers_of_a_redirected_step_count():
    """The breaker asks again where its ban hits the guard's answer; the guard counts every pick it returned."""
    obs = crafted()
    guard = PickGuard(scored(scores()), ("pick", "push_left", "push_right"), H, W, max_picks=3)
    breaker = LoopBreaker(guard, max_visits=1, radius=0)  # bans a cell after one action on it
    first = int(breaker.predict(obs, episode_start=np.array([True]), deterministic=True)[0])
    assert first == flat(0, 7, 42) and guard._picks == [(7, 42)]
    second = int(breaker.predict(obs, episode_start=np.array([False]), deterministic=True)[0])
    assert breaker.stats["redirects"] == 1  # B's cell is banned: asked again, the next-best action is the push
    assert second == flat(1, 20, 30)
    assert guard._picks == [(7, 42), (7, 42)]  # the redirected first answer counted, the push did not


def test_bad_input_and_the_registry():
    with pytest.raises(ValueError, match="pick map"):
        PickGuard(scored(scores()), ("push_left", "push_right", "pull"), H, W)
    with pytest.raises(ValueError, match="max_picks"):
        PickGuard(scored(scores()), ("pick", "push_left", "push_right"), H, W, max_picks=0)
    with pytest.raises(ValueError, match="shape"):
        PickGuard(scored(scores()), ("pick", "push_left", "push_right"), H, W).predict(np.zeros((1, 4, H, W)))
    assert policies.policy_wrappers("m.zip+geometry-filter+pick-guard+loop-breaker") == (
        "m.zip", ("+geometry-filter", PICK_GUARD, "+loop-breaker"))
