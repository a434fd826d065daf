"""The paper's heuristic baselines (§V-b), H-d and H-a, and a random policy (`heuristics`): SB3's
``predict`` signature, reading only the observation."""

from shelf_env.baselines.heuristics import AccessibilityHeuristic, DistanceHeuristic, ObservationView, RandomPolicy

__all__ = ["AccessibilityHeuristic", "DistanceHeuristic", "ObservationView", "RandomPolicy"]
