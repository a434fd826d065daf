"""QEnsemble: greedy on the (weighted) mean of its members' Q-maps, within the caller's masks; and the
``NAME.ensemble.json`` policy files that evaluations, falls and the demo play it through."""

import json

import gymnasium as gym
import numpy as np
import pytest
from pixel_envs import FindTheSquareEnv

from sb3_pixeldqn import LoopBreaker, PixelDoubleDQN, QEnsemble
from shelf_env import policies
from shelf_env.cli import demo
from shelf_env.evaluation import protocol as ev

SMALL = dict(widths=(4, 8, 8))


def members(n_maps: int = 2, seeds: tuple[int, ...] = (0, 1)) -> tuple[gym.Env, list[PixelDoubleDQN]]:
    env = FindTheSquareEnv(n_maps=n_maps)
    maps = [("pick", 0)] if n_maps == 1 else [("pick", 0), ("push", 0)]
    return env, [PixelDoubleDQN("FCNPolicy", env, policy_kwargs=dict(maps=maps, **SMALL), seed=s) for s in seeds]


def test_it_acts_on_the_mean_q_maps_within_the_masks():
    env, models = members()
    obs = np.stack([env.reset(seed=k)[0] for k in range(3)])
    qs = [m.policy.q_map_values(obs).reshape(3, -1) for m in models]
    assert not np.allclose(qs[0], qs[1])  # two seeds: two different nets
    ensemble = QEnsemble(models)
    mean = (qs[0] + qs[1]) / 2
    np.testing.assert_allclose(ensemble.q_values(obs).numpy(), mean, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(ensemble.q_map_values(obs[0]), mean[0].reshape(2, 12, 20), rtol=1e-5, atol=1e-6)
    actions, state = ensemble.predict(obs)
    assert state is None and actions.shape == (3,) and list(actions) == list(mean.argmax(axis=1))
    single, _ = ensemble.predict(obs[0])
    assert np.ndim(single) == 0 and int(single) == int(mean[0].argmax())
    # masks: only the allowed actions compete, and the best of them wins
    masks = np.zeros((3, env.action_space.n), dtype=bool)
    rng = np.random.default_rng(0)
    for row in masks:
        row[rng.choice(env.action_space.n, 5, replace=False)] = True
    masked, _ = ensemble.predict(obs, action_masks=masks)
    expected = np.where(masks, mean, -np.inf).argmax(axis=1)
    assert list(masked) == list(expected) and all(masks[k, a] for k, a in enumerate(masked))


def test_weights_pick_the_members_that_count():
    env, models = members()
    obs = env.reset(seed=3)[0]
    only_first = QEnsemble(models, weights=[1.0, 0.0])
    assert int(only_first.predict(obs)[0]) == int(models[0].predict(obs, deterministic=True)[0])
    np.testing.assert_allclose(QEnsemble(models, weights=[2, 2]).weights, [0.5, 0.5])


def test_bad_members_and_weights_are_refused_by_name():
    env, models = members()
    with pytest.raises(ValueError, match="at least two models"):
        QEnsemble(models[:1])
    with pytest.raises(ValueError, match="weights must be 2"):
        QEnsemble(models, weights=[1.0, -1.0])
    with pytest.raises(ValueError, match="weights must be 2"):
        QEnsemble(models, weights=[1.0])
    _, one_map = members(n_maps=1, seeds=(0,))
    with pytest.raises(ValueError, match="member 1 has action space"):
        QEnsemble([models[0], one_map[0]])
    with pytest.raises(ValueError, match="member 1 .* has no policy"):
        QEnsemble([models[0], object()])


@pytest.fixture(scope="module")
def checkpoints(tmp_path_factory):
    """Two tiny pick-only ShelfSort checkpoints (seeds 0, 1) and one pick-and-push."""
    folder = tmp_path_factory.mktemp("ensemble")
    paths = {}
    for name, primitives, maps, seed in (("a", ("pick",), [("pick", 0)], 0), ("b", ("pick",), [("pick", 0)], 1),
                                         ("pp", ("pick", "push"), None, 0)):
        env = gym.make("ShelfSort-v0", primitives=primitives)
        kwargs = dict(maps=maps, **SMALL) if maps else dict(SMALL)
        PixelDoubleDQN("FCNPolicy", env, policy_kwargs=kwargs, seed=seed).save(folder / f"{name}.zip")
        env.close()
        paths[name] = folder / f"{name}.zip"
    return folder, paths


def test_an_ensemble_file_is_a_policy_the_evaluation_plays(checkpoints):
    folder, paths = checkpoints
    manifest = policies.write_ensemble(folder / "sub" / "e.ensemble.json", [paths["a"], paths["b"]])
    assert json.loads(manifest.read_text()) == {"members": ["../a.zip", "../b.zip"]}  # relative to its folder
    policy = str(manifest)
    assert ev.policy_label(policy) == "e" and ev.policy_label(policy + ev.LOOP_BREAKER) == "e+loop-breaker"
    assert ev.check_policy(policy) == ("pick",)
    assert ev.policy_pixel_size(policy) == policies.checkpoint_pixel_size(paths["a"])
    assert ev.policy_files(policy) == [manifest, manifest.parent / "../a.zip", manifest.parent / "../b.zip"]
    # the digest covers the members' bytes, not only the file naming them
    other = policies.write_ensemble(folder / "f.ensemble.json", [paths["a"], paths["a"]])
    assert ev.policy_digest(policy) != ev.policy_digest(str(other))
    env = ev.make_env(policy, 2, "train")
    try:
        agent = ev.make_policy(policy, env)
        assert isinstance(agent, QEnsemble) and len(agent.models) == 2 and ev.takes_action_masks(agent)
        obs, _ = env.reset(seed=ev.scene_seed(0, 2, 0))
        masks = env.get_wrapper_attr("action_masks")()
        mean = (agent.models[0].policy.q_map_values(obs) + agent.models[1].policy.q_map_values(obs)).reshape(-1) / 2
        assert ev.greedy_action(env, agent, obs, True, True, False) == int(np.where(masks, mean, -np.inf).argmax())
        record = ev.run_episode(env, agent, ev.scene_seed(0, 2, 0), max_actions=3)
        assert record["actions"] >= 1
        wrapped = ev.make_policy(policy + ev.LOOP_BREAKER, env)
        assert isinstance(wrapped, LoopBreaker)
        # the demo overlays the ensemble's mean maps, bare or through the breaker
        assert demo.q_map_values_of(wrapped)(obs).shape == (1, *obs.shape[1:])
        np.testing.assert_allclose(demo.q_map_values_of(agent)(obs).reshape(-1), mean, rtol=1e-5, atol=1e-6)
    finally:
        env.close()


def test_bad_ensemble_files_are_refused_by_name(checkpoints):
    folder, paths = checkpoints
    with pytest.raises(ValueError, match="ends with '.ensemble.json'"):
        policies.write_ensemble(folder / "e.json", [paths["a"], paths["b"]])
    with pytest.raises(ValueError, match="two or more members"):
        policies.write_ensemble(folder / "one.ensemble.json", [paths["a"]])
    with pytest.raises(ValueError, match="not files"):
        policies.write_ensemble(folder / "gone.ensemble.json", [paths["a"], folder / "gone.zip"])
    assert not (folder / "gone.ensemble.json").exists()  # nothing half-written
    broken = folder / "broken.ensemble.json"
    broken.write_text("{not json")
    with pytest.raises(ValueError, match="broken.ensemble.json is not readable JSON"):
        ev.check_policy(str(broken))
    (folder / "short.ensemble.json").write_text(json.dumps({"members": ["a.zip"]}))
    with pytest.raises(ValueError, match="two or more checkpoint paths"):
        ev.check_policy(str(folder / "short.ensemble.json"))
    (folder / "lost.ensemble.json").write_text(json.dumps({"members": ["a.zip", "lost.zip"]}))
    with pytest.raises(ValueError, match="not files: .*lost.zip"):
        ev.check_policy(str(folder / "lost.ensemble.json"))
    mixed = policies.write_ensemble(folder / "mixed.ensemble.json", [paths["a"], paths["pp"]])
    with pytest.raises(ValueError, match="different primitives"):
        ev.check_policy(str(mixed))
