"""Watch a policy sort one unseen cabinet: ``shelf-demo`` / ``python -m shelf_env.cli.demo``.

    shelf-demo                                  # the shipped P+S model (or the best committed checkpoint)
    shelf-demo --policy h-d --n 5 --seed 3 --out /tmp/h_d.gif
    shelf-demo --policy results/learning/recipe_n3.zip --object-set train

Loads the policy, resets ShelfSort-v0 to a held-out scene (evaluation seed
`shelf_env.evaluation.protocol.HELDOUT_SEED`, run ``--seed``: no training run saw it), plays it greedily
(a learned model within the env's action masks, as evaluation does) and writes an animated GIF.
One frame per action, three panels: the rendered cabinet and the observation heightmap the policy
acted on, and the Q-values of the chosen primitive's map over it (yellow high, purple low; cells outside the
action mask dimmed; heuristics have no Q-values) with the executed pixel marked. It prints each
action as it goes and the outcome (sorted or not, actions, falls). The GIF is written only at the
end, atomically; bad input is one line on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import pathlib
import sys
from typing import Any

import cv2
import gymnasium as gym
import numpy as np

from shelf_env import params
from shelf_env.actions import ActionCodec
from shelf_env.evaluation import protocol as ev
from shelf_env.files import write_atomically
from shelf_env.policies import policy_files, policy_wrappers

#: The policy shelf-demo shows by default: the shipped P+S as examples/pretrained/README.md says to play it (under its
#: geometry pick filter, the pick guard and the loop breaker), else the shipped P+S alone, else the best committed
#: checkpoint.
DEFAULT_POLICIES = ("examples/pretrained/p_s.zip+geometry-filter+pick-guard+loop-breaker",
                    "examples/pretrained/p_s.zip", "results/learning/recipe_n3.zip")
PANEL = (400, 300)  # width, height of each panel
PRIMITIVE_LABEL = {"pick": "pick-and-place", "push_left": "push left", "push_right": "push right"}


def default_policy(root: pathlib.Path | None = None) -> str:
    """The first of `DEFAULT_POLICIES` whose files all exist (relative to the project root or the cwd)."""
    roots = [pathlib.Path.cwd()] if root is None else [root]
    roots.append(pathlib.Path(__file__).resolve().parents[2])
    for rel in DEFAULT_POLICIES:
        name, wrappers = policy_wrappers(rel)
        for base in roots:
            if all(f.is_file() for f in policy_files(str(base / name) + "".join(wrappers))):
                path, cwd = (base / name).resolve(), pathlib.Path.cwd()
                return (str(path.relative_to(cwd)) if path.is_relative_to(cwd) else str(path)) + "".join(wrappers)
    raise ValueError(f"no committed policy found ({', '.join(DEFAULT_POLICIES)}); pass --policy")


def _colourmap(values: np.ndarray) -> np.ndarray:
    """uint8 RGB of values in [0, 1] (viridis)."""
    grey = np.clip(values * 255, 0, 255).astype(np.uint8)
    bgr = cv2.applyColorMap(grey, cv2.COLORMAP_VIRIDIS)
    return bgr[..., ::-1]


def heightmap_panel(obs: np.ndarray) -> np.ndarray:
    """The observation's colour channels, scaled to a panel (nearest: cells stay crisp)."""
    return cv2.resize(np.ascontiguousarray(obs[:3].transpose(1, 2, 0)), PANEL, interpolation=cv2.INTER_NEAREST)


def q_panel(obs: np.ndarray, q_map: np.ndarray | None, allowed: np.ndarray | None) -> np.ndarray:
    """Q-values of one map as a heat overlay on the heightmap (normalised over the allowed cells)."""
    base = obs[:3].transpose(1, 2, 0).astype(np.float32)
    if q_map is None:
        out = base * 0.5 + 64
    else:
        sel = q_map[allowed] if allowed is not None and allowed.any() else q_map.reshape(-1)
        lo, hi = float(np.percentile(sel, 1)), float(np.percentile(sel, 99))
        heat = _colourmap((q_map - lo) / max(hi - lo, 1e-6)).astype(np.float32)
        out = 0.35 * base + 0.65 * heat
        if allowed is not None:
            out[~allowed] *= 0.35
    return cv2.resize(np.clip(out, 0, 255).astype(np.uint8), PANEL, interpolation=cv2.INTER_NEAREST)


def mark(panel: np.ndarray, codec: ActionCodec, row: int, col: int) -> np.ndarray:
    """A ring around the executed cell."""
    sx, sy = PANEL[0] / codec.cols, PANEL[1] / codec.rows
    centre = (int((col + 0.5) * sx), int((row + 0.5) * sy))
    cv2.circle(panel, centre, 9, (255, 0, 0), 2, lineType=cv2.LINE_AA)
    cv2.circle(panel, centre, 2, (255, 0, 0), -1)
    return panel


def caption(panel: np.ndarray, text: str) -> np.ndarray:
    cv2.rectangle(panel, (0, 0), (PANEL[0], 20), (255, 255, 255), -1)
    cv2.putText(panel, text, (5, 15), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    return panel


def frame(scene: np.ndarray, obs: np.ndarray, q: np.ndarray | None, allowed: np.ndarray | None,
          codec: ActionCodec, action: int | None, title: str) -> np.ndarray:
    """One GIF frame: cabinet | heightmap | Q-map of the chosen primitive, with a title bar; the
    last frame (no action) shows the end state."""
    left = caption(cv2.resize(scene, PANEL, interpolation=cv2.INTER_AREA), "cabinet (rendered)")
    middle = caption(heightmap_panel(obs), "observation (heightmap)")
    if action is None:
        right = caption(heightmap_panel(obs), "")
    else:
        name, row, col = codec.decode(action)
        m = codec.map_index(name)
        cells = codec.rows * codec.cols
        q_map = None if q is None else q[m]
        map_allowed = None if allowed is None else allowed[m * cells:(m + 1) * cells].reshape(codec.rows, codec.cols)
        label = f"Q: {PRIMITIVE_LABEL.get(name, name)}" if q is not None else f"{PRIMITIVE_LABEL.get(name, name)}"
        right = caption(q_panel(obs, q_map, map_allowed), label)
        middle, right = mark(middle, codec, row, col), mark(right, codec, row, col)
    body = np.concatenate([left, middle, right], axis=1)
    bar = np.full((26, body.shape[1], 3), 255, dtype=np.uint8)
    cv2.putText(bar, title, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (0, 0, 0), 1, cv2.LINE_AA)
    return np.concatenate([bar, body], axis=0)


def q_map_values_of(agent: Any) -> Any:
    """The Q-map function (``obs -> (maps, rows, cols)``) of a checkpoint's network, or an ensemble's mean maps
    (`sb3_pixeldqn.QEnsemble`), looked up through the wrappers around it (a `LoopBreaker`, a
    `shelf_env.fall_filter.FallFilter`: each holds what it wraps as ``policy``), so the overlay shows the model's
    own values and the marked cell is what the wrappers let it do; None for a heuristic."""
    inner = agent
    for _ in range(8):  # a wrapper, a model, its network: a few levels down at most
        own = getattr(inner, "q_map_values", None)
        if own is not None:
            return own
        inner = getattr(inner, "policy", None)
        if inner is None:
            return None
    return None


def run(policy: str, n: int, seed: int, object_set: str, out: pathlib.Path, max_actions: int = params.MAX_ACTIONS,
        log: Any = print) -> dict[str, Any]:
    """Play one held-out scene with ``policy`` and write the GIF; returns the outcome."""
    primitives = ev.check_policy(policy)
    env = gym.make("ShelfSort-v0", num_objects=n, object_set=object_set, primitives=primitives,
                   pixel_size=ev.policy_pixel_size(policy), max_actions=max_actions, render_mode="rgb_array")
    try:
        codec = ActionCodec.of(env)
        action_masks = env.get_wrapper_attr("action_masks")
        agent = ev.make_policy(policy, env, seed=seed)
        masked = ev.takes_action_masks(agent)
        q_of = q_map_values_of(agent)
        obs, info = env.reset(seed=ev.scene_seed(ev.HELDOUT_SEED, n, seed))
        label = ev.policy_label(policy)
        frames: list[np.ndarray] = []
        log(f"{label} on a held-out scene ({n} {object_set} objects, seed {seed}), "
            f"{info['num_unsorted_initial']} not in their region")
        done, first = False, True
        while not done:
            scene = np.asarray(env.render())  # what the camera saw: the frame shows the state the policy acted on
            allowed = action_masks()
            kwargs: dict[str, Any] = {"action_masks": allowed} if masked else {}
            if ev.predict_takes(agent, "episode_start"):
                kwargs["episode_start"] = np.array([first])
            action, _ = agent.predict(obs, deterministic=True, **kwargs)
            first = False
            action = int(np.asarray(action).reshape(-1)[0])
            q = q_of(obs) if q_of is not None else None
            name, row, col = codec.decode(action)
            next_obs, reward, terminated, truncated, info = env.step(action)
            done = terminated or truncated
            k = info["action_count"]
            status = "sorted" if info["is_success"] else ("an object fell" if info["fell"] else f"reward {reward:g}")
            log(f"  action {k:2d}: {PRIMITIVE_LABEL.get(name, name):15s} at cell ({row:2d}, {col:3d}) -> {status}")
            frames.append(frame(scene, obs, q, allowed if masked else None, codec, action,
                                f"action {k}: {PRIMITIVE_LABEL.get(name, name)} -> {status} "
                                f"({info['num_sorted']}/{n} in their region)"))
            obs = next_obs
        outcome = {"policy": label, "sorted": bool(info["is_success"]), "actions": int(info["action_count"]),
                   "fell": bool(info["fell"]), "num_objects": n, "object_set": object_set, "seed": seed}
        end = "SORTED" if outcome["sorted"] else ("FELL" if outcome["fell"] else "NOT SORTED")
        frames.append(frame(np.asarray(env.render()), obs, None, None, codec, None,
                            f"{label}: {end} after {outcome['actions']} actions"))
    finally:
        env.close()
    save_gif(frames, out)
    log(f"{end}: {outcome['actions']} actions, {'a fall' if outcome['fell'] else 'no fall'}; wrote {out}")
    return outcome


def save_gif(frames: list[np.ndarray], out: pathlib.Path, ms_per_frame: int = 1200) -> None:
    """An animated GIF (the last frame held three times as long), written atomically."""
    from PIL import Image

    images = [Image.fromarray(f).convert("P", palette=Image.Palette.ADAPTIVE, colors=255) for f in frames]
    durations = [ms_per_frame] * (len(images) - 1) + [3 * ms_per_frame]
    write_atomically(out, lambda tmp: images[0].save(tmp, format="GIF", save_all=True, append_images=images[1:],
                                                     duration=durations, loop=0, optimize=True))


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="shelf-demo", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--policy", default=None,
                   help=f"a PixelDoubleDQN zip, h-a or h-d (default: the first of {', '.join(DEFAULT_POLICIES)})")
    p.add_argument("--n", type=int, default=3, help="number of objects (1..14; default 3)")
    p.add_argument("--seed", type=int, default=0, help="which held-out scene (>= 0)")
    p.add_argument("--object-set", choices=["ycb", "train"], default="ycb",
                   help="unseen YCB objects (default) or the training objects")
    p.add_argument("--out", type=pathlib.Path, default=pathlib.Path("runs/demo.gif"),
                   help="the GIF to write (default runs/demo.gif, outside the tracked files)")
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        policy = args.policy if args.policy is not None else default_policy()
        if policy == "random":
            raise ValueError("shelf-demo shows a PixelDoubleDQN zip, h-a or h-d, not random")
        ev.check_policy(policy)
        ev.check_ns([args.n])
        if args.seed < 0:
            raise ValueError(f"--seed must be >= 0, got {args.seed}")
        if args.out.suffix.lower() != ".gif":
            raise ValueError(f"--out must name a .gif file, got {args.out}")
    except ValueError as err:
        print(f"shelf-demo: error: {err}", file=sys.stderr)
        return 2
    if args.policy is None:
        print(f"policy: {policy}")
    import torch

    torch.set_num_threads(1)
    run(policy, args.n, args.seed, args.object_set, args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
