"""Roll out a scripted policy in ShelfSort-v0 and save the scene next to its heightmap.

    python examples/demo.py [--num-objects 5] [--steps 8] [--seed 0] [--out docs/scene_and_heightmap.png]

The scripted policy sees only the observation, like a learned one: it picks the class-coloured
pixel farthest from the centroid of the visible floor tinted for that class (the env's place
heuristic then puts the object in its region). Later issues replace it with a trained model.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import gymnasium as gym
import numpy as np

import shelf_env  # noqa: F401  (registers ShelfSort-v0)
from shelf_env.camera.heightmap import CLASS_RGB, REGION_RGB
from shelf_env.world.objects import OBJECT_SETS


def scripted_pick(obs: np.ndarray) -> int:
    """Flat pick action (map 0) for the object pixel farthest from its class's tinted region."""
    rgb = obs[:3].transpose(1, 2, 0).astype(int)
    best, best_d = None, -1.0
    for k in range(len(CLASS_RGB)):
        obj = np.argwhere((rgb == CLASS_RGB[k]).all(-1))
        region = np.argwhere((rgb == REGION_RGB[k]).all(-1))
        if len(obj) == 0:
            continue
        centre = region.mean(0) if len(region) else np.array(obs.shape[1:]) / 2
        d = np.linalg.norm(obj - centre, axis=1)
        i = int(np.argmax(d))
        if d[i] > best_d:
            best, best_d = obj[i], float(d[i])
    if best is None:
        return 0
    return int(best[0] * obs.shape[2] + best[1])


def side_by_side(scene: np.ndarray, obs: np.ndarray) -> np.ndarray:
    """Scene image (H, W, 3) and the heightmap's colours, scaled to the same height."""
    hm = obs[:3].transpose(1, 2, 0)
    scale = scene.shape[0] / hm.shape[0]
    hm = cv2.resize(hm, (int(hm.shape[1] * scale), scene.shape[0]), interpolation=cv2.INTER_NEAREST)
    gap = np.full((scene.shape[0], 12, 3), 255, np.uint8)
    return np.concatenate([scene, gap, hm], axis=1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--num-objects", type=int, default=5)
    ap.add_argument("--object-set", default="train", choices=list(OBJECT_SETS))
    ap.add_argument("--steps", type=int, default=8)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="docs/scene_and_heightmap.png")
    args = ap.parse_args()

    env = gym.make("ShelfSort-v0", num_objects=args.num_objects, object_set=args.object_set,
                   render_mode="rgb_array")
    obs, info = env.reset(seed=args.seed)
    first = side_by_side(env.render(), obs)
    total = 0.0
    for t in range(args.steps):
        obs, reward, terminated, truncated, info = env.step(scripted_pick(obs))
        total += reward
        print(f"step {t + 1}: reward {reward:+.0f}  sorted {info['num_sorted']}/{info['num_objects']}"
              f"  fell {info['fell']}")
        if terminated or truncated:
            break
    last = side_by_side(env.render(), obs)
    env.close()
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    picture = np.concatenate([first, np.full((12, first.shape[1], 3), 255, np.uint8), last], axis=0)
    cv2.imwrite(str(out), cv2.cvtColor(picture, cv2.COLOR_RGB2BGR))
    print(f"return {total:+.0f}, success {info['is_success']}; wrote {out} (top: start, bottom: end)")


if __name__ == "__main__":
    main()
