"""Cost of one PixelDoubleDQN gradient step, against a naive version and a hand-written loop.

    python benchmarks/train_step.py [--steps 10] [--widths 16 32 64] [--threads 2]

All three do the same maths on the same replay data (4 x 80 x 120 uint8 observations, the P+S
layout, batch 32): the double-DQN target, the single-pixel Huber loss, an Adam step and the Polyak
update. They differ only in how much they compute:

- ``train()``  — PixelDoubleDQN.train: online net on s for the executed map only, online net on s'
  for all maps (no grad, chunked), target net on s' for the argmax map only;
- ``naive``    — every map for every term (online on s with gradients for all three maps, the
  target net for all three maps), in one batch-32 pass per term, in the default memory layout;
- ``hand``     — a plain PyTorch loop written out below, with the same selective computation and
  layout as ``train()`` but no SB3 machinery (replay sampling from numpy arrays, no logger).

It prints seconds per step and the ratios naive / train() (target >= 2) and train() / hand
(target <= 1.1), all measured in this one run with the variants interleaved step by step so that
machine load affects them alike.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np
import torch as th
import torch.nn.functional as F
from stable_baselines3.common.logger import configure
from stable_baselines3.common.utils import polyak_update

from sb3_pixeldqn import PixelDoubleDQN
from sb3_pixeldqn.networks import rotate

SHAPE = (4, 80, 120)
N_ACTIONS = 3 * SHAPE[1] * SHAPE[2]
BATCH = 32


class ReplayOnly(gym.Env):
    """Spaces of ShelfSort-v0 (P+S, 5 mm cells); never stepped."""

    observation_space = gym.spaces.Box(0, 255, SHAPE, dtype=np.uint8)
    action_space = gym.spaces.Discrete(N_ACTIONS)

    def reset(self, *, seed=None, options=None):
        return np.zeros(SHAPE, dtype=np.uint8), {}

    def step(self, action):
        raise RuntimeError("not used")


def make_model(widths: tuple[int, int, int], seed: int = 0) -> PixelDoubleDQN:
    model = PixelDoubleDQN("FCNPolicy", ReplayOnly(), buffer_size=512, seed=seed, device="cpu",
                           policy_kwargs=dict(widths=widths))
    model.set_logger(configure(None, []))
    return model


def fill(model: PixelDoubleDQN, n: int, rng: np.random.Generator) -> None:
    for _ in range(n):
        obs = rng.integers(0, 256, (1, *SHAPE), dtype=np.uint8)
        next_obs = rng.integers(0, 256, (1, *SHAPE), dtype=np.uint8)
        done = rng.random(1) < 0.2
        model.replay_buffer.add(obs, next_obs, rng.integers(0, N_ACTIONS, 1), np.array([-1.0]), done, [{}])


def naive_step(model: PixelDoubleDQN) -> None:
    """Every map for every term, no chunking, default layout."""
    policy, gamma = model.policy, model.gamma
    batch = model.replay_buffer.sample(BATCH)
    obs, next_obs = batch.observations.float() / 255, batch.next_observations.float() / 255
    with th.no_grad():
        best = model.q_net.q_maps(next_obs).flatten(1).argmax(1)
        target_all = model.q_net_target.q_maps(next_obs).flatten(1)
        y = batch.rewards[:, 0] + (1 - batch.dones[:, 0]) * gamma * target_all.gather(1, best[:, None])[:, 0]
    q_all = model.q_net.q_maps(obs).flatten(1)
    loss = F.smooth_l1_loss(q_all.gather(1, batch.actions.long())[:, 0], y)
    policy.optimizer.zero_grad(set_to_none=True)
    loss.backward()
    policy.optimizer.step()
    polyak_update(model.q_net.parameters(), model.q_net_target.parameters(), model.tau)


class HandWritten:
    """The same selective maths as PixelDoubleDQN.train, written as a bare PyTorch loop."""

    def __init__(self, model: PixelDoubleDQN) -> None:
        buf = model.replay_buffer
        n = buf.pos
        self.obs = buf.observations[:n, 0]
        self.next_obs = buf.next_observations[:n, 0]
        self.actions = buf.actions[:n, 0, 0]
        self.rewards = buf.rewards[:n, 0]
        self.dones = buf.dones[:n, 0]
        self.online = model.q_net.fcns
        self.target = model.q_net_target.fcns
        self.optimizer = model.policy.optimizer
        self.params = list(model.q_net.parameters())
        self.target_params = list(model.q_net_target.parameters())
        self.gamma, self.tau = model.gamma, model.tau
        self.maps = model.policy.maps
        self.chunk = model.policy.no_grad_chunk

    def images(self, x: np.ndarray) -> th.Tensor:
        return (th.from_numpy(x).float() / 255).contiguous(memory_format=th.channels_last)

    def values_at(self, fcns, images: th.Tensor, actions: th.Tensor) -> th.Tensor:
        hw = images.shape[-2] * images.shape[-1]
        maps, pixels = actions // hw, actions % hw
        out = images.new_zeros(len(actions))
        for name in fcns:
            groups = [(m, deg) for m, (n, deg) in enumerate(self.maps) if n == name and (maps == m).any()]
            if not groups:
                continue
            rows = [th.nonzero(maps == m)[:, 0] for m, _ in groups]
            views = th.cat([rotate(images[r], deg) for r, (_, deg) in zip(rows, groups)])
            q = fcns[name](views.contiguous(memory_format=th.channels_last))
            for r, part, (_, deg) in zip(rows, q.split([len(r) for r in rows]), groups):
                v = rotate(part, -deg % 360).flatten(1).gather(1, pixels[r, None])[:, 0]
                out = out.index_put((r,), v)
        return out

    def step(self, rng: np.random.Generator) -> None:
        idx = rng.integers(0, len(self.obs), BATCH)
        obs, next_obs = self.images(self.obs[idx]), self.images(self.next_obs[idx])
        actions = th.from_numpy(self.actions[idx]).long()
        rewards, dones = th.from_numpy(self.rewards[idx]), th.from_numpy(self.dones[idx])
        with th.no_grad():
            chunks = []
            for x in next_obs.split(self.chunk):
                pick = self.online["pick"](x)
                push = self.online["push"](th.cat([x, rotate(x, 180)]).contiguous(memory_format=th.channels_last))
                chunks.append(th.stack([pick, push[: len(x)], rotate(push[len(x):], 180)], 1))
            best = th.cat(chunks).flatten(1).argmax(1)
            y = rewards + (1 - dones) * self.gamma * self.values_at(self.target, next_obs, best)
        loss = F.smooth_l1_loss(self.values_at(self.online, obs, actions), y)
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        self.optimizer.step()
        with th.no_grad():
            for p, t in zip(self.params, self.target_params):
                t.mul_(1 - self.tau).add_(p, alpha=self.tau)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=10)
    parser.add_argument("--widths", type=int, nargs=3, default=[16, 32, 64])
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    th.set_num_threads(args.threads)
    rng = np.random.default_rng(0)
    model = make_model(tuple(args.widths))
    fill(model, 256, rng)
    hand = HandWritten(model)
    variants = {"train()": lambda: model.train(1, BATCH), "naive": lambda: naive_step(model),
                "hand": lambda: hand.step(rng)}
    for run in variants.values():  # warm-up
        run()
    seconds = {name: [] for name in variants}
    for _ in range(args.steps):
        for name, run in variants.items():
            t0 = time.perf_counter()
            run()
            seconds[name].append(time.perf_counter() - t0)
    print(f"batch {BATCH}, obs {SHAPE}, P+S maps, widths {tuple(args.widths)}, {args.threads} threads, "
          f"{args.steps} interleaved steps (median s/step)")
    med = {name: float(np.median(s)) for name, s in seconds.items()}
    for name, s in med.items():
        print(f"  {name:8s} {s:.3f}")
    print(f"naive / train()  = {med['naive'] / med['train()']:.2f}   (target >= 2)")
    print(f"train() / hand   = {med['train()'] / med['hand']:.3f}  (target <= 1.1)")


if __name__ == "__main__":
    main()
