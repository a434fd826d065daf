"""Does a learned P+S checkpoint's Q-map predict which picks drop an object? (issue 10 diagnostic)

Plays the privileged lookahead teacher (H-d with the one-step simulator probe, `shelf_env.privileged.lookahead`)
on scenes that no training or evaluation used (``scene_seed(5, N, run)``; the evaluations use seeds
0..2) and, at every decision where the teacher rejected a pick because its probe dropped an object
(`LookaheadHeuristic.counterfactuals`), asks each checkpoint for its Q-map of that observation:

- pairs: (rejected pick, the teacher's action) at the same state; ``ranked`` is the share where the
  checkpoint values the teacher's action above the rejected pick;
- ``greedy invalid``: the share of states where the checkpoint's own greedy action (masked argmax,
  as `shelf-evaluate` acts), tried in a forked copy of the env (`probe_outcome`: the step without its
  camera), would end the episode invalid (an object falls, or the scene is not at rest): at those decisions, and at the
  teacher's other decisions (no pick rejected).

    python research/fall_prediction.py results/training/p_s_long.zip results/training/p_s_la.zip \
        --n 8 --episodes 12 --out results/p_s_la/fall_prediction.md
"""

from __future__ import annotations

import argparse
import pathlib

import gymnasium as gym
import torch as th

from sb3_pixeldqn import PixelDoubleDQN
from shelf_env import params
from shelf_env.evaluation.protocol import scene_seed
from shelf_env.files import write_text_atomically
from shelf_env.privileged.lookahead import LookaheadDistance, probe_outcome

HELD_OUT_SEED = 5  # scene_seed's seed index: the evaluations use 0..2, training its own RNG


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("checkpoints", nargs="+", type=pathlib.Path)
    p.add_argument("--n", type=int, default=8, help="objects per scene")
    p.add_argument("--episodes", type=int, default=12)
    p.add_argument("--object-set", default="ycb")
    p.add_argument("--out", type=pathlib.Path, default=None, help="write the Markdown table here")
    args = p.parse_args(argv)
    if args.episodes < 1 or not 1 <= args.n <= params.MAX_OBJECTS:
        p.error(f"--episodes must be >= 1 and --n in [1, {params.MAX_OBJECTS}]")
    th.set_num_threads(2)
    models = {path.stem: PixelDoubleDQN.load(path, device="cpu") for path in args.checkpoints}
    env = gym.make("ShelfSort-v0", num_objects=args.n, object_set=args.object_set, max_actions=params.MAX_ACTIONS,
                   pixel_size=0.01).unwrapped
    teacher = LookaheadDistance(env)
    counts = {name: {"decisions": 0, "pairs": 0, "ranked": 0, "greedy_invalid": 0, "other": 0,
                     "other_invalid": 0} for name in models}
    try:
        for run in range(args.episodes):
            obs, _ = env.reset(seed=scene_seed(HELD_OUT_SEED, args.n, run))
            done = False
            while not done:
                action = int(teacher.predict(obs)[0])
                rejected = [a for a, _, _ in teacher.counterfactuals()]
                mask = env.get_wrapper_attr("action_masks")()
                valid: dict[int, bool] = {}  # this state's probes: checkpoints often agree on the action
                for name, model in models.items():
                    q = model.policy.q_map_values(obs).reshape(-1)  # the env's action order
                    greedy = int(model.predict(obs, deterministic=True, action_masks=mask)[0])
                    if greedy not in valid:
                        valid[greedy] = probe_outcome(env, greedy).valid
                    invalid = int(not valid[greedy])
                    c = counts[name]
                    if rejected:
                        c["decisions"] += 1
                        c["pairs"] += len(rejected)
                        c["ranked"] += sum(bool(q[action] > q[a]) for a in rejected)
                        c["greedy_invalid"] += invalid
                    else:
                        c["other"] += 1
                        c["other_invalid"] += invalid
                obs, _, terminated, truncated, _ = env.step(action)
                done = terminated or truncated
    finally:
        env.close()
    lines = [f"Held-out scenes (scene_seed({HELD_OUT_SEED}, {args.n}, run), {args.episodes} episodes, "
             f"{args.object_set} objects) played by h-d-lookahead; at its decisions that rejected a pick "
             "because the probe dropped an object:", "",
             "| checkpoint | decisions | (rejected, taken) pairs | taken valued above rejected | "
             "its greedy action invalid there | other decisions | its greedy action invalid there |",
             "|---|---|---|---|---|---|---|"]

    def pct(part: int, whole: int) -> str:
        return f"{100 * part / whole:.0f} %" if whole else "-"

    for name, c in counts.items():
        lines.append(f"| {name} | {c['decisions']} | {c['pairs']} | {pct(c['ranked'], c['pairs'])} | "
                     f"{pct(c['greedy_invalid'], c['decisions'])} | {c['other']} | "
                     f"{pct(c['other_invalid'], c['other'])} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out is not None:
        write_text_atomically(args.out, text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
