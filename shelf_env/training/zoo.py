"""rl-zoo3 integration: the ``pixel_double_dqn`` algorithm, the recipe as an rl-zoo3 hyper-parameter
file, and the callback that applies the parts of the recipe rl-zoo3 has no key for.

    python examples/zoo_train.py --algo pixel_double_dqn --env ShelfSort-v0 --gym-packages shelf_env \\
        -conf examples/hyperparams/pixel_double_dqn.yml
    python examples/zoo_enjoy.py --algo pixel_double_dqn --env ShelfSort-v0 --gym-packages shelf_env -f logs/
    python examples/zoo_record.py --algo pixel_double_dqn --env ShelfSort-v0 -f logs/

One place for the recipe: ``examples/hyperparams/pixel_double_dqn.yml`` is generated from
`shelf_env.training.config.PRESETS` by `zoo_hyperparams` (``python -m shelf_env.training.zoo`` rewrites it; a test
checks the committed file is what it generates). Constructor arguments become rl-zoo3 keys; the
rest of the recipe (demonstrations, symmetry augmentation, the curriculum with its greedy gate,
TensorBoard images) is `RecipeCallback`'s keyword arguments under ``callback:``.

rl-zoo3's ``enjoy`` and ``record_video`` call ``model.predict`` without action masks, so they show
the all-pixel argmax (`PixelDoubleDQN.predict`'s documented behaviour without ``action_masks``);
``shelf-demo`` and ``shelf-evaluate`` act within the env's masks.
"""

from __future__ import annotations

import argparse
import dataclasses
import pathlib
from typing import Any

from stable_baselines3.common.callbacks import BaseCallback, CallbackList

from sb3_pixeldqn import PICK_AND_PUSH_MAPS, PICK_ONLY_MAPS, HindsightRelabelReplayBuffer, PixelDoubleDQN
from shelf_env.actions import ActionCodec
from shelf_env.training.config import (
    PRESETS,
    SIMULATOR_DEMOS,
    TrainConfig,
    augmentations,
    collect_demonstrations,
    demo_policy,
    env_codec,
    load_demonstration_data,
    make_callbacks,
    make_env,
)

ALGO = "pixel_double_dqn"
ENV_ID = "ShelfSort-v0"
HYPERPARAMS = pathlib.Path(__file__).resolve().parents[2] / "examples" / "hyperparams" / f"{ALGO}.yml"
#: TrainConfig fields that are PixelDoubleDQN constructor arguments of the same name.
MODEL_KEYS = ("learning_rate", "buffer_size", "learning_starts", "batch_size", "tau", "gamma", "gradient_steps",
              "target_update_interval", "exploration_initial_eps", "exploration_final_eps", "exploration_timesteps",
              "masked", "masked_exploration", "demo_fraction", "margin", "margin_weight")
#: TrainConfig fields that go to the env (as ``env_kwargs``).
ENV_KEYS = ("object_set", "primitives", "pixel_size", "safe_picks", "closed_loop", "min_num_objects",
            "progress_reward", "invalid_reward")


def register() -> None:
    """Add ``pixel_double_dqn`` to rl-zoo3's algorithm table (before its command line is parsed)."""
    from rl_zoo3.utils import ALGOS

    ALGOS[ALGO] = PixelDoubleDQN


def saved_env_kwargs(argv: list[str]) -> dict[str, Any]:
    """The ``env_kwargs`` a run was trained with (its ``config.yml``), for the rl-zoo3 command line
    ``argv`` (``-f``/``--folder``, ``--algo``, ``--env``, ``--exp-id`` as rl-zoo3 reads them); {} if
    the run has none. rl-zoo3's enjoy reads them itself; its record_video does not."""
    import argparse

    import yaml
    from rl_zoo3.utils import get_latest_run_id

    p = argparse.ArgumentParser(add_help=False)
    p.add_argument("-f", "--folder", default="rl-trained-agents", help="rl-zoo3's log folder")
    p.add_argument("--algo", default=ALGO, help="rl-zoo3's algorithm name")
    p.add_argument("--env", default=ENV_ID, help="the env id")
    p.add_argument("--exp-id", type=int, default=0, help="the run's id (0: the latest)")
    args, _ = p.parse_known_args(argv)
    exp_id = args.exp_id or get_latest_run_id(str(pathlib.Path(args.folder) / args.algo), args.env)
    config = pathlib.Path(args.folder) / args.algo / f"{args.env}_{exp_id}" / args.env / "config.yml"
    if not config.is_file():
        return {}
    saved = dict(yaml.load(config.read_text(), Loader=yaml.UnsafeLoader))  # rl-zoo3 writes pairs
    return dict(saved.get("env_kwargs") or {})


def zoo_hyperparams(config: TrainConfig, n_timesteps: int = 20_000) -> dict[str, Any]:
    """The rl-zoo3 hyper-parameter entry of ``config`` (``{ENV_ID: {...}}``)."""
    maps = PICK_AND_PUSH_MAPS if "push" in config.primitives else PICK_ONLY_MAPS
    entry: dict[str, Any] = {"n_timesteps": int(n_timesteps), "policy": "FCNPolicy"}
    entry["env_kwargs"] = {"num_objects": config.start_objects, **{k: _plain(getattr(config, k)) for k in ENV_KEYS}}
    entry.update({key: _plain(getattr(config, key)) for key in MODEL_KEYS})
    entry["policy_kwargs"] = f"dict(maps={[tuple(m) for m in maps]!r}, widths={tuple(config.widths)!r})"
    entry["replay_buffer_kwargs"] = (f"dict(relabel={config.relabel!r}, noop={config.noop!r}, "
                                     f"noop_penalty={config.noop_penalty!r})")
    used = {*MODEL_KEYS, *ENV_KEYS, "widths", "relabel", "noop", "noop_penalty", "start_objects", "extra"}
    rest = {f.name: _plain(getattr(config, f.name)) for f in dataclasses.fields(config) if f.name not in used}
    rest["start_objects"] = config.start_objects
    entry["callback"] = [{"shelf_env.training.zoo.RecipeCallback": rest}]
    return {ENV_ID: entry}


def _plain(value: Any) -> Any:
    return list(value) if isinstance(value, tuple) else value


def write_hyperparams(path: pathlib.Path = HYPERPARAMS, preset: str = "recipe", n_timesteps: int = 20_000) -> str:
    """Write the yml of a preset (atomically) and return its text."""
    import yaml

    from shelf_env.files import write_text_atomically

    header = (f"# Generated by `python -m shelf_env.training.zoo` from shelf_env.training.config.PRESETS[{preset!r}]:\n"
              "# edit the preset, not this file (tests/test_zoo.py checks that they agree).\n")
    text = header + yaml.safe_dump(zoo_hyperparams(PRESETS[preset], n_timesteps), sort_keys=False, width=1000)
    write_text_atomically(path, text)
    return text


class RecipeCallback(BaseCallback):
    """The parts of a `TrainConfig` that are not constructor arguments, applied to an rl-zoo3 run.

    At construction, the keyword arguments are TrainConfig fields (those `zoo_hyperparams` puts under
    ``callback:``); the model's own arguments come from the yml's other keys. When training starts:
    the symmetry augmentation is set on the model, the demonstrations are collected into the
    buffer (once: not again if the buffer already holds some), and the curriculum callback (with its
    greedy gate and its own eval env) and the optional Q-map images run beside rl-zoo3's callbacks.
    """

    def __init__(self, verbose: int = 1, **fields: Any) -> None:
        super().__init__(verbose)
        self.fields = fields
        self.children: CallbackList | None = None

    def _config(self) -> TrainConfig:
        """The config: the training env's layout, cell size, object set, safe picks, closed loop, mix
        of sizes and rewards (``env_kwargs``) with this callback's fields; the greedy checks' env is built
        from it, so it plays under the training env's conditions."""
        env = self.training_env
        codec: ActionCodec = env.get_attr("codec")[0]
        primitives = ("pick", "push") if "push_left" in codec.map_names else ("pick",)
        watch = env.get_attr("drag_watch")[0]
        settings = {"primitives": primitives, "object_set": env.get_attr("object_set")[0],
                    "pixel_size": codec.pixel_size, "safe_picks": env.get_attr("safe_picks")[0],
                    "closed_loop": False if watch is None else dataclasses.asdict(watch),
                    "min_num_objects": env.get_attr("min_num_objects")[0],
                    "progress_reward": env.get_attr("progress_reward")[0],
                    "invalid_reward": env.get_attr("invalid_reward")[0]}
        return PRESETS["recipe"].replace(**{**settings, **self.fields})

    def update_child_locals(self, locals_: dict[str, Any]) -> None:
        if self.children is not None:
            self.children.update_locals(locals_)

    def _on_training_start(self) -> None:
        model = self.model
        assert isinstance(model, PixelDoubleDQN), "RecipeCallback trains a PixelDoubleDQN"
        config = self._config()
        if config.actor:
            raise ValueError("actor: true in the yml, but rl-zoo3 builds and steps its own envs; train with "
                             "`shelf-train --actor` for an actor process, or set actor: false")
        if config.guard is not None:
            raise ValueError(f"guard: {config.guard} in the yml, but rl-zoo3 builds and steps its own envs; train with "
                             "`shelf-train` for a supervised training env, or set guard: null")
        if config.n_envs > 1:
            raise ValueError(f"n_envs: {config.n_envs} in the recipe callback's fields, but rl-zoo3 builds its own "
                             "envs: set the yml's own n_envs instead")
        model.augment = augmentations(config, env_codec(self.training_env))
        buffer = model.replay_buffer
        assert isinstance(buffer, HindsightRelabelReplayBuffer)
        if config.demo_data is not None and buffer.demonstrations is None:  # the teacher dataset's transitions
            load_demonstration_data(model, config, log=lambda line: print(line, flush=True) if self.verbose else None)
        if config.demo_policy is not None and buffer.demonstrations is None and config.demo_steps > 0:
            if config.demo_policy in SIMULATOR_DEMOS:  # it probes the env it acts in: the training env itself
                envs = getattr(self.training_env, "envs", None)
                if envs is None or len(envs) != 1:
                    raise ValueError(f"demo_policy {config.demo_policy} probes the simulator of the env it plays "
                                     f"in; rl-zoo3 gave {type(self.training_env).__name__} with "
                                     f"{self.training_env.num_envs} env(s): use n_envs: 1 (a DummyVecEnv)")
                demos = demo_policy(config, envs[0])
            else:
                probe = make_env(config)  # these heuristics read only the layout of the env they are built on
                demos = demo_policy(config, probe)
                probe.close()
            collect_demonstrations(model, config, demos, lambda n: self.training_env.env_method("set_num_objects", n),
                                   log=lambda line: print(line, flush=True) if self.verbose else None)
        self.children = CallbackList(make_callbacks(config, seed=model.seed or 0, verbose=self.verbose))
        self.children.init_callback(model)
        self.children.on_training_start(self.locals, self.globals)

    def _on_step(self) -> bool:
        assert self.children is not None
        return self.children.on_step()

    def _on_training_end(self) -> None:
        if self.children is not None:
            self.children.on_training_end()


def main(argv: list[str] | None = None) -> int:
    """``python -m shelf_env.training.zoo [PATH]``: write the rl-zoo3 hyperparameter file (default `HYPERPARAMS`)."""
    parser = argparse.ArgumentParser(prog="python -m shelf_env.training.zoo",
                                     description="Write rl-zoo3's hyperparameter file from PRESETS['recipe'].")
    parser.add_argument("path", nargs="?", type=pathlib.Path, default=HYPERPARAMS,
                        help=f"where to write it (default {HYPERPARAMS})")
    target = parser.parse_args(argv).path
    write_hyperparams(target)
    print(f"wrote {target}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
