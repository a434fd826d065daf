"""Proof of learning on a tiny synthetic image env whose best pixel is known (no physics)."""

import pytest
from pixel_envs import FindTheSquareEnv

from sb3_pixeldqn import PixelDoubleDQN


def greedy_hit_rate(model: PixelDoubleDQN, env: FindTheSquareEnv, episodes: int = 50) -> float:
    hits = 0
    for seed in range(10_000, 10_000 + episodes):
        obs, _ = env.reset(seed=seed)
        action, _ = model.predict(obs, deterministic=True)
        hits += env.on_square(int(action))
    return hits / episodes


def train(n_maps: int, good_map: int, steps: int, seed: int = 0, directional: bool = False,
          masked: bool | None = None) -> tuple[float, float]:
    maps = (("pick", 0), ("push", 0), ("push", 180))[:n_maps]

    def make() -> FindTheSquareEnv:
        return FindTheSquareEnv(n_maps=n_maps, good_map=good_map, directional=directional)

    env = make()
    model = PixelDoubleDQN("FCNPolicy", env, policy_kwargs=dict(maps=maps), learning_rate=1e-3,
                           learning_starts=50, exploration_timesteps=steps // 2, masked=masked,
                           masked_exploration=True, buffer_size=2_000, seed=seed)
    untrained = greedy_hit_rate(model, make())
    model.learn(steps)
    return untrained, greedy_hit_rate(model, make())


def test_learns_the_square_within_a_few_hundred_steps():
    # a 3x3 square in a 12x20 image: a random pixel hits it 4 % of the time. Exploration is masked
    # to the square but the greedy argmax is not (masked=False), so it must learn where the square is.
    untrained, trained = train(n_maps=1, good_map=0, steps=500, masked=False)
    assert untrained < 0.2
    assert trained >= 0.8


@pytest.mark.slow
def test_learns_which_rotated_map_to_use():
    # P+S layout; a marker left of the square makes push@0 pay, right of it push@180; pick never
    # pays. The argmax must choose the right map (one shared push FCN seen at 0° and 180°) and pixel.
    untrained, trained = train(n_maps=3, good_map=1, steps=1500, directional=True)
    assert untrained < 0.2
    assert trained >= 0.8
