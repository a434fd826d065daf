"""Conditions beyond the paper's task, each chosen at the env's construction and off by default:
the closed loop (`closed_loop`: watched primitives, ``closed_loop=``), safe picks (`safe_picks`:
masks without carries through taller neighbours, ``safe_picks=``) and perception noise
(`perception_noise`, ``perception_noise=``)."""

from shelf_env.conditions.closed_loop import DragWatch, WatchedPrimitives
from shelf_env.conditions.perception_noise import PerceptionNoise
from shelf_env.conditions.safe_picks import carry_clear, carry_path

__all__ = ["DragWatch", "PerceptionNoise", "WatchedPrimitives", "carry_clear", "carry_path"]
