"""shelf_env.training.config: presets, the model they build, demonstrations on the real env, masks in evaluation."""

import gymnasium as gym
import numpy as np
import pytest

from sb3_pixeldqn import PixelDoubleDQN
from shelf_env import params
from shelf_env.baselines.heuristics import DistanceHeuristic
from shelf_env.evaluation import protocol as ev
from shelf_env.symmetry import MirrorWidth, PermuteClasses
from shelf_env.training.config import PRESETS, TrainConfig, collect_demonstrations, demo_policy, make_env, make_model


def test_paper_preset_keeps_the_papers_values():
    paper = PRESETS["paper"]
    assert (paper.learning_rate, paper.tau, paper.target_update_interval, paper.gamma, paper.batch_size) == (
        1e-4, 1e-3, 1, 0.9, 32)
    assert not paper.masked and not paper.masked_exploration and paper.demo_policy is None and paper.augment == ()
    assert (paper.pixel_size, paper.gate, paper.relabel, paper.exploration_initial_eps) == (
        0.005, "training", "all", 0.8)


def test_recipe_model_has_every_lever_and_config_round_trips():
    config = PRESETS["recipe"].replace(buffer_size=100, widths=(4, 8, 8))
    env = make_env(config)
    model = make_model(config, env)
    assert model.masked and model._use_masks and model.target_update_interval == 100 and model.tau == 1.0
    assert [type(t) for t in model.augment] == [MirrorWidth, PermuteClasses]
    assert model.replay_buffer.relabel == "changed" and model.replay_buffer.noop == "penalty"
    assert model.observation_space.shape == (4, 40, 60)
    assert TrainConfig.from_dict(config.to_dict()) == config
    with pytest.raises(ValueError, match="unknown TrainConfig fields \\['lr'\\]"):
        config.replace(lr=1)
    with pytest.raises(ValueError, match="unknown augmentations \\['rotate'\\]"):
        make_model(config.replace(augment=("rotate",)), env)
    env.close()


@pytest.mark.parametrize("bad", [0, -2, 1.5, True, "4"])
def test_n_envs_must_be_a_positive_integer(bad):
    with pytest.raises(ValueError, match="n_envs must be an integer >= 1"):
        PRESETS["p_s"].replace(n_envs=bad)


def test_parallel_envs_and_the_actor_process_exclude_each_other():
    with pytest.raises(ValueError, match="cannot be combined with n_envs = 4"):
        PRESETS["p_s"].replace(actor=True, n_envs=4)
    assert PRESETS["p_s"].replace(actor=True, n_envs=1).actor  # one env in an actor process is fine


def test_lookahead_teacher_probes_the_training_env_it_demonstrates_in():
    # demo_policy="h-d-lookahead": H-d that probes each pick in the very env the demonstrations are
    # played in (a privileged teacher); its probes leave that env's episode as it was
    from shelf_env.privileged.lookahead import LookaheadDistance

    config = PRESETS["recipe"].replace(buffer_size=50, widths=(4, 8, 8), start_objects=2,
                                       demo_policy="h-d-lookahead")
    env = make_env(config)
    model = make_model(config, env)
    teacher = demo_policy(config, env)
    assert isinstance(teacher, LookaheadDistance) and teacher.env is env
    stats = model.collect_demonstrations(teacher, 6)
    assert stats["steps"] == 6 and stats["successes"] >= 1
    assert teacher.stats["probes"] >= teacher.stats["decisions"] >= 1
    demos = model.replay_buffer.demonstrations
    assert demos is not None and demos.n_stored >= 6
    env.close()


def test_lookahead_teacher_counterfactuals_are_kept_as_terminal_non_expert_transitions(monkeypatch):
    # demo_counterfactuals: every pick the teacher rejected (its probe ended the episode invalid) is
    # stored before the step as a terminal transition with the env's reward, without the margin flag
    from shelf_env.privileged import lookahead

    config = PRESETS["recipe"].replace(buffer_size=50, widths=(4, 8, 8), start_objects=2, demo_steps=6,
                                       demo_objects=(2,), demo_policy="h-d-lookahead", demo_counterfactuals=True)
    env = make_env(config)
    model = make_model(config, env)
    teacher = demo_policy(config, env)
    real_probe = lookahead.probe_step
    first_probes: list[int] = []

    def probe(probed_env, action):  # the first candidate of every decision "falls": each step has a veto
        outcome = real_probe(probed_env, action)
        if not teacher._probed:
            first_probes.append(action)
            return lookahead.Outcome(params.REWARD_INVALID, True, True, False, "x", outcome.next_obs)
        return outcome

    monkeypatch.setattr(lookahead, "probe_step", probe)
    lines: list[str] = []
    collect_demonstrations(model, config, teacher, env.get_wrapper_attr("set_num_objects"), log=lines.append)
    demos = model.replay_buffer.demonstrations
    kept = ~demos.expert[:demos.n_stored]
    # each decision's first probe, unless the teacher took it anyway (every probe invalid)
    expected = len(first_probes) - teacher.stats["unavoidable"] - teacher.stats["uncover_unavoidable"]
    assert kept.sum() == expected >= 1 and f"{expected} rejected actions kept" in lines[0]
    assert set(demos.actions[:demos.n_stored][kept, 0, 0]) <= set(first_probes)
    assert (demos.rewards[:demos.n_stored][kept, 0] == params.REWARD_INVALID).all()
    assert (demos.dones[:demos.n_stored][kept, 0] == 1.0).all()
    env.close()


def test_the_guard_supervises_the_training_env_only():
    from shelf_env.privileged.lookahead import FallGuard, LookaheadAccessibility
    from shelf_env.training.config import make_actor_env, make_training_env

    config = PRESETS["recipe"].replace(start_objects=2, guard="h-a-lookahead")
    env = make_training_env(config)
    assert isinstance(env, FallGuard) and isinstance(env.teacher, LookaheadAccessibility)
    assert env.teacher.env is env.env  # the teacher probes the env the guard wraps
    env.close()
    plain = make_env(config)  # greedy checks, evaluations and demonstrations: no supervisor
    assert not isinstance(plain, FallGuard)
    plain.close()
    assert not isinstance(make_training_env(config.replace(guard=None)), FallGuard)
    actor = make_actor_env(config)
    try:
        assert actor.env_is_wrapped(FallGuard) == [True]
    finally:
        actor.close()


@pytest.mark.parametrize("changes, match", [
    ({"guard": "h-a"}, "guard must be a teacher that probes the simulator .* got 'h-a'"),
    ({"demo_counterfactuals": True}, "needs a demonstrator that probes the simulator .* got demo_policy 'h-a'"),
    ({"demo_counterfactuals": "yes", "demo_policy": "h-d-lookahead"}, "must be true or false, got 'yes'"),
])
def test_counterfactuals_need_a_lookahead_teacher(changes, match):
    with pytest.raises(ValueError, match=match):
        PRESETS["p_s"].replace(**changes)


def test_heuristic_demonstrations_fill_the_kept_store_and_a_wrong_layout_is_refused():
    config = PRESETS["recipe"].replace(buffer_size=50, widths=(4, 8, 8), start_objects=1)
    env = make_env(config)
    model = make_model(config, env)
    stats = model.collect_demonstrations(demo_policy(config, env), 4)
    assert stats["steps"] == 4 and stats["successes"] >= 1
    demos = model.replay_buffer.demonstrations
    assert demos.n_stored >= 4
    masks = np.unpackbits(demos.next_masks[:4], axis=1, count=int(env.action_space.n)).astype(bool)
    assert masks.any(axis=1).all() and not masks.all(axis=1).any()  # real masks, final ones from info
    pick_only = gym.make("ShelfSort-v0", primitives=("pick",), pixel_size=0.01)
    with pytest.raises(ValueError, match="acts in Discrete\\(2400\\) but the model's action layout is Discrete"):
        model.collect_demonstrations(DistanceHeuristic(pick_only), 2)
    pick_only.close()
    env.close()


def test_episode_end_carries_the_final_mask(env):
    env.reset(seed=3, options={"num_objects": 1})
    policy = DistanceHeuristic(env)
    obs = env._obs
    for _ in range(40):
        mask_before = env.action_masks()
        action, _ = policy.predict(obs)
        obs, _, terminated, truncated, info = env.step(int(action))
        if terminated or truncated:
            assert np.array_equal(info["action_mask"], env.action_masks())
            break
        assert "action_mask" not in info and mask_before.dtype == bool
    else:
        pytest.fail("the episode did not end")


def test_evaluation_gives_masks_to_masked_policies_only(tmp_path):
    config = PRESETS["recipe"].replace(buffer_size=20, widths=(4, 8, 8))
    env = make_env(config)
    model = make_model(config, env)
    assert ev.takes_action_masks(model) and not ev.takes_action_masks(DistanceHeuristic(env))
    # a model trained without masks is evaluated as it was trained: the paper's all-pixel argmax
    assert not ev.takes_action_masks(make_model(config.replace(masked=False), env))
    model.save(tmp_path / "m.zip")
    assert ev.checkpoint_pixel_size(tmp_path / "m.zip") == pytest.approx(0.01)
    records = ev.evaluate_cell(str(tmp_path / "m.zip"), 1, ev.HELDOUT_SEED, 1, "train")
    assert records[0].actions >= 1 and records[0].noops <= records[0].actions
    seen = []
    original = PixelDoubleDQN.predict

    def spy(self, obs, *a, action_masks=None, **kw):
        seen.append(action_masks)
        return original(self, obs, *a, action_masks=action_masks, **kw)

    PixelDoubleDQN.predict = spy
    try:
        ev.run_episode(env, PixelDoubleDQN.load(tmp_path / "m.zip", env=env), ev.scene_seed(1, 1, 0), max_actions=3)
    finally:
        PixelDoubleDQN.predict = original
    assert seen and all(m is not None and m.dtype == bool and m.any() for m in seen)
    env.close()


def test_committed_recipe_checkpoint_sorts_held_out_scenes():
    """results/learning/recipe_n3.zip (docs/experiments/learning-recipe.md) loads on a fresh env at its cell size and,
    greedy with the env's masks, sorts the first held-out scenes at N = 3 within 3 N actions, none of them a no-op."""
    path = "results/learning/recipe_n3.zip"
    env = gym.make("ShelfSort-v0", num_objects=3, pixel_size=ev.checkpoint_pixel_size(path))
    model = PixelDoubleDQN.load(path, env=env, device="cpu")
    results = [ev.run_episode(env, model, ev.scene_seed(ev.HELDOUT_SEED, 3, run)) for run in range(3)]
    assert all(r["success"] and r["actions"] <= 9 and r["noops"] == 0 for r in results), results
    env.close()


def test_eval_action_limit_grows_with_objects_only_when_asked():
    from shelf_env.training.config import eval_action_limit

    assert eval_action_limit(PRESETS["recipe"]) == 20
    limit = eval_action_limit(PRESETS["recipe"].replace(eval_actions_per_object=3.0))
    assert [limit(n) for n in (1, 6, 7, 8)] == [20, 20, 21, 24]


def test_callbacks_include_q_map_images_only_when_asked():
    from sb3_pixeldqn import CurriculumCallback, QMapImageCallback
    from shelf_env.training.config import make_callbacks

    assert [type(c) for c in make_callbacks(PRESETS["recipe"], verbose=0)] == [CurriculumCallback]
    with_images = make_callbacks(PRESETS["recipe"].replace(tb_images_every=500), verbose=0)
    assert [type(c) for c in with_images] == [CurriculumCallback, QMapImageCallback] and with_images[1].every == 500
    with pytest.raises(ValueError, match="tb_images_every"):
        PRESETS["recipe"].replace(tb_images_every=-1)


def test_safe_picks_reaches_the_training_and_check_envs_and_the_zoo_file():
    from shelf_env.training.zoo import ENV_ID, zoo_hyperparams

    config = PRESETS["p_s"].replace(safe_picks=True)
    env = make_env(config)
    assert env.unwrapped.safe_picks and not make_env(PRESETS["p_s"]).unwrapped.safe_picks
    assert DistanceHeuristic(env).safe_picks  # demonstrations on it restrict their picks too
    assert zoo_hyperparams(config)[ENV_ID]["env_kwargs"]["safe_picks"] is True
    assert TrainConfig.from_dict(config.to_dict()).safe_picks
    with pytest.raises(ValueError, match="safe_picks"):
        config.replace(safe_picks="yes")
    env.close()


def test_closed_loop_reaches_the_training_and_check_envs_and_the_zoo_file():
    from shelf_env.training.zoo import ENV_ID, zoo_hyperparams

    open_env, default_env = make_env(PRESETS["p_s"]), make_env(PRESETS["p_s"].replace(closed_loop=True))
    assert open_env.unwrapped.drag_watch is None  # open loop by default, as in the paper
    config = PRESETS["p_s"].replace(closed_loop={"stacked": "put back"}, safe_picks=True)
    env = make_env(config)
    assert env.unwrapped.drag_watch is not None and env.unwrapped.drag_watch.stacked == "put back"
    assert default_env.unwrapped.drag_watch.stacked == "deeper"
    open_env.close()
    default_env.close()
    assert zoo_hyperparams(config)[ENV_ID]["env_kwargs"]["closed_loop"] == {"stacked": "put back"}
    assert TrainConfig.from_dict(config.to_dict()).closed_loop == {"stacked": "put back"}
    with pytest.raises(ValueError, match="closed_loop.*unknown closed_loop keys"):
        config.replace(closed_loop={"stack": "deeper"})
    with pytest.raises(ValueError, match="closed_loop must be true, false or a dict"):
        config.replace(closed_loop="on")
    env.close()


def test_min_num_objects_mixes_the_training_env_only_and_reaches_the_zoo_file():
    from shelf_env.training.config import make_curriculum, make_training_env
    from shelf_env.training.zoo import ENV_ID, zoo_hyperparams

    config = PRESETS["p_s"].replace(min_num_objects=3, start_objects=6, pixel_size=0.02)
    training = make_training_env(config)
    assert training.unwrapped.min_num_objects == 3 and training.unwrapped.num_objects == 6
    check = make_curriculum(config, verbose=0).eval_env  # greedy checks stay at the stage's N
    assert check.unwrapped.min_num_objects is None
    assert make_env(config).unwrapped.min_num_objects is None  # evaluations too
    assert zoo_hyperparams(config)[ENV_ID]["env_kwargs"]["min_num_objects"] == 3
    assert zoo_hyperparams(PRESETS["p_s"])[ENV_ID]["env_kwargs"]["min_num_objects"] is None
    assert TrainConfig.from_dict(config.to_dict()).min_num_objects == 3
    for bad in (0, 9, 2.5, True, "3"):
        with pytest.raises(ValueError, match="TrainConfig.min_num_objects must be None or an integer"):
            PRESETS["p_s"].replace(min_num_objects=bad)
    training.close()
    check.close()
