"""The shipped models in examples/pretrained: each loads alone on a fresh env and acts greedily on a
held-out scene; on the wrong layout (S on P+S, other cell size) `load` refuses it by name."""

import pathlib

import gymnasium as gym
import numpy as np
import pytest

import shelf_env  # noqa: F401  (registers ShelfSort-v0)
from sb3_pixeldqn import PixelDoubleDQN
from shelf_env.evaluation import protocol as ev
from shelf_env.training.ship import DISTILLED, DISTILLED_REPORT, MAX_MB, MODELS, archived

PRETRAINED = pathlib.Path(__file__).resolve().parents[1] / "examples" / "pretrained"
SHIPPED = sorted(PRETRAINED.rglob("*.zip"))


def test_what_is_shipped_is_known_and_carded():
    assert SHIPPED, "no model shipped in examples/pretrained (bash scripts/ship_models.sh)"
    names = {z.relative_to(PRETRAINED).as_posix() for z in SHIPPED}
    replaced = {f"v{k}/{DISTILLED}" for k in archived(PRETRAINED)}  # earlier distilled P+S, each with its report
    assert names <= set(MODELS.values()) | {DISTILLED} | replaced
    assert (DISTILLED in names) == (PRETRAINED / DISTILLED_REPORT).is_file()  # a distilled P+S ships with its report
    assert all((PRETRAINED / name).is_file() for name in replaced)
    card = (PRETRAINED / "README.md").read_text()
    for zip_path in SHIPPED:
        assert f"`{zip_path.relative_to(PRETRAINED).as_posix()}`: PixelDoubleDQN" in card
        assert zip_path.stat().st_size <= MAX_MB * 2**20


@pytest.mark.parametrize("zip_path", SHIPPED, ids=[z.relative_to(PRETRAINED).as_posix() for z in SHIPPED])
def test_shipped_model_loads_alone_and_acts_greedily_within_the_masks(zip_path):
    model = PixelDoubleDQN.load(zip_path)  # no env, no other file
    assert model.curriculum_state["finished"] is not None  # a finished run, not a mid-run checkpoint
    env = gym.make("ShelfSort-v0", num_objects=3, object_set="ycb", primitives=ev.checkpoint_primitives(zip_path),
                   pixel_size=ev.checkpoint_pixel_size(zip_path))  # the layout the card gives
    assert model.observation_space == env.observation_space and model.action_space == env.action_space
    obs, _ = env.reset(seed=ev.scene_seed(7, 3, 0))  # an evaluation scene (SeedSequence seeds, not the training stream)
    for _ in range(6):
        masks = env.unwrapped.action_masks()
        action, _ = model.predict(obs, deterministic=True, action_masks=masks)
        again, _ = model.predict(obs, deterministic=True, action_masks=masks)
        action = int(np.asarray(action).reshape(-1)[0])
        assert action == int(np.asarray(again).reshape(-1)[0]) and masks[action]  # greedy, within the mask
        obs, reward, terminated, truncated, info = env.step(action)
        assert reward in (-10.0, -1.0, 0.0) and obs.shape == env.observation_space.shape
        if terminated or truncated:
            break
    env.close()


@pytest.mark.parametrize("zip_path", SHIPPED, ids=[z.relative_to(PRETRAINED).as_posix() for z in SHIPPED])
def test_shipped_model_on_the_wrong_layout_is_refused_by_name(zip_path):
    own = ev.checkpoint_primitives(zip_path)
    other = ("pick",) if "push" in own else ("pick", "push")
    size = ev.checkpoint_pixel_size(zip_path)
    for kwargs in ({"primitives": other, "pixel_size": size}, {"primitives": own, "pixel_size": 2 * size}):
        env = gym.make("ShelfSort-v0", num_objects=3, **kwargs)
        with pytest.raises(ValueError, match=f"checkpoint {zip_path} does not fit this env"):
            PixelDoubleDQN.load(zip_path, env=env)
        env.close()


FILTERS = sorted(PRETRAINED.rglob("*.geometry_risk.pt"))


def test_the_shipped_p_s_plays_under_its_geometry_filter_as_its_card_says():
    """The shelf's p_s.zip ships with its camera-only pick filter and pick guard: the policy the card names loads
    from the registry alone and acts within the masks, playing no pick the filter masks while a kept one is
    allowed, and no pick of an object that looks sorted while another allowed action is left."""
    import json

    from shelf_env.baselines.heuristics import ObservationView
    from shelf_env.fall_filter import FallFilter
    from shelf_env.pick_guard import PICK_GUARD
    from shelf_env.training.model_card import filtered_name
    from shelf_env.training.ship import FILTER_INFO, FILTER_RISK

    assert PRETRAINED / FILTER_RISK in FILTERS  # the P+S to use is the filtered one
    card = (PRETRAINED / "README.md").read_text()
    for risk in FILTERS:
        zip_path = risk.with_name(DISTILLED)
        assert zip_path.is_file() and risk.with_name(FILTER_INFO).is_file()
        label = json.loads(risk.with_name(FILTER_INFO).read_text())["label"]
        name = filtered_name(zip_path.relative_to(PRETRAINED.parents[1]), label)
        assert f'make_policy("{name}", env)' in card
        guarded = PICK_GUARD in name
        assert guarded or risk != PRETRAINED / FILTER_RISK  # the shelf's P+S to use plays under the pick guard
        env = gym.make("ShelfSort-v0", num_objects=5, primitives=ev.checkpoint_primitives(zip_path),
                       pixel_size=ev.checkpoint_pixel_size(zip_path))
        policy = ev.make_policy(str(PRETRAINED.parents[1] / name), env)
        filt = policy.policy
        while not isinstance(filt, FallFilter):
            filt = filt.policy
        obs, _ = env.reset(seed=ev.scene_seed(7, 5, 0))
        first = True
        for _ in range(4):
            masks = env.unwrapped.action_masks()
            risky = (filt.risk.risk(obs) >= filt.risk.threshold).reshape(-1)
            chosen, _ = policy.predict(obs, deterministic=True, episode_start=np.array([first]), action_masks=masks)
            action = int(np.asarray(chosen).reshape(-1)[0])
            first = False
            assert masks[action]
            picks = risky.size  # the pick map comes first: actions below it are picks
            looks_sorted = ObservationView.from_observation(obs, margin_cells=0).sorted_cells.reshape(-1)
            unguarded = masks.copy()
            if guarded:
                unguarded[:picks] &= ~looks_sorted
                if unguarded.any():
                    assert action >= picks or not looks_sorted[action]
            if action < picks and (unguarded[:picks] & ~risky).any():
                assert not risky[action]
            obs, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                break
        env.close()
