"""The robot (§IV-B): the UR5 with its blade and suction cup (`arm`), its closed-form kinematics
(`kinematics`), the push and pick-and-place primitives as the paper runs them, open loop
(`primitives`), and the place heuristic that chooses where a picked object goes (`placement`)."""

from shelf_env.robot.arm import MotionConfig, Robot, carry_height
from shelf_env.robot.placement import place_position
from shelf_env.robot.primitives import Grasp, Primitives

__all__ = ["Grasp", "MotionConfig", "Primitives", "Robot", "carry_height", "place_position"]
