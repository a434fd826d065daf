"""Distillation (sb3_pixeldqn.distill): a loss on every labelled pixel lowers on a small crafted dataset and
teaches the Q-maps which labelled actions end the episode invalid; bad data is refused by name."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch as th
from pixel_envs import FindTheSquareEnv

from sb3_pixeldqn import PixelDoubleDQN
from sb3_pixeldqn.distill import LabelledStates, LossOptions, distill, distillation_loss, evaluate, teacher_sets


def crafted(n_states: int = 24, seed: int = 0) -> tuple[PixelDoubleDQN, LabelledStates]:
    """FindTheSquare scenes: acting on the square is the teacher's (valid) choice; cells six columns beside the
    square 'drop an object' (invalid, value -10); far cells are valid with unknown value."""
    env = FindTheSquareEnv(shape=(4, 12, 20), n_maps=1)
    model = PixelDoubleDQN("FCNPolicy", env, policy_kwargs=dict(maps=[("pick", 0)], widths=(4, 8, 8)), seed=0,
                           learning_rate=3e-3)
    rng = np.random.default_rng(seed)
    obs, label_state, label_action, invalid, value, teacher = [], [], [], [], [], []
    for s in range(n_states):
        o, _ = env.reset(seed=int(rng.integers(1 << 30)))
        r, c = env._centre
        obs.append(o)
        teacher.append(r * 20 + c)
        labels = [(r * 20 + c, False, np.nan)]  # the teacher's: on the square
        for dc in (-6, 6):  # six columns left and right of the square: invalid
            if 0 <= c + dc < 20:
                labels.append((r * 20 + c + dc, True, -10.0))
        far = int(rng.integers(240))
        if abs(far // 20 - r) > 3:
            labels.append((far, False, np.nan))
        for a, bad, v in labels:
            label_state.append(s)
            label_action.append(a)
            invalid.append(bad)
            value.append(v)
    data = LabelledStates(np.stack(obs), np.array(label_state), np.array(label_action), np.array(invalid),
                          np.array(value, np.float32), np.array(teacher))
    return model, data


def test_distillation_lowers_the_loss_and_ranks_invalid_actions_below_valid_ones() -> None:
    th.manual_seed(0)
    model, data = crafted()
    train, held_out = data.subset(np.arange(16)), data.subset(np.arange(16, 24))
    before, before_held = evaluate(model.policy, train), evaluate(model.policy, held_out)
    history = distill(model, train, epochs=120, batch_states=8)
    after, after_held = evaluate(model.policy, train), evaluate(model.policy, held_out)
    assert history[-1]["loss"] < history[0]["loss"]
    assert after["loss"] < 0.5 * before["loss"]
    assert after["value"] < before["value"] and after["ranking"] < before["ranking"]
    # the best labelled action of (nearly) every training state is now a valid one
    assert after["invalid_choice"] <= 0.125 < before["invalid_choice"]
    assert after_held["loss"] < before_held["loss"]  # and it generalises to scenes it never saw
    for p, q in zip(model.q_net.parameters(), model.q_net_target.parameters()):  # the target follows
        assert th.equal(p, q)


def test_the_loss_terms_are_what_the_docstring_says() -> None:
    q = th.tensor([[0.0, -2.0, 1.0, 5.0]], requires_grad=True)  # one state, four actions
    state = th.tensor([0, 0, 0])
    action = th.tensor([0, 1, 2])
    invalid = th.tensor([False, True, False])
    value = th.tensor([float("nan"), -10.0, float("nan")])
    loss, parts = distillation_loss(q, state, action, invalid, value, th.tensor([0]), LossOptions(margin=1.0))
    assert parts["value"] == pytest.approx(7.5)  # Huber(-2, -10) with delta 1
    # valid 0 vs invalid -2: relu(-2 + 1 - 0) = 0; valid 1 vs invalid -2: 0
    assert parts["ranking"] == 0.0
    # teacher 0 over the labelled actions 0, 1, 2: max(0, -2 + 1, 1 + 1) - 0 = 2 (action 3 is not labelled)
    assert parts["teacher"] == pytest.approx(2.0)
    loss.backward()
    assert q.grad is not None and q.grad[0, 3] == 0.0  # unlabelled pixels get no gradient


def test_bad_labelled_states_are_refused_by_name() -> None:
    model, data = crafted(4)
    with pytest.raises(ValueError, match="labelled action outside"):
        distill(model, LabelledStates(data.obs, data.label_state, data.label_action + 10_000, data.label_invalid,
                                      data.label_value, data.teacher_action))
    with pytest.raises(ValueError, match="observations uint8 \\(4, 6, 20\\)"):
        distill(model, LabelledStates(data.obs[:, :, :6], data.label_state, data.label_action, data.label_invalid,
                                      data.label_value, data.teacher_action))
    with pytest.raises(ValueError, match="outside the states"):
        distill(model, LabelledStates(data.obs[:1], data.label_state, data.label_action, data.label_invalid,
                                      data.label_value, data.teacher_action[:1]))


class FlipWidth:
    """A width flip drawn with probability ½ (the `Transform` interface), for a 12 x 20 single map."""

    def __call__(self, obs, action, next_obs, next_mask, rng):
        if rng.random() < 0.5:
            return obs, action, next_obs, next_mask
        r, c = divmod(int(action), 20)
        flipped_mask = np.asarray(next_mask).reshape(12, 20)[:, ::-1].reshape(-1)
        return obs[..., ::-1].copy(), r * 20 + 19 - c, next_obs[..., ::-1].copy(), flipped_mask


def test_augmentation_moves_a_states_labels_and_teacher_with_its_observation() -> None:
    from sb3_pixeldqn.distill import augmented

    _, data = crafted(n_states=40)
    left_half = np.zeros((40, 12, 20), bool)
    left_half[:, :, :10] = True
    data = LabelledStates(data.obs, data.label_state, data.label_action, data.label_invalid, data.label_value,
                          data.teacher_action, np.packbits(left_half.reshape(40, -1), axis=1))
    out = augmented(data, [FlipWidth()], 240, np.random.default_rng(0))
    masks = out.unpacked_masks(240).reshape(40, 12, 20)
    flipped = [s for s in range(40) if not np.array_equal(out.obs[s], data.obs[s])]
    assert 5 < len(flipped) < 35  # about half the states were drawn flipped
    for s in range(40):
        rows = np.flatnonzero(data.label_state == s)
        r, c = np.divmod(data.label_action[rows], 20)
        tr, tc = divmod(int(data.teacher_action[s]), 20)
        if s in flipped:  # every label of the state and its teacher action flipped with it
            assert np.array_equal(out.obs[s], data.obs[s][..., ::-1])
            assert np.array_equal(out.label_action[rows], r * 20 + 19 - c)
            assert out.teacher_action[s] == tr * 20 + 19 - tc
            assert masks[s, :, 10:].all() and not masks[s, :, :10].any()  # the mask moved with it
        else:
            assert np.array_equal(masks[s], left_half[s])
            assert np.array_equal(out.label_action[rows], data.label_action[rows])
            assert out.teacher_action[s] == data.teacher_action[s]
    assert np.array_equal(out.label_invalid, data.label_invalid) and np.array_equal(out.label_state, data.label_state)
    assert augmented(data, [], 240, np.random.default_rng(0)) is data
    # the square's teacher action still lands on the (flipped) square: training on it stays consistent
    model, _ = crafted(n_states=1)
    th.manual_seed(0)
    history = distill(model, data.subset(np.arange(16)), epochs=30, batch_states=8, augment=[FlipWidth()])
    assert history[-1]["loss"] < history[0]["loss"]


def test_with_masks_the_teacher_margin_spans_every_allowed_action() -> None:
    # one state, four actions; labels on 0 (the teacher's) and 1; action 2 unlabelled but allowed and valued high,
    # action 3 higher still but not allowed
    q = th.tensor([[1.0, 0.0, 3.0, 9.0]], requires_grad=True)
    args = (th.tensor([0, 0]), th.tensor([0, 1]), th.tensor([False, False]), th.tensor([np.nan, np.nan]),
            th.tensor([0]))
    _, over_labels = distillation_loss(q, *args)
    masks = th.tensor([[True, True, True, False]])
    loss, over_masks = distillation_loss(q, *args, masks=masks)
    assert over_labels["teacher"] == pytest.approx(0.0)  # 1 >= 0 + margin among the labelled actions
    assert over_masks["teacher"] == pytest.approx(3.0)  # (3 + 1) - 1: the allowed unlabelled action counts
    loss.backward()
    assert q.grad[0, 2] > 0 and q.grad[0, 0] < 0 and q.grad[0, 3] == 0  # pushed down, up, untouched


def test_the_progress_term_ranks_valid_actions_by_what_they_achieved() -> None:
    # one state: 0 sorted an object (+1), 1 changed nothing useful (0), 2 dropped one (invalid, not ranked here)
    q = th.tensor([[0.0, 0.5, 3.0]], requires_grad=True)
    args = (th.tensor([0, 0, 0]), th.tensor([0, 1, 2]), th.tensor([False, False, True]), th.full((3,), np.nan),
            th.tensor([-1]))
    _, without = distillation_loss(q, *args)
    loss, parts = distillation_loss(q, *args, progress=th.tensor([1.0, 0.0, 5.0]))
    assert without["progress"] == 0.0
    assert parts["progress"] == pytest.approx(1.5)  # relu(0.5 + 1 - 0); the invalid action's score is ignored
    loss.backward()
    assert q.grad[0, 0] < 0 < q.grad[0, 1]  # the sorting step pushed up, the useless one down


def test_the_anchor_keeps_unlabelled_actions_at_the_starting_values() -> None:
    import copy

    drift = {}
    for anchor in (0.0, 10.0):
        th.manual_seed(0)
        model, data = crafted()
        start = copy.deepcopy(model.q_net).requires_grad_(False)
        obs = th.as_tensor(data.obs)
        with th.no_grad():
            q0 = start.q_maps(model.policy.images(obs)).flatten(1)
        history = distill(model, data, epochs=20, batch_states=8, anchor=anchor, anchor_net=start if anchor else None)
        with th.no_grad():
            q1 = model.q_net.q_maps(model.policy.images(obs)).flatten(1)
        free = th.ones_like(q0, dtype=th.bool)
        free[th.as_tensor(data.label_state), th.as_tensor(data.label_action)] = False
        drift[anchor] = float((q1 - q0)[free].abs().mean())
        assert history[-1]["loss"] < history[0]["loss"]
        assert ("anchor" in history[-1]) and (history[-1]["anchor"] > 0) == (anchor > 0)
    assert drift[10.0] < 0.5 * drift[0.0]
    model, data = crafted(4)
    with pytest.raises(ValueError, match="anchor_net"):
        distill(model, data, anchor=1.0)


def test_near_cells_is_a_square_on_the_teachers_own_map() -> None:
    from sb3_pixeldqn.distill import near_cells

    grid = (2, 4, 5)  # two maps of 4 x 5
    near = near_cells(th.tensor([1 * 5 + 1, 20 + 3 * 5 + 4]), grid, 1).reshape(2, *grid).numpy()
    expected = np.zeros((2, *grid), dtype=bool)
    expected[0, 0, 0:3, 0:3] = True  # map 0, around row 1 col 1
    expected[1, 1, 2:4, 3:5] = True  # map 1, around row 3 col 4 (clipped at the corner)
    assert (near == expected).all()


def test_a_teacher_radius_makes_the_teachers_neighbourhood_compete_with_the_rest_of_the_map() -> None:
    # one map of 3 x 5: the teacher's cell (1, 1) = 6, its neighbour (1, 2) = 7 valued higher, a far cell (1, 4) = 9
    q = th.zeros((1, 15))
    q[0, 6], q[0, 7], q[0, 9] = 1.0, 2.5, 2.0
    q.requires_grad_(True)
    args = (th.tensor([0]), th.tensor([6]), th.tensor([False]), th.tensor([np.nan]), th.tensor([6]))
    masks = th.zeros((1, 15), dtype=th.bool)
    masks[0, [6, 7, 9]] = True
    _, pixel = distillation_loss(q, *args, masks=masks)
    loss, square = distillation_loss(q, *args, LossOptions(teacher_radius=1), masks=masks, grid=(1, 3, 5))
    assert pixel["teacher"] == pytest.approx(2.5)  # (2.5 + 1) - 1: the neighbour is the competitor
    assert square["teacher"] == pytest.approx(0.5)  # (2 + 1) - 2.5: the far cell against the square's best
    loss.backward()
    assert q.grad[0, 7] < 0 < q.grad[0, 9] and q.grad[0, 6] == 0  # the square's best up, the far cell down
    _, outside_the_mask = distillation_loss(q, *args, LossOptions(teacher_radius=1),
                                            masks=masks & (th.arange(15) != 9), grid=(1, 3, 5))
    assert outside_the_mask["teacher"] == 0.0  # nothing allowed outside the square: nothing to beat
    with pytest.raises(ValueError, match="teacher_radius > 0 needs the grid"):
        distillation_loss(q, *args, LossOptions(teacher_radius=1))  # no grid to place the square on


def test_teacher_near_counts_greedy_actions_within_the_radius() -> None:
    model, data = crafted(n_states=8)
    masked = LabelledStates(data.obs, data.label_state, data.label_action, data.label_invalid, data.label_value,
                            data.teacher_action, np.packbits(np.ones((8, 240), dtype=bool), axis=1))
    with th.no_grad():
        for p in model.q_net.parameters():
            p.zero_()  # a flat map: the masked argmax is action 0, row 0 col 0, for every state
    report = evaluate(model.policy, masked, LossOptions(teacher_radius=30))
    assert report["teacher_near"] == 1.0  # a square this large holds the whole map
    far = evaluate(model.policy, masked, LossOptions(teacher_radius=1))
    rows, cols = masked.teacher_action // 20, masked.teacher_action % 20
    assert far["teacher_near"] == pytest.approx(float(np.mean((rows <= 1) & (cols <= 1))))
    assert "teacher_near" not in evaluate(model.policy, masked)


def test_teacher_set_choice_counts_greedy_actions_as_good_as_the_teachers() -> None:
    model, data = crafted(n_states=8)
    with th.no_grad():
        for p in model.q_net.parameters():
            p.zero_()  # a flat map: the masked argmax is action 0 for every state
    assert (data.teacher_action != 0).all()
    n = len(data.label_action)
    # every old label sorts one object (the teacher's too); a new label at action 0 in each state, valid, that sorts
    # one in states 0-3 (as good as the teacher's) and none in states 4-7
    labelled = LabelledStates(data.obs, np.concatenate([data.label_state, np.arange(8)]),
                              np.concatenate([data.label_action, np.zeros(8, int)]),
                              np.concatenate([data.label_invalid, np.zeros(8, bool)]),
                              np.concatenate([data.label_value, np.full(8, np.nan, np.float32)]), data.teacher_action,
                              np.packbits(np.ones((8, 240), dtype=bool), axis=1),
                              np.concatenate([np.ones(n, np.float32), (np.arange(8) < 4).astype(np.float32)]))
    assert evaluate(model.policy, labelled)["teacher_set_choice"] == 0.5
    assert evaluate(model.policy, labelled, LossOptions(teacher_radius=30))["teacher_set_choice"] == 1.0
    assert "teacher_set_choice" not in evaluate(model.policy, dataclasses.replace(labelled, label_progress=None))


def test_the_weights_choose_what_training_fits() -> None:
    reports = {}
    for name, weights in (("none", (0.0, 0.0, 0.0, 0.0)), ("teacher", (0.0, 0.0, 1.0, 0.0))):
        model, data = crafted(n_states=16)
        th.manual_seed(0)
        distill(model, data, epochs=15, batch_states=8, options=LossOptions(weights=weights))
        reports[name] = evaluate(model.policy, data)
    start = evaluate(crafted(n_states=16)[0].policy, crafted(n_states=16)[1])
    assert reports["teacher"]["teacher"] < 0.5 * start["teacher"]  # the teacher term alone fits the teacher
    assert reports["none"]["teacher"] > 0.8 * start["teacher"]  # with every weight 0 only weight decay moves it


def test_a_progress_radius_pushes_down_the_best_allowed_cell_near_a_useless_action() -> None:
    # one map of 3 x 5; a useful action at (0, 0) = 0; a useless one labelled at (1, 3) = 8, its unlabelled
    # neighbour (1, 4) = 9 valued higher (the next greedy choice), a disallowed neighbour (2, 3) = 13 higher still
    q = th.zeros((1, 15))
    q[0, 0], q[0, 8], q[0, 9], q[0, 13] = 2.0, 0.5, 1.8, 5.0
    q.requires_grad_(True)
    args = (th.tensor([0, 0]), th.tensor([0, 8]), th.tensor([False, False]), th.full((2,), np.nan),
            th.tensor([-1]))
    progress = th.tensor([1.0, 0.0])
    masks = th.ones((1, 15), dtype=th.bool)
    masks[0, 13] = False
    _, pixel = distillation_loss(q, *args, masks=masks, progress=progress)
    loss, square = distillation_loss(q, *args, LossOptions(progress_radius=1), masks=masks, progress=progress,
                                     grid=(1, 3, 5))
    assert pixel["progress"] == pytest.approx(0.0)  # 0.5 + 1 <= 2: the labelled pixel alone is low enough
    assert square["progress"] == pytest.approx(0.8)  # 1.8 + 1 - 2: its allowed neighbour is not
    loss.backward()
    assert q.grad[0, 9] > 0 > q.grad[0, 0] and q.grad[0, 8] == 0 and q.grad[0, 13] == 0
    with pytest.raises(ValueError, match="progress_radius > 0 needs the grid"):
        distillation_loss(q, *args, LossOptions(progress_radius=1), progress=progress)  # no grid


def test_a_teacher_temperature_makes_the_teacher_term_a_cross_entropy_over_the_allowed_actions() -> None:
    q = th.tensor([[1.0, 0.0, 3.0, 9.0]], requires_grad=True)
    args = (th.tensor([0, 0]), th.tensor([0, 1]), th.tensor([False, False]), th.tensor([np.nan, np.nan]),
            th.tensor([0]))
    masks = th.tensor([[True, True, True, False]])
    loss, parts = distillation_loss(q, *args, LossOptions(weights=(0.0, 0.0, 1.0, 0.0), teacher_temperature=1.0),
                                    masks=masks)
    assert parts["teacher"] == pytest.approx(float(np.log(np.e + 1 + np.e ** 3) - 1.0), rel=1e-5)
    loss.backward()
    softmax = np.exp([1.0, 0.0, 3.0]) / np.exp([1.0, 0.0, 3.0]).sum()
    assert q.grad[0, :3].numpy() == pytest.approx(softmax - np.array([1.0, 0.0, 0.0]), rel=1e-5)  # every allowed one
    assert q.grad[0, 3] == 0  # not allowed: untouched
    with pytest.raises(ValueError, match="teacher_temperature must be a finite number >= 0"):
        LossOptions(teacher_temperature=-1.0)


def test_a_teacher_set_holds_the_labelled_actions_as_good_as_the_teachers() -> None:
    # state 0 (teacher 0, progress 1): action 2 valid and progress 1 (in), 3 valid progress 0 (out), 4 invalid
    # progress 1 (out), 5 progress 2 (in); state 1 (teacher 6, progress 0: no set): 7 valid progress 1 (out);
    # state 2 (teacher -1) is not a row
    label_state = th.tensor([0, 0, 0, 0, 0, 1, 1, 2])
    label_action = th.tensor([0, 2, 3, 4, 5, 6, 7, 8])
    invalid = th.tensor([False, False, False, True, False, False, False, False])
    progress = th.tensor([1.0, 1.0, 0.0, 1.0, 2.0, 0.0, 1.0, 1.0])
    teacher = th.tensor([0, 6, -1])
    sets = teacher_sets(th.tensor([0, 1]), label_state, label_action, invalid, progress, teacher, 15)
    assert sets[0].nonzero().flatten().tolist() == [0, 2, 5] and not sets[1].any()
    # with a radius each member brings its square: one map of 3 x 5, action 2 = (0, 2), 5 = (1, 0)
    square = teacher_sets(th.tensor([0]), label_state, label_action, invalid, progress, teacher, 15, (1, 3, 5), 1)
    assert square[0].nonzero().flatten().tolist() == [0, 1, 2, 3, 5, 6, 7, 8, 10, 11]
    # a teacher whose own label fell, or that is unlabelled, gets no set
    assert not teacher_sets(th.tensor([0]), label_state, label_action, th.tensor([True] + [False] * 7), progress,
                            teacher, 15).any()
    assert not teacher_sets(th.tensor([0]), label_state, label_action, invalid, progress, th.tensor([1, 6, -1]),
                            15).any()


def test_a_teacher_set_pulls_up_the_ties_the_teacher_broke_instead_of_pushing_them_down() -> None:
    # the teacher picks 0 (progress 1); action 2 sorts as much (a tie), action 1 nothing; 3 is not allowed
    args = (th.tensor([0, 0, 0]), th.tensor([0, 1, 2]), th.tensor([False, False, False]), th.full((3,), np.nan),
            th.tensor([0]))
    progress = th.tensor([1.0, 0.0, 1.0])
    masks = th.tensor([[True, True, True, False]])
    grads = {}
    for teacher_set in (False, True):
        q = th.tensor([[1.0, 0.0, 3.0, 9.0]], requires_grad=True)
        options = LossOptions(weights=(0.0, 0.0, 1.0, 0.0), teacher_temperature=1.0, teacher_set=teacher_set)
        loss, parts = distillation_loss(q, *args, options, masks=masks, progress=progress)
        loss.backward()
        grads[teacher_set] = q.grad[0].numpy().copy()
        if teacher_set:  # the set {0, 2} against every allowed action
            assert parts["teacher"] == pytest.approx(float(np.log(np.e + 1 + np.e ** 3) - np.log(np.e + np.e ** 3)),
                                                     rel=1e-5)
    assert grads[False][2] > 0 > grads[True][2]  # the tie: pushed down alone, pulled up in the set
    assert grads[True][1] > 0 and grads[True][3] == 0  # the useless action still down; the disallowed untouched
    with pytest.raises(ValueError, match="teacher_set needs the labels' progress scores"):
        distillation_loss(q, *args, LossOptions(teacher_temperature=1.0, teacher_set=True), masks=masks)


def test_loss_options_refuse_bad_values_by_name() -> None:
    assert LossOptions(weights=[1, 2, 3, 4]).weights == (1.0, 2.0, 3.0, 4.0)  # type: ignore[arg-type]
    for kwargs, message in (({"margin": float("nan")}, "margin must be a finite number >= 0"),
                            ({"teacher_radius": -1}, "teacher_radius must be a finite number >= 0, got -1"),
                            ({"progress_radius": 1.5}, "progress_radius must be a whole number of cells"),
                            ({"weights": (1.0, 1.0, 1.0)}, "weights must be 4 numbers"),
                            ({"weights": (1.0, -1.0, 1.0, 1.0)}, "the ranking weight must be a finite number >= 0"),
                            ({"teacher_set": 1}, "teacher_set must be True or False, got 1")):
        with pytest.raises(ValueError, match=message):
            LossOptions(**kwargs)  # type: ignore[arg-type]
