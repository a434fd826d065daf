"""Issue 9, lever 9: does acting overlapped with learning pay on two cores? Measured in one run.

    python benchmarks/overlap.py [--ns 3 8] [--seconds 120] [--steps 100]

For each N, two ways of running the recipe's training loop (`shelf_env.training.PRESETS["recipe"]`)
on the same two cores, one after the other:

- **sequential** (what `shelf-train` does): one process, torch on 2 threads, act then learn, one
  gradient step per env step (timed as `benchmarks/train_loop.py` does, after the buffer's
  ``learning_starts``).
- **overlapped**: an actor process (env + a CPU copy of the Q-network, torch on 1 thread) plays
  ε-greedy masked actions (the recipe's ε schedule) and sends each transition (observations,
  action, reward, done, info with its relabelled twin, the next state's mask) to a learner
  process (torch on 1 thread) that stores it in the same replay buffer and trains. The learner
  sends its weights back every ``--sync-every`` updates. The replay ratio is the recipe's: the
  learner does exactly one gradient step per transition received, and the actor waits when it
  is more than ``--max-lag`` transitions ahead, so both ways do the same work per env step.

Prints env steps per hour of each and the ratio, plus where each overlapped process waited. The
issue adopts an actor process only if the ratio is at least 1.3 (docs/learning.md, lever 9).
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import pathlib
import queue as queue_lib
import sys
import time
from typing import Any

import numpy as np
import torch as th

import shelf_env  # noqa: F401  (registers ShelfSort-v0)
from sb3_pixeldqn.pixel_dqn import draw_masked_action
from shelf_env.training import PRESETS, make_env, make_model

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from train_loop import prepared_model, timed_steps  # noqa: E402  (shared with the sequential measurement)


def actor(n: int, seed: int, transitions: Any, weights: Any, learned: Any, stop: Any, max_lag: int) -> None:
    """Play the env and send transitions until ``stop`` is set; wait while ``max_lag`` ahead of the
    learner's updates (``learned``); load new weights whenever the learner sent some."""
    th.set_num_threads(1)
    config = PRESETS["recipe"].replace(start_objects=n, max_objects=n)
    env = make_env(config)
    model = make_model(config, env, seed=seed)
    n_maps, rng = model.policy.n_maps, np.random.default_rng(seed)
    obs, _ = env.reset(seed=seed)
    sent, waited = 0, 0.0
    while not stop.is_set():
        t0 = time.perf_counter()
        while sent - config.learning_starts > learned.value + max_lag and not stop.is_set():
            time.sleep(0.002)
        waited += time.perf_counter() - t0
        try:
            model.policy.load_state_dict({k: th.from_numpy(v) for k, v in weights.get_nowait().items()})
        except queue_lib.Empty:
            pass
        mask = env.unwrapped.action_masks()
        if sent < config.learning_starts or rng.random() < model._epsilon(sent):  # the recipe's schedule
            action = draw_masked_action(mask, n_maps, rng)
        else:
            action = int(model.policy.predict(obs[None], deterministic=True, action_masks=mask[None])[0][0])
        next_obs, reward, terminated, truncated, info = env.step(action)
        next_mask = env.unwrapped.action_masks()
        info = {**info, "TimeLimit.truncated": bool(truncated and not terminated)}
        transitions.put((obs, next_obs, action, float(reward), bool(terminated or truncated), info, next_mask))
        sent += 1
        obs = env.reset()[0] if terminated or truncated else next_obs
    transitions.put(("waited", waited))
    env.close()


def overlapped(n: int, seconds: float, seed: int, sync_every: int, max_lag: int) -> dict[str, float]:
    """Env steps and gradient steps per hour of the actor/learner pair over ``seconds`` of learning."""
    th.set_num_threads(1)
    config, env, model, _ = prepared_model("recipe", n, seed)
    model._current_progress_remaining = 1.0  # what learn() sets before train(): the full learning rate
    ctx = mp.get_context("spawn")
    transitions, weights, stop = ctx.Queue(maxsize=4 * max_lag), ctx.Queue(maxsize=1), ctx.Event()
    learned = ctx.Value("i", 0)
    proc = ctx.Process(target=actor, args=(n, seed + 1, transitions, weights, learned, stop, max_lag), daemon=True)
    proc.start()
    buffer = model.replay_buffer
    received, updates, learner_wait = 0, 0, 0.0
    t_start = None
    try:
        while t_start is None or time.perf_counter() - t_start < seconds:
            t0 = time.perf_counter()
            item = transitions.get(timeout=300)
            if t_start is not None:
                learner_wait += time.perf_counter() - t0
            obs, next_obs, action, reward, done, info, next_mask = item
            buffer.add(obs[None], next_obs[None], np.array([action]), np.array([reward]), np.array([done]), [info],
                       next_action_masks=next_mask[None])
            received += 1
            if received == config.learning_starts:  # the buffer is filled: learning (and timing) starts
                t_start = time.perf_counter()
            if received > config.learning_starts:
                model.train(gradient_steps=config.gradient_steps, batch_size=config.batch_size)
                updates += config.gradient_steps
                learned.value = updates
                if updates % sync_every == 0:
                    try:
                        weights.put_nowait({k: v.detach().cpu().numpy().copy()
                                            for k, v in model.policy.state_dict().items()})
                    except queue_lib.Full:
                        pass
        elapsed = time.perf_counter() - t_start
        steps = received - config.learning_starts
    finally:
        stop.set()
    actor_wait = 0.0
    deadline = time.perf_counter() + 60
    while time.perf_counter() < deadline:  # drain until the actor reports how long it waited
        try:
            item = transitions.get(timeout=5)
        except queue_lib.Empty:
            continue
        if isinstance(item[0], str) and item[0] == "waited":
            actor_wait = float(item[1])
            break
    weights.cancel_join_thread()  # weights the actor never took must not hold up our exit
    proc.join(timeout=30)
    if proc.is_alive():
        proc.terminate()
    env.close()
    return {"steps_per_hour": 3600 * steps / elapsed, "updates_per_hour": 3600 * updates / elapsed,
            "learner_wait": learner_wait / elapsed, "actor_wait_s": actor_wait, "seconds": elapsed}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--ns", type=int, nargs="+", default=[3, 8])
    p.add_argument("--seconds", type=float, default=120.0, help="overlapped: learning time measured per N")
    p.add_argument("--steps", type=int, default=100, help="sequential: env steps measured per N")
    p.add_argument("--sync-every", type=int, default=20, help="learner updates between weight copies")
    p.add_argument("--max-lag", type=int, default=8, help="transitions the actor may run ahead")
    p.add_argument("--threads", type=int, default=2, help="sequential: torch threads (the two cores)")
    args = p.parse_args()
    for n in args.ns:
        th.set_num_threads(args.threads)
        seconds, _ = timed_steps("recipe", n, args.steps, seed=0)
        seq = 3600 / seconds
        print(f"N = {n:2d} sequential ({args.threads} threads): {seconds:.3f} s/env step = "
              f"{seq:,.0f} env steps/hour", flush=True)
        r = overlapped(n, args.seconds, seed=0, sync_every=args.sync_every, max_lag=args.max_lag)
        print(f"N = {n:2d} overlapped (actor 1 thread + learner 1 thread): {r['steps_per_hour']:,.0f} env steps/hour, "
              f"{r['updates_per_hour']:,.0f} gradient steps/hour over {r['seconds']:.0f} s; learner waited "
              f"{100 * r['learner_wait']:.0f} % of the time, actor {r['actor_wait_s']:.0f} s", flush=True)
        print(f"N = {n:2d} overlapped / sequential env steps per hour: {r['steps_per_hour'] / seq:.2f}x", flush=True)


if __name__ == "__main__":
    main()
