"""The physical world: cabinet, ground, objects and their target regions.

`World` owns one PyBullet client. It builds the static cabinet once, and on every
:meth:`World.spawn` removes the previous objects and creates new ones, so the body count of the
client stays constant over any number of episodes. Collision shapes are cached per shape and size
(PyBullet cannot free a collision shape once a body has used it), which is why training sizes are
drawn on a 2.5 mm grid (`shelf_env.world.objects.SIZE_GRID`).

Definitions used by the reward and the tests:

- An object is *inside* the cabinet when its base position lies in the interior box
  (0 <= x <= depth, |y| <= width/2, -1 cm <= z <= height).
- An object is *in region k* when it is inside and the (x, y) of its base position lies in the
  closed rectangle of region k. (The base position is the centre of the object's bounding box.)
- An object is *at rest* when its linear speed is below REST_LINEAR_SPEED and its angular speed
  below REST_ANGULAR_SPEED.
- The scene is *valid* when every object is inside and at rest; *sorted* when it is valid and
  every object is in the region of its own class.

Sleeping (speed, not physics): with ``sleeping=True`` (the default) objects use Bullet's
deactivation. Before each primitive the env puts every object at rest to sleep
(:meth:`World.sleep_resting`); a sleeping object costs almost nothing per physics step and is
woken by any contact with an awake body (the tool, a held or a moving object), or when an object
it touches is woken. A woken object only falls asleep again after two seconds below
REST_LINEAR_SPEED. Resting contacts of untouched objects otherwise dominate the step cost
(`benchmarks/sleeping.py` measures the effect per action);
`tests/test_primitives.py::test_sleeping_objects_move_as_awake_ones` checks that a push and a pick
move sleeping objects as they move awake ones.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pybullet as pb

from shelf_env import params
from shelf_env.world.objects import ObjectSpec, mesh_path


@dataclass(frozen=True)
class Region:
    """Axis-aligned rectangle on the cabinet floor: x in [x0, x1], y in [y0, y1]."""

    x0: float
    x1: float
    y0: float
    y1: float

    def contains(self, x: float, y: float) -> bool:
        return self.x0 <= x <= self.x1 and self.y0 <= y <= self.y1

    @property
    def centre(self) -> tuple[float, float]:
        return (self.x0 + self.x1) / 2, (self.y0 + self.y1) / 2


def is_at_rest(client: int, uid: int) -> bool:
    """Is body ``uid`` at rest: slower than REST_LINEAR_SPEED and REST_ANGULAR_SPEED (module docstring)?"""
    lin, ang = pb.getBaseVelocity(uid, physicsClientId=client)
    return bool(np.linalg.norm(lin) < params.REST_LINEAR_SPEED and np.linalg.norm(ang) < params.REST_ANGULAR_SPEED)


@dataclass(frozen=True)
class Physics:
    """How much simulation an action gets: speed, with outcomes equal up to Bullet's chaos.

    ``solver_iterations``: at most this many sequential-impulse sweeps per physics step over the
    contacts, the arm's motors and the suction constraint; ``solver_residual``: stop sweeping once
    a sweep's largest squared velocity correction is below it (m²/s²). ``skip_free_motion``: do not
    simulate the parts of the arm's motions where nothing can happen (`shelf_env.robot.arm.Robot.move_linear`).

    ``PHYSICS["reference"]`` is PyBullet's default solver (50 sweeps, 1e-7: in practice always 50)
    with every motion simulated: the physics of every result before 2026-11-23.
    ``PHYSICS["fast"]``, the default, is what `benchmarks/env_step.py --compare` measured as
    cheaper with the same outcomes on a fixed scene set (`benchmarks/physics_outcomes.py`).
    """

    solver_iterations: int
    solver_residual: float
    skip_free_motion: bool

    def __post_init__(self) -> None:
        if isinstance(self.solver_iterations, bool) or not isinstance(self.solver_iterations, int) \
                or self.solver_iterations < 1:
            raise ValueError(f"solver_iterations must be a positive integer, got {self.solver_iterations!r}")
        if not self.solver_residual >= 0:
            raise ValueError(f"solver_residual must be >= 0, got {self.solver_residual!r}")

    @classmethod
    def named(cls, physics: str | Physics) -> Physics:
        """A `Physics` from a name in `PHYSICS` (or an instance, returned as is)."""
        if isinstance(physics, Physics):
            return physics
        if physics not in PHYSICS:
            raise ValueError(f"unknown physics {physics!r}; expected one of {sorted(PHYSICS)} or a Physics")
        return PHYSICS[physics]

    @classmethod
    def parse(cls, text: str) -> Physics:
        """A name of `PHYSICS`, or ``ITERATIONS:RESIDUAL:SKIP`` (SKIP 0 or 1), as benchmarks take it."""
        if ":" not in text:
            return cls.named(text)
        parts = text.split(":")
        if len(parts) != 3 or parts[2] not in ("0", "1"):
            raise ValueError(f"physics {text!r} is not a name or ITERATIONS:RESIDUAL:SKIP (SKIP 0 or 1)")
        try:
            return cls(int(parts[0]), float(parts[1]), parts[2] == "1")
        except ValueError as err:
            raise ValueError(f"physics {text!r}: {err}") from None


PHYSICS: dict[str, Physics] = {
    "reference": Physics(solver_iterations=50, solver_residual=1e-7, skip_free_motion=False),
    "fast": Physics(solver_iterations=20, solver_residual=1e-5, skip_free_motion=True),
}


@dataclass
class PlacedObject:
    """An object body in the world, with its class."""

    uid: int
    spec: ObjectSpec
    cls: int


def obb_corners(x: float, y: float, yaw: float, footprint: tuple[float, float]) -> np.ndarray:
    """Corners (4, 2) of an object's footprint rectangle at (x, y) rotated by ``yaw``."""
    hx, hy = footprint[0] / 2, footprint[1] / 2
    c, s = np.cos(yaw), np.sin(yaw)
    local = np.array([[hx, hy], [-hx, hy], [-hx, -hy], [hx, -hy]])
    return local @ np.array([[c, s], [-s, c]]) + np.array([x, y])


def obbs_overlap(a: np.ndarray, b: np.ndarray) -> bool:
    """Separating-axis test for two convex quadrilaterals given by their corners."""
    for poly in (a, b):
        for i in range(4):
            edge = poly[(i + 1) % 4] - poly[i]
            axis = np.array([-edge[1], edge[0]])
            pa, pb_ = a @ axis, b @ axis
            if pa.max() < pb_.min() or pb_.max() < pa.min():
                return False
    return True


def sample_regions(
    rng: np.random.Generator,
    class_area: np.ndarray,
    depth: float = params.CABINET_DEPTH,
    width: float = params.CABINET_WIDTH,
    region_width: float = params.REGION_WIDTH,
    min_depth: float = params.REGION_MIN_DEPTH,
    max_fill: float = params.REGION_MAX_FILL,
) -> list[Region] | None:
    """Draw one target region per class, or None if some class cannot fit its objects.

    The classes get a random left-to-right order; the spare width (cabinet width minus the
    regions' widths) is split at random into the four gaps beside and between the regions.
    Region k's depth is uniform in [max(min_depth, need_k), depth] where
    need_k = class_area[k] / (max_fill * region_width), so its objects cover at most
    ``max_fill`` of it; its front edge is uniform over the positions that keep it inside.
    """
    n = len(class_area)
    need = class_area / (max_fill * region_width)
    if (need > depth).any():
        return None
    spare = width - n * region_width
    gaps = rng.dirichlet(np.ones(n + 1)) * spare
    order = rng.permutation(n)
    regions: list[Region | None] = [None] * n
    y_left = width / 2  # +y is the camera's left; regions are laid out from left to right
    for slot, cls in enumerate(order):
        y_left -= gaps[slot]
        d = rng.uniform(max(min_depth, need[cls]), depth)
        x0 = rng.uniform(0.0, depth - d)
        regions[cls] = Region(float(x0), float(x0 + d), float(y_left - region_width), float(y_left))
        y_left -= region_width
    return regions  # type: ignore[return-value]


class World:
    """A PyBullet client holding the cabinet, the ground and the current objects."""

    def __init__(self, client: int, sleeping: bool = True, physics: str | Physics = "fast") -> None:
        self.client = client
        self.sleeping = bool(sleeping)
        solver = Physics.named(physics)  # the robot reads skip_free_motion; the world sets the solver
        pb.setGravity(0, 0, -9.81, physicsClientId=client)
        pb.setTimeStep(params.TIME_STEP, physicsClientId=client)
        pb.setPhysicsEngineParameter(numSolverIterations=solver.solver_iterations,
                                     solverResidualThreshold=solver.solver_residual,
                                     physicsClientId=client)
        self._shape_cache: dict[tuple, int] = {}
        self.static_uids: list[int] = []
        self._build_static()
        self.objects: list[PlacedObject] = []
        self.regions: list[Region] = []

    # ---- static scene -------------------------------------------------------------------
    def _box(self, half: tuple[float, float, float], pos: tuple[float, float, float], rgba) -> int:
        col = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=half, physicsClientId=self.client)
        vis = pb.createVisualShape(pb.GEOM_BOX, halfExtents=half, rgbaColor=rgba, physicsClientId=self.client)
        uid = pb.createMultiBody(0, col, vis, pos, physicsClientId=self.client)
        pb.changeDynamics(uid, -1, lateralFriction=0.5, physicsClientId=self.client)
        self.static_uids.append(uid)
        return uid

    def _build_static(self) -> None:
        d, w, h, t = params.CABINET_DEPTH, params.CABINET_WIDTH, params.CABINET_HEIGHT, params.WALL_THICKNESS
        wood = (0.72, 0.58, 0.42, 1.0)
        inner = (0.85, 0.82, 0.78, 1.0)
        self.floor_uid = self._box((d / 2, w / 2 + t, t / 2), (d / 2, 0, -t / 2), inner)
        self.wall_uids = (
            self._box((d / 2, w / 2 + t, t / 2), (d / 2, 0, h + t / 2), wood),  # ceiling
            self._box((t / 2, w / 2 + t, h / 2 + t), (d + t / 2, 0, h / 2), wood),  # back
            self._box((d / 2, t / 2, h / 2 + t), (d / 2, w / 2 + t / 2, h / 2), wood),  # left (+y)
            self._box((d / 2, t / 2, h / 2 + t), (d / 2, -w / 2 - t / 2, h / 2), wood),  # right (-y)
        )
        stand_h = -params.GROUND_Z - t
        stand_rgba = (0.4, 0.4, 0.42, 1.0)
        stand = self._box((d / 2, w / 2, stand_h / 2), (d / 2, 0, -t - stand_h / 2), stand_rgba)
        ground = pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=self.client)
        self.ground_uid = pb.createMultiBody(0, ground, -1, (0, 0, params.GROUND_Z), physicsClientId=self.client)
        ground_rgba = (0.55, 0.57, 0.6, 1.0)
        pb.changeVisualShape(self.ground_uid, -1, rgbaColor=ground_rgba, physicsClientId=self.client)
        self.static_uids.append(self.ground_uid)
        # below the cabinet floor: never seen through the opening (see HeightmapCamera)
        self.decorative = ((stand, stand_rgba), (self.ground_uid, ground_rgba))

    # ---- objects ------------------------------------------------------------------------
    def _collision_shape(self, spec: ObjectSpec) -> int:
        key = (spec.kind, spec.shape, spec.size)
        if key in self._shape_cache:
            return self._shape_cache[key]
        c = self.client
        sx, sy, sz = spec.size
        if spec.shape == "box":
            col = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=(sx / 2, sy / 2, sz / 2), physicsClientId=c)
        elif spec.shape == "cylinder":
            col = pb.createCollisionShape(pb.GEOM_CYLINDER, radius=sx / 2, height=sz, physicsClientId=c)
        elif spec.shape == "mesh":
            if spec.mesh is None:
                raise ValueError(f"object {spec.kind!r} has shape 'mesh' but names no mesh file")
            col = pb.createCollisionShape(pb.GEOM_MESH, fileName=mesh_path(spec.mesh), physicsClientId=c)
        elif spec.shape == "mug":
            r, reach, hh = spec.extra["radius"], spec.extra["handle_reach"], spec.extra["handle_height"]
            body_y = -sy / 2 + r
            bar = 0.008
            col = pb.createCollisionShapeArray(
                shapeTypes=[pb.GEOM_CYLINDER, pb.GEOM_BOX, pb.GEOM_BOX, pb.GEOM_BOX],
                radii=[r, 0, 0, 0],
                lengths=[sz, 0, 0, 0],
                halfExtents=[[0, 0, 0], [bar, reach / 2, bar], [bar, reach / 2, bar], [bar, bar, hh / 2]],
                collisionFramePositions=[
                    [0, body_y, 0],
                    [0, body_y + r + reach / 2 - bar, hh / 2 - bar],
                    [0, body_y + r + reach / 2 - bar, -hh / 2 + bar],
                    [0, sy / 2 - bar, 0],
                ],
                physicsClientId=c,
            )
        else:
            raise ValueError(f"unknown object shape {spec.shape!r}")
        self._shape_cache[key] = col
        return col

    def add_object(self, spec: ObjectSpec, cls: int, x: float, y: float, yaw: float) -> PlacedObject:
        """Create one object body resting on the cabinet floor at (x, y) with heading ``yaw``."""
        col = self._collision_shape(spec)
        orn = pb.getQuaternionFromEuler((0, 0, yaw))
        uid = pb.createMultiBody(
            spec.mass, col, -1, (x, y, spec.height / 2 + 0.0005), orn, physicsClientId=self.client
        )
        pb.changeVisualShape(uid, -1, rgbaColor=spec.rgba, physicsClientId=self.client)
        pb.changeDynamics(
            uid, -1, lateralFriction=0.5, spinningFriction=0.001, rollingFriction=0.0001,
            restitution=0.0, physicsClientId=self.client,
        )
        if self.sleeping:
            # sleepThreshold is on the squared speed: asleep only after 2 s below REST_LINEAR_SPEED
            pb.changeDynamics(uid, -1, activationState=pb.ACTIVATION_STATE_ENABLE_SLEEPING,
                              sleepThreshold=params.REST_LINEAR_SPEED ** 2, physicsClientId=self.client)
        obj = PlacedObject(uid, spec, cls)
        self.objects.append(obj)
        return obj

    def clear_objects(self) -> None:
        for obj in self.objects:
            pb.removeBody(obj.uid, physicsClientId=self.client)
        self.objects = []

    def remove_object(self, obj: PlacedObject) -> None:
        pb.removeBody(obj.uid, physicsClientId=self.client)
        self.objects.remove(obj)

    def sample_layout(
        self, specs: list[ObjectSpec], rng: np.random.Generator, clearance: float = 0.005,
        margin: float = 0.01, tries_per_object: int = 300,
    ) -> list[tuple[float, float, float]] | None:
        """Random non-overlapping (x, y, yaw) for every spec, or None if they did not fit.

        Larger footprints are placed first; every footprint rectangle (grown by ``clearance``)
        stays ``margin`` away from the walls and apart from the others.
        """
        d, w = params.CABINET_DEPTH, params.CABINET_WIDTH
        order = np.argsort([-s.footprint_area for s in specs])
        placed: list[np.ndarray] = []
        poses: list[tuple[float, float, float] | None] = [None] * len(specs)
        for i in order:
            spec = specs[i]
            grown = (spec.footprint[0] + clearance, spec.footprint[1] + clearance)
            for _ in range(tries_per_object):
                yaw = float(rng.uniform(-np.pi, np.pi)) if spec.can_yaw else 0.0
                x = float(rng.uniform(0, d))
                y = float(rng.uniform(-w / 2, w / 2))
                corners = obb_corners(x, y, yaw, grown)
                if (corners[:, 0].min() < margin or corners[:, 0].max() > d - margin
                        or corners[:, 1].min() < -w / 2 + margin or corners[:, 1].max() > w / 2 - margin):
                    continue
                if any(obbs_overlap(corners, other) for other in placed):
                    continue
                placed.append(corners)
                poses[i] = (x, y, yaw)
                break
            else:
                return None
        return poses  # type: ignore[return-value]

    # ---- state --------------------------------------------------------------------------
    def pose(self, obj: PlacedObject) -> tuple[np.ndarray, np.ndarray]:
        pos, orn = pb.getBasePositionAndOrientation(obj.uid, physicsClientId=self.client)
        return np.asarray(pos), np.asarray(orn)

    def positions(self) -> np.ndarray:
        """Base positions (N, 3) of the current objects."""
        if not self.objects:
            return np.zeros((0, 3))
        return np.array([pb.getBasePositionAndOrientation(o.uid, physicsClientId=self.client)[0]
                         for o in self.objects])

    @staticmethod
    def inside(pos: np.ndarray) -> np.ndarray:
        """Boolean per position: is it in the cabinet's interior box?"""
        pos = np.atleast_2d(pos)
        return ((pos[:, 0] >= 0) & (pos[:, 0] <= params.CABINET_DEPTH)
                & (np.abs(pos[:, 1]) <= params.CABINET_WIDTH / 2)
                & (pos[:, 2] >= -0.01) & (pos[:, 2] <= params.CABINET_HEIGHT))

    def at_rest(self) -> np.ndarray:
        """Boolean per object: is it at rest (see module docstring)?"""
        return np.array([is_at_rest(self.client, o.uid) for o in self.objects], dtype=bool)

    def sleep_resting(self) -> None:
        """Put every object at rest to sleep (no-op unless ``sleeping``); see module docstring."""
        if not self.sleeping:
            return
        for obj, resting in zip(self.objects, self.at_rest()):
            if resting:
                pb.changeDynamics(obj.uid, -1, activationState=pb.ACTIVATION_STATE_SLEEP,
                                  physicsClientId=self.client)

    def region_of(self, pos: np.ndarray) -> np.ndarray:
        """Index of the region holding each position's (x, y), or -1 for none."""
        pos = np.atleast_2d(pos)
        out = np.full(len(pos), -1)
        for k, reg in enumerate(self.regions):
            hit = ((pos[:, 0] >= reg.x0) & (pos[:, 0] <= reg.x1)
                   & (pos[:, 1] >= reg.y0) & (pos[:, 1] <= reg.y1) & self.inside(pos))
            out[hit & (out < 0)] = k
        return out

    def classes(self) -> np.ndarray:
        return np.array([o.cls for o in self.objects], dtype=int)

    def in_own_region(self, pos: np.ndarray | None = None) -> np.ndarray:
        pos = self.positions() if pos is None else pos
        return self.region_of(pos) == self.classes()

    def settle(self, max_steps: int = params.SETTLE_MAX_STEPS, check_every: int = 10,
               step_fn=None) -> int:
        """Step physics until every object is at rest (or ``max_steps``); returns steps taken."""
        step = step_fn or (lambda: pb.stepSimulation(physicsClientId=self.client))
        n = 0
        while n < max_steps:
            for _ in range(check_every):
                step()
            n += check_every
            if self.at_rest().all():
                break
        return n
