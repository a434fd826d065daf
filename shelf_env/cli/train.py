"""Train PixelDoubleDQN on ShelfSort-v0 with the curriculum, on a wall-clock budget, resumably.

    shelf-train --out runs/curriculum --hours 2 [--preset recipe|p_s|s|paper|issue3] [--set KEY=VALUE ...]
    python examples/train.py ...                  # the same

The configuration is a `shelf_env.training.config.TrainConfig` preset with overrides; it is stored in
``progress.json`` and a resumed run keeps it. With demonstrations, they are collected first (their
wall time counts in the budget) and kept in the replay buffer.

Everything lives in ``--out``: ``model.zip`` and ``replay.pkl`` (checkpoint, written atomically
every ``--checkpoint-minutes``), ``progress.json`` (wall time and steps used so far, curriculum
history), ``episodes.csv`` (one row per finished episode) and ``tb/`` (TensorBoard). Running the
same command again resumes from the last checkpoint until the total budget is spent; rows of
``episodes.csv`` written after that checkpoint are dropped, as their steps are redone.
``python examples/plot_training.py runs/curriculum`` turns ``episodes.csv`` into a PNG.

A resumed run keeps its configuration; ``--amend KEY=VALUE`` changes one of the fields that a
running curriculum can take up (``AMENDABLE``: stage bounds and greedy checks, not the network,
the env or the optimiser) and records the change and the env step it took effect at in
``progress.json`` (``amendments``), so that the run's history says what it ran under and when.

``--init-from ZIP`` starts a new run from a trained checkpoint's weights (same primitives, cell
size and network; online and target networks; not its buffer), e.g. to fine-tune a shipped model
under another configuration (``--set safe_picks=true``); ``progress.json`` records the file's
sha256. A resumed run continues from its own checkpoint.

``--actor`` (``--set actor=true``; amendable) steps the env in an actor process
(`sb3_pixeldqn.actor.ActorVecEnv`) while the learner trains: the actor takes one torch thread and
the learner ``--threads`` minus one (docs/experiments/learning-recipe.md, lever 9). Demonstrations are collected on an
in-process env before it starts.

``--mirror DIR`` keeps a copy of everything but the replay buffer (``model.zip``,
``progress.json``, ``episodes.csv``, ``tb/``) in ``DIR`` after every checkpoint, for committing.
A run whose ``--out`` has no checkpoint (a fresh machine) starts from that copy: it resumes from
the weights, the curriculum stage and ε with an empty buffer, which it refills (demonstrations
again, then ``learning_starts`` steps before learning resumes).
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import hashlib
import json
import pathlib
import sys
import time
from typing import Any, TextIO

import torch as th
from stable_baselines3.common.callbacks import BaseCallback, CallbackList

import shelf_env  # noqa: F401  (registers ShelfSort-v0)
from sb3_pixeldqn import HindsightRelabelReplayBuffer, PixelDoubleDQN
from sb3_pixeldqn.callbacks import curriculum_over
from shelf_env.files import copy_atomically, write_json_atomically, write_text_atomically
from shelf_env.training.config import (
    PRESETS,
    TrainConfig,
    collect_demonstrations,
    demo_policy,
    field_help,
    guarded,
    init_from_checkpoint,
    load_demonstration_data,
    make_actor_env,
    make_callbacks,
    make_model,
    make_unsupervised_training_env,
    use_parallel_envs,
)

#: TrainConfig fields ``--amend`` may change in a resumed run: what the curriculum callback reads
#: when it is built, and how the env steps are collected (in an actor process or not); nothing the
#: saved model or its replay buffer depends on. Not ``guard``: its corrections need room in the
#: demonstration store, which is sized when the run's demonstrations are collected.
AMENDABLE = ("max_stage_timesteps", "min_stage_timesteps", "max_objects", "eval_every", "eval_episodes",
             "eval_max_actions", "eval_actions_per_object", "tb_images_every", "actor", "actor_max_lag",
             "actor_sync_every", "n_envs")
EPISODE_FIELDS = ["timestep", "wall_seconds", "num_objects", "success", "actions", "return", "fell"]


def parse_set(text: str) -> tuple[str, Any]:
    """"key=value" with value parsed as JSON when it can be (numbers, true/false, null, lists)."""
    if "=" not in text:
        raise argparse.ArgumentTypeError(f"--set and --amend need key=value, got {text!r}")
    key, value = text.split("=", 1)
    try:
        return key, json.loads(value)
    except json.JSONDecodeError:
        return key, value


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="shelf-train", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", type=pathlib.Path, default=pathlib.Path("runs/curriculum"),
                   help="the run's folder: checkpoint, progress, episodes.csv, TensorBoard; resumed when it has them")
    p.add_argument("--preset", choices=sorted(PRESETS), default="recipe",
                   help="starting configuration (shelf_env/training/config.py); flags below override it")
    p.add_argument("--set", dest="overrides", type=parse_set, action="append", default=[], metavar="KEY=VALUE",
                   help="override any TrainConfig field, e.g. --set masked=false --set augment=[]")
    p.add_argument("--hours", type=float, default=2.0, help="total wall-clock budget over all resumes")
    p.add_argument("--max-steps", type=int, default=10**7, help="total env-step budget over all resumes")
    p.add_argument("--checkpoint-minutes", type=float, default=10.0, help="minutes between checkpoints")
    p.add_argument("--mirror", type=pathlib.Path, default=None,
                   help="copy the checkpoint (all but the replay buffer) here; resume from it when --out has none")
    p.add_argument("--amend", dest="amendments", type=parse_set, action="append", default=[], metavar="KEY=VALUE",
                   help=f"change a resumed run's configuration from now on; one of {', '.join(AMENDABLE)}")
    p.add_argument("--device", default="auto", help="torch device of the learner, as SB3's (auto: cuda if available)")
    p.add_argument("--init-from", type=pathlib.Path, default=None, metavar="ZIP",
                   help="a new run starts from this checkpoint's weights (same layout and network; its buffer "
                        "is not used); a resumed run continues from its own checkpoint")
    p.add_argument("--seed", type=int, default=0, help="seed of the model and the training env")
    p.add_argument("--threads", type=int, default=2, help="torch CPU threads (actor and learner together)")
    add_config_flags(p.add_argument_group("training settings (TrainConfig fields; the preset's value unless given)"))
    return p.parse_args(argv)


def parse_bool(text: str) -> bool:
    value = {"true": True, "1": True, "yes": True, "false": False, "0": False, "no": False}.get(text.lower())
    if value is None:
        raise argparse.ArgumentTypeError(f"expected true or false, got {text!r}")
    return value


def parse_json_or_text(text: str) -> Any:
    """A value as JSON where it parses (numbers, true/false, null, lists, objects), else the text itself."""
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def add_config_flags(group: Any) -> None:
    """One flag per `TrainConfig` field (``--learning-rate``, ``--widths 16 32 64``, ``--actor``), its type
    from the field's default and its help from the field's comment (`field_help`): every setting is
    declared once, in TrainConfig. A flag not given leaves the preset's value (`config_from_args`)."""
    helps = field_help()
    for f in dataclasses.fields(TrainConfig):
        if f.name == "extra":
            continue
        default = PRESETS["recipe"].__dict__[f.name]
        flag = "--" + f.name.replace("_", "-")
        kwargs: dict[str, Any] = {"dest": "config_" + f.name, "default": argparse.SUPPRESS, "help": helps[f.name]}
        if isinstance(default, bool) and f.name != "closed_loop":
            kwargs.update(type=parse_bool, nargs="?", const=True, metavar="true|false")
        elif isinstance(default, tuple):
            element = int if default and isinstance(default[0], int) else str
            kwargs.update(type=element, nargs="*", metavar=f.name.upper())
        elif isinstance(default, float):
            kwargs.update(type=float, metavar="X")
        elif isinstance(default, int) and "None" not in str(f.type):
            kwargs.update(type=int, metavar="N")
        else:  # str, int or None, and the closed loop's true/false/JSON object
            kwargs.update(type=parse_json_or_text, metavar="VALUE")
        group.add_argument(flag, **kwargs)


def config_from_args(args: argparse.Namespace) -> TrainConfig:
    """The preset with the flags' and ``--set``'s overrides applied."""
    changes = {key.removeprefix("config_"): value for key, value in vars(args).items() if key.startswith("config_")}
    changes.update(dict(args.overrides))
    return PRESETS[args.preset].replace(**changes)


class BudgetAndCheckpoint(BaseCallback):
    """Logs finished episodes, checkpoints every few minutes and stops when the budget is spent."""

    def __init__(self, out: pathlib.Path, progress: dict, hours: float, max_steps: int, every_minutes: float,
                 mirror: pathlib.Path | None = None) -> None:
        super().__init__()
        self.out = out
        self.mirror = mirror
        self.progress = progress
        self.budget_seconds = hours * 3600.0
        self.max_steps = max_steps
        self.every_seconds = every_minutes * 60.0
        self.session_start = time.monotonic()
        self.wall_before_session = float(progress["wall_seconds"])
        self.last_checkpoint = self.session_start
        self.csv_file: TextIO | None = None
        self.writer: csv.DictWriter | None = None
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
                assert self.writer is not None  # opened at training start
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
        if self.csv_file is not None:
            self.csv_file.close()

    def checkpoint(self) -> None:
        if self.csv_file is not None:
            self.csv_file.flush()
        model = self.model
        assert isinstance(model, PixelDoubleDQN)
        model.save(self.out / "model.zip")
        model.save_replay_buffer(self.out / "replay.pkl")
        self.progress.update(
            wall_seconds=round(self.wall_seconds(), 1),
            timesteps=model.num_timesteps,
            curriculum=model.curriculum_state,
        )
        write_json_atomically(self.out / "progress.json", self.progress)
        if self.mirror is not None:
            copy_checkpoint(self.out, self.mirror)
        self.last_checkpoint = time.monotonic()
        print(f"[{self.progress['wall_seconds'] / 60:6.1f} min] checkpoint at step {model.num_timesteps}, "
              f"N = {(model.curriculum_state or {}).get('value')}", flush=True)


def session_record(model: PixelDoubleDQN, progress: dict, threads: int, buffer_kept: bool,
                   actor: bool = False, n_envs: int = 1) -> dict[str, Any]:
    """Where and when one run of the command started (for the model card's hardware and history)."""
    import datetime
    import os
    import platform

    return {
        "started": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "timesteps": int(model.num_timesteps), "wall_seconds": float(progress["wall_seconds"]),
        "machine": f"{platform.system()} {platform.machine()}, {os.cpu_count()} CPUs", "torch_threads": int(threads),
        "device": device_name(model.device), "buffer_kept": bool(buffer_kept), "actor": bool(actor),
        "n_envs": int(n_envs),
    }


def device_name(device: th.device) -> str:
    """``cpu``, or ``cuda (NVIDIA H100 80GB HBM3)``: which accelerator a session's learner ran on."""
    if device.type == "cuda":
        return f"cuda ({th.cuda.get_device_name(device)})"
    return str(device)


MIRRORED = ("model.zip", "episodes.csv", "progress.json")  # progress last: it vouches for the others


def copy_checkpoint(src: pathlib.Path, dst: pathlib.Path) -> None:
    """Copy a run's checkpoint but its replay buffer (``MIRRORED`` files and ``tb/``), each file atomically."""
    for name in MIRRORED:
        if (src / name).exists():
            copy_atomically(src / name, dst / name)
    if (src / "tb").is_dir():
        for path in sorted((src / "tb").rglob("*")):
            target = dst / path.relative_to(src)
            if path.is_file() and (not target.exists() or target.stat().st_size != path.stat().st_size):
                copy_atomically(path, target)


def truncate_csv(path: pathlib.Path, rows: int) -> None:
    """Keep the header and the first ``rows`` episode rows (those covered by the checkpoint)."""
    if not path.exists():
        write_text_atomically(path, ",".join(EPISODE_FIELDS) + "\r\n")  # csv's header line
        return
    lines = path.read_text().splitlines(keepends=True)
    write_text_atomically(path, "".join(lines[: rows + 1]))


def check_init_from(path: pathlib.Path, config: TrainConfig) -> None:
    """``--init-from``: a readable checkpoint with the run's primitives and cell size (its network
    is checked when its weights are loaded, `shelf_env.training.config.init_from_checkpoint`)."""
    from shelf_env.evaluation import protocol as ev

    primitives = ev.checkpoint_primitives(path)  # a clear error for a missing or unreadable file
    pixel_size = ev.checkpoint_pixel_size(path)
    if set(primitives) != set(config.primitives) or abs(pixel_size - config.pixel_size) > 1e-9:
        raise ValueError(f"--init-from {path} was trained with primitives {primitives} at {pixel_size * 1000:g} mm "
                         f"cells; this run has {config.primitives} at {config.pixel_size * 1000:g} mm")


def amend(config: TrainConfig, progress: dict, changes: dict[str, Any]) -> TrainConfig:
    """``config`` with ``changes`` applied (checked by TrainConfig), recorded in ``progress``'s
    ``amendments`` with the env step they take effect at; fields already at their value are no change."""
    changes = {key: value for key, value in changes.items() if getattr(config, key) != value}
    if not changes:
        return config
    amended = config.replace(**changes)
    progress.setdefault("amendments", []).append({"timesteps": int(progress["timesteps"]), "changes": changes})
    progress["config"] = amended.to_dict()
    print(f"amended from step {progress['timesteps']}: {changes}", flush=True)
    return amended


def main(argv: list[str] | None = None) -> int:
    """Train (or resume) as the flags say; 0 when done, 2 with one line on stderr for bad input."""
    args = parse_args(argv)
    try:
        if args.hours <= 0 or args.max_steps < 1 or args.checkpoint_minutes < 0 or args.threads < 1:
            raise ValueError("--hours and --max-steps must be > 0, --checkpoint-minutes >= 0, --threads >= 1")
        mirrored = args.mirror is not None and (args.mirror / "model.zip").exists()
        resuming = (args.out / "model.zip").exists() or mirrored
        if resuming and hasattr(args, "config_n_envs"):  # a run moving to another machine: recorded as an amendment
            args.amendments.append(("n_envs", args.config_n_envs))
        if not resuming:  # a fresh run: its configuration is checked before anything is written
            config = config_from_args(args)  # TrainConfig checks its fields and values
            if args.amendments:
                raise ValueError(f"--amend changes a resumed run, and {args.out} holds none; use --set for a new run")
            if args.init_from is not None:
                check_init_from(args.init_from, config)
        bad = sorted({key for key, _ in args.amendments} - set(AMENDABLE))
        if bad:
            raise ValueError(f"--amend cannot change {bad}; amendable fields: {list(AMENDABLE)}")
        if args.amendments:  # checked against the stored configuration before anything is written
            stored = args.out if (args.out / "progress.json").exists() else args.mirror
            if stored is None or not (stored / "progress.json").exists():
                raise ValueError(f"--amend: no progress.json in {args.out} or --mirror to amend")
            TrainConfig.from_dict(json.loads((stored / "progress.json").read_text())["config"]).replace(
                **dict(args.amendments))
    except ValueError as err:
        print(f"shelf-train: error: {err}", file=sys.stderr)
        return 2
    th.set_num_threads(args.threads)
    train(args)
    return 0


def train(args: argparse.Namespace) -> None:
    """The run of ``main``, arguments checked."""
    args.out.mkdir(parents=True, exist_ok=True)
    progress_path = args.out / "progress.json"
    if args.mirror is not None and not (args.out / "model.zip").exists() and (args.mirror / "model.zip").exists():
        copy_checkpoint(args.mirror, args.out)  # a fresh machine: start from the committed checkpoint
        print(f"starting from the checkpoint in {args.mirror}", flush=True)
    resume = (args.out / "model.zip").exists() and progress_path.exists()
    if resume:  # the run's own configuration wins over the flags
        progress = json.loads(progress_path.read_text())
        config = TrainConfig.from_dict(progress["config"])
        config = amend(config, progress, dict(args.amendments))
    else:
        config = config_from_args(args)
        progress = {"wall_seconds": 0.0, "timesteps": 0, "episodes": 0, "demo_seconds": 0.0,
                    "args": {k: str(v) for k, v in vars(args).items()}, "config": config.to_dict()}
    env = make_unsupervised_training_env(config)  # the learner's (no actor) and the demonstrations'
    if resume:
        model = PixelDoubleDQN.load(args.out / "model.zip", env=env, tensorboard_log=str(args.out / "tb"),
                                    device=args.device)
        # under the possibly amended cap
        if curriculum_over(model.curriculum_state or {}, model.num_timesteps, config.max_objects,
                           config.max_stage_timesteps):
            print(f"the curriculum is over: N = {config.max_objects} trained max_stage_timesteps = "
                  f"{config.max_stage_timesteps} steps by step {model.num_timesteps}; nothing to do")
            return
        print(f"resuming at step {model.num_timesteps}, {progress['wall_seconds'] / 60:.1f} min used", flush=True)
        if (args.out / "replay.pkl").exists():
            model.load_replay_buffer(args.out / "replay.pkl")
        else:  # refill before learning again, as a fresh run does
            model.learning_starts = model.num_timesteps + config.learning_starts
            print("no replay.pkl: resuming from the weights, the curriculum stage and epsilon with an empty "
                  f"buffer (demonstrations are collected again; learning resumes after step {model.learning_starts})",
                  flush=True)
    else:
        model = make_model(config, env, seed=args.seed, tensorboard_log=str(args.out / "tb"), device=args.device)
        if args.init_from is not None:
            init_from_checkpoint(model, args.init_from)
            digest = hashlib.sha256(args.init_from.read_bytes()).hexdigest()
            progress["init_from"] = {"path": str(args.init_from), "sha256": digest}
            print(f"starting from the weights of {args.init_from}", flush=True)
    progress.setdefault("sessions", []).append(session_record(model, progress, args.threads,
                                                              buffer_kept=(args.out / "replay.pkl").exists(),
                                                              actor=config.actor, n_envs=config.n_envs))
    session = len(progress["sessions"]) - 1
    demos = demo_policy(config, env)
    buffer = model.replay_buffer
    assert isinstance(buffer, HindsightRelabelReplayBuffer)
    if config.demo_data is not None and buffer.demonstrations is None:
        start = time.monotonic()
        load_demonstration_data(model, config, log=lambda line: print(line, flush=True))
        progress["demo_seconds"] = progress.get("demo_seconds", 0.0) + time.monotonic() - start
    if demos is not None and buffer.demonstrations is None:
        seconds = collect_demonstrations(model, config, demos, env.get_wrapper_attr("set_num_objects"),
                                         log=lambda line: print(line, flush=True))
        progress["wall_seconds"] += seconds
        progress["demo_seconds"] = progress.get("demo_seconds", 0.0) + seconds
    truncate_csv(args.out / "episodes.csv", progress["episodes"])
    budget = BudgetAndCheckpoint(args.out, progress, args.hours, args.max_steps, args.checkpoint_minutes, args.mirror)
    if budget.wall_seconds() >= budget.budget_seconds or model.num_timesteps >= args.max_steps:
        print("budget already spent; nothing to do")
        return
    if config.guard is not None:  # the learner's steps are supervised (the actor's and parallel envs build it)
        if not config.actor and config.n_envs == 1:
            model.set_env(guarded(config, env))
        print(f"supervised by {config.guard} (FallGuard): actions that would drop an object are replaced, both "
              "kept", flush=True)
    if config.actor:  # lever 9: from here on the env steps come from an actor process
        th.set_num_threads(max(1, args.threads - 1))
        model.set_env(make_actor_env(config))
        env.close()
        print(f"acting in an actor process (1 torch thread); the learner has {th.get_num_threads()}", flush=True)
    # with n_envs > 1 the env steps come from n_envs env processes from here on; each session's
    # envs get their own seeds (env i of session k: seed + 1000 k + i)
    use_parallel_envs(model, config, seed=args.seed + 1000 * session)
    if config.n_envs > 1:
        print(f"collecting from {config.n_envs} env processes; learner on {model.device}", flush=True)
    callbacks = [*make_callbacks(config, seed=args.seed), budget]
    try:
        model.learn(10**9, callback=CallbackList(callbacks), log_interval=5, reset_num_timesteps=not resume)
    finally:
        model.get_env().close()  # type: ignore[union-attr]  # the actor process, if any, ends here
    print(f"done: {model.num_timesteps} steps, {progress['wall_seconds'] / 60:.1f} min, "
          f"curriculum {(model.curriculum_state or {}).get('history')}", flush=True)


if __name__ == "__main__":
    raise SystemExit(main())
