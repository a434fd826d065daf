"""Train PixelDoubleDQN on ShelfSort-v0 with the curriculum, on a wall-clock budget, resumably.

    python examples/train.py --out runs/curriculum --hours 2

Everything lives in ``--out``: ``model.zip`` and ``replay.pkl`` (checkpoint, written atomically
every ``--checkpoint-minutes``), ``progress.json`` (wall time and steps used so far, curriculum
history), ``episodes.csv`` (one row per finished episode) and ``tb/`` (TensorBoard). Running the
same command again resumes from the last checkpoint until the total budget is spent; rows of
``episodes.csv`` written after that checkpoint are dropped, as their steps are redone.
``python examples/plot_training.py runs/curriculum`` turns ``episodes.csv`` into a PNG.
"""

from __future__ import annotations

import argparse
import csv
import json
import pathlib
import time

import gymnasium as gym
import torch as th
from stable_baselines3.common.callbacks import BaseCallback, CallbackList

import shelf_env  # noqa: F401  (registers ShelfSort-v0)
from sb3_pixeldqn import PICK_AND_PUSH_MAPS, PICK_ONLY_MAPS, CurriculumCallback, PixelDoubleDQN
from shelf_env.evaluation import write_json_atomic

EPISODE_FIELDS = ["timestep", "wall_seconds", "num_objects", "success", "actions", "return", "fell"]


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", type=pathlib.Path, default=pathlib.Path("runs/curriculum"))
    p.add_argument("--hours", type=float, default=2.0, help="total wall-clock budget over all resumes")
    p.add_argument("--max-steps", type=int, default=10**7, help="total env-step budget over all resumes")
    p.add_argument("--checkpoint-minutes", type=float, default=10.0)
    p.add_argument("--primitives", choices=["pick-push", "pick"], default="pick-push", help="P+S or the S baseline")
    p.add_argument("--start-objects", type=int, default=1)
    p.add_argument("--max-objects", type=int, default=8)
    p.add_argument("--widths", type=int, nargs=3, default=[16, 32, 64])
    p.add_argument("--buffer-size", type=int, default=50_000)
    p.add_argument("--learning-starts", type=int, default=100)
    p.add_argument("--learning-rate", type=float, default=1e-4)
    p.add_argument("--exploration-timesteps", type=int, default=2_000)
    p.add_argument("--min-stage-timesteps", type=int, default=0,
                   help="curriculum stages last at least this many steps (0: the paper's rule)")
    p.add_argument("--uniform-exploration", action="store_true", help="draw exploratory actions uniformly")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--threads", type=int, default=2, help="torch CPU threads")
    return p.parse_args(argv)


class BudgetAndCheckpoint(BaseCallback):
    """Logs finished episodes, checkpoints every few minutes and stops when the budget is spent."""

    def __init__(self, out: pathlib.Path, progress: dict, hours: float, max_steps: int, every_minutes: float) -> None:
        super().__init__()
        self.out = out
        self.progress = progress
        self.budget_seconds = hours * 3600.0
        self.max_steps = max_steps
        self.every_seconds = every_minutes * 60.0
        self.session_start = time.monotonic()
        self.wall_before_session = float(progress["wall_seconds"])
        self.last_checkpoint = self.session_start
        self.csv_file = None
        self.writer = None
        self.episode_returns: dict[int, float] = {}

    def wall_seconds(self) -> float:
        return self.wall_before_session + time.monotonic() - self.session_start

    def _on_training_start(self) -> None:
        self.csv_file = open(self.out / "episodes.csv", "a", newline="")  # noqa: SIM115
        self.writer = csv.DictWriter(self.csv_file, fieldnames=EPISODE_FIELDS)

    def _on_step(self) -> bool:
        steps = zip(self.locals["dones"], self.locals["infos"], self.locals["rewards"])
        for i, (done, info, reward) in enumerate(steps):
            self.episode_returns[i] = self.episode_returns.get(i, 0.0) + float(reward)
            if done:
                self.writer.writerow({
                    "timestep": self.num_timesteps,
                    "wall_seconds": round(self.wall_seconds(), 1),
                    "num_objects": info.get("num_objects"),
                    "success": int(bool(info.get("is_success"))),
                    "actions": info.get("action_count"),
                    "return": self.episode_returns.pop(i),
                    "fell": int(bool(info.get("fell"))),
                })
                self.progress["episodes"] += 1
        now = time.monotonic()
        if now - self.last_checkpoint >= self.every_seconds:
            self.checkpoint()
        return self.wall_seconds() < self.budget_seconds and self.num_timesteps < self.max_steps

    def _on_training_end(self) -> None:
        self.checkpoint()
        self.csv_file.close()

    def checkpoint(self) -> None:
        self.csv_file.flush()
        self.model.save(self.out / "model.zip")
        self.model.save_replay_buffer(self.out / "replay.pkl")
        self.progress.update(
            wall_seconds=round(self.wall_seconds(), 1),
            timesteps=self.model.num_timesteps,
            curriculum=self.model.curriculum_state,
        )
        write_json_atomic(self.out / "progress.json", self.progress)
        self.last_checkpoint = time.monotonic()
        print(f"[{self.progress['wall_seconds'] / 60:6.1f} min] checkpoint at step {self.model.num_timesteps}, "
              f"N = {self.model.curriculum_state['value']}", flush=True)


def truncate_csv(path: pathlib.Path, rows: int) -> None:
    """Keep the header and the first ``rows`` episode rows (those covered by the checkpoint)."""
    if not path.exists():
        with open(path, "w", newline="") as f:
            csv.DictWriter(f, fieldnames=EPISODE_FIELDS).writeheader()
        return
    lines = path.read_text().splitlines(keepends=True)
    path.write_text("".join(lines[: rows + 1]))


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    th.set_num_threads(args.threads)
    args.out.mkdir(parents=True, exist_ok=True)
    primitives = ("pick", "push") if args.primitives == "pick-push" else ("pick",)
    env = gym.make("ShelfSort-v0", num_objects=args.start_objects, primitives=primitives)
    progress_path = args.out / "progress.json"
    resume = (args.out / "model.zip").exists() and progress_path.exists()
    if resume:
        progress = json.loads(progress_path.read_text())
        model = PixelDoubleDQN.load(args.out / "model.zip", env=env, tensorboard_log=str(args.out / "tb"))
        model.load_replay_buffer(args.out / "replay.pkl")
        print(f"resuming at step {model.num_timesteps}, {progress['wall_seconds'] / 60:.1f} min used", flush=True)
    else:
        progress = {"wall_seconds": 0.0, "timesteps": 0, "episodes": 0,
                    "args": {k: str(v) for k, v in vars(args).items()}}
        model = PixelDoubleDQN(
            "FCNPolicy",
            env,
            learning_rate=args.learning_rate,
            buffer_size=args.buffer_size,
            learning_starts=args.learning_starts,
            exploration_timesteps=args.exploration_timesteps,
            exploration_mask=None if args.uniform_exploration else "exploration_mask",
            policy_kwargs=dict(maps=PICK_AND_PUSH_MAPS if len(primitives) == 2 else PICK_ONLY_MAPS,
                               widths=tuple(args.widths)),
            tensorboard_log=str(args.out / "tb"),
            seed=args.seed,
        )
    truncate_csv(args.out / "episodes.csv", progress["episodes"])
    budget = BudgetAndCheckpoint(args.out, progress, args.hours, args.max_steps, args.checkpoint_minutes)
    if budget.wall_seconds() >= budget.budget_seconds or model.num_timesteps >= args.max_steps:
        print("budget already spent; nothing to do")
        return
    curriculum = CurriculumCallback(start_value=args.start_objects, max_value=args.max_objects,
                                    min_stage_timesteps=args.min_stage_timesteps, verbose=1)
    model.learn(10**9, callback=CallbackList([curriculum, budget]), log_interval=5, reset_num_timesteps=not resume)
    print(f"done: {model.num_timesteps} steps, {progress['wall_seconds'] / 60:.1f} min, "
          f"curriculum {model.curriculum_state['history']}", flush=True)


if __name__ == "__main__":
    main()
