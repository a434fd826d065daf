"""shelf_env: the confined-shelf sorting world of "Learning to Rearrange Objects in Confined
Environments" in Gymnasium + PyBullet. ``gym.make("ShelfSort-v0", num_objects=N, ...)``."""

from gymnasium.envs.registration import register

from shelf_env.env import ShelfSortEnv, map_names

__all__ = ["ShelfSortEnv", "map_names"]
__version__ = "0.1.0"

register(id="ShelfSort-v0", entry_point="shelf_env.env:ShelfSortEnv")
