"""Constants of the paper and of our simulated set-up, in one place.

Every value here is a named default: the classes that use it take it as an overridable
argument. Paper section in brackets.
"""

from __future__ import annotations

# Cabinet interior [§IV-D.3]: x = depth (0 at the open front, + into the cabinet),
# y = width (+ is the camera's left), z = up (0 on the cabinet floor).
CABINET_DEPTH = 0.40
CABINET_WIDTH = 0.60
CABINET_HEIGHT = 0.27
WALL_THICKNESS = 0.02
# The cabinet stands on a stand; the ground outside is this far below its floor, so an object
# that leaves the cabinet lands, is detected and removed.
GROUND_Z = -0.45

NUM_CLASSES = 3
CLASS_NAMES = ("green", "yellow", "blue")

# Primitives [§IV-B]
PUSH_LENGTH = 0.08  # l_p
PUSH_HEIGHT = 0.05  # z_p: height of the blade's middle above the cabinet floor

# Episode [§IV-D, §V-c]
MAX_ACTIONS = 40
MAX_OBJECTS = 14
REWARD_INVALID = -10.0
REWARD_SORTED = 0.0
REWARD_STEP = -1.0

# Target regions (ours; the paper says only "randomly located"): every region is a rectangle
# REGION_WIDTH wide (along y) whose depth is drawn so that its class's objects cover at most
# REGION_MAX_FILL of it; see `shelf_env.world.cabinet.sample_regions`.
REGION_WIDTH = 0.18
REGION_MIN_DEPTH = 0.16
REGION_MAX_FILL = 0.5

# Observation
PIXEL_SIZE = 0.005  # metres per heightmap cell: 80 x 120 for the cabinet

# Physics
TIME_STEP = 1.0 / 240.0
SETTLE_MAX_STEPS = 240  # 1 s cap for objects to come to rest after a motion
REST_LINEAR_SPEED = 0.02  # m/s: slower than this counts as resting
REST_ANGULAR_SPEED = 0.5  # rad/s
