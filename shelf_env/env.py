"""`ShelfSort-v0`: sort N objects of 3 classes into their target regions in a cabinet.

Observation ``Box(0, 255, (4, H, W), uint8)``: the recoloured top-down heightmap of §IV-A
(R, G, B, height over the cabinet height). Rows run from the back of the cabinet (row 0) to the
front, columns from the camera's left (col 0) to its right. With the default 5 mm cells,
H x W = 80 x 120: 5 mm is the finest size at which the 640 x 480 camera still samples every
cell of an empty cabinet, and it keeps the smallest objects (4 cm) 8 cells wide; coarser maps
lose object edges and finer ones cost the FCN quadratically more on CPU.

Action ``Discrete(n_maps * H * W)``: ``a = m * H * W + row * W + col``. Maps, in order:

- ``primitives=("pick", "push")`` (P+S, default): 0 pick-and-place, 1 push-left, 2 push-right;
- ``primitives=("pick",)`` (S): 0 pick-and-place.

Push-left moves the blade towards the camera's left (+y, decreasing col), push-right towards
its right. The cell centre is the push's start or the pick point; targets are kept 2 cm short of
the back wall and 8 mm from the side walls, where the blade's tip and thickness would hit them.

Reward (Eq. 2): -10 if the step leaves the scene invalid (an object outside the cabinet, or not
at rest 1 s after the motion), 0 if it reaches the sorted state, -1 otherwise. ``terminated`` on
sorted or invalid, ``truncated`` after ``max_actions`` actions. See `shelf_env.world.cabinet` for the
exact definitions of inside, at rest and in-region.

Action masks (sb3-contrib's convention): `ShelfSortEnv.action_masks` marks the picks and pushes
that can touch a visible object; at an episode's end ``info["action_mask"]`` holds the mask of the
final observation (a VecEnv resets before anyone could ask for it).

Hindsight protocol (§IV-D.3, read by `sb3_pixeldqn.HindsightRelabelReplayBuffer`): when a step
ends valid with every object inside some target region but not all in their own,
``info["relabelled"]`` holds ``{"obs", "next_obs", "reward", "terminated"}``: both observations
recoloured with every object's class replaced by the class of the region it is in, reward 0,
terminated True. The action is unchanged.

``perception_noise`` (off by default; `shelf_env.conditions.perception_noise`): segmentation dropout of whole
objects or parts, class flips and depth noise on every capture, seeded per episode; the policy's
observation, the masks and the env's own planning see the noisy map, rewards the true state.

``closed_loop=True`` (off by default, as in the paper): before the pick's carry out of the opening,
the heightmap says whether the carried object clears its neighbours; if not, it is carried sideways
to the nearest clear way out, or put back where it was picked when there is none. During the
carry the cup's force sensor and a small camera image watch for a dragged neighbour, and a drag
they catch makes the robot carry the object back and put it down. When the place's descent stops
on other objects near the opening, the object is not released there but placed again further in
(`shelf_env.conditions.closed_loop.DragWatch`; a dict of its fields or a DragWatch tunes it); ``info["interventions"]``
lists what it did. With ``safe_picks=True`` as well (the setting to use for the fewest falls) it
cuts the episodes with a fall at N = 8..14 by 76 % (H-a), 75 % (H-d) and 60 % (the shipped P+S)
and sorts more at N = 3..5, on issue 10's YCB grid (`results/closed_loop/on_deeper_safe_table.md`).
It stays off by default: the paper's task is open loop (issue 10's evaluation and the shipped
models), and watching costs 1.5-3x the time per action (`benchmarks/closed_loop.py`).

``safe_picks=True`` (off by default): `action_masks` leaves out the picks whose object would be
carried out of the opening through a taller visible neighbour (`shelf_env.conditions.safe_picks`), the motion
that drags most fallen objects out; the heuristics restrict their picks the same way.

``min_num_objects=k`` (None by default): each reset draws N uniformly from
[min(k, num_objects), num_objects] (`ShelfSortEnv.episode_size`, from the env's seeded stream)
instead of always playing ``num_objects``, which a curriculum (`set_num_objects`) then moves as
the upper end: training on a mix of sizes so that the low N are not forgotten at a high stage
(`shelf_env.training.config.TrainConfig.min_num_objects`). ``info["num_objects"]`` gives each
episode's N.

``progress_reward=c`` (0 by default: the paper's reward, unchanged): a valid step's reward gains
``c`` per object that it brought into its own class's region and loses ``c`` per object that it
took out of it (``c * Δ info["num_sorted"]``); an invalid step's reward stays -10. The relabelled
transition gains ``c`` per object whose region the step changed (its progress under the relabelled
classes). Why: with γ = 0.9 and -1 per step, one more step to go changes a state's value by
0.9^k, under 0.1 once the sorted state is more than ~20 steps away, which is where N = 10..14 start;
the bonus makes each object sorted visible in the step that sorts it. It is a training signal
only: success, the evaluation and the heuristics do not read rewards.

``invalid_reward=r`` (-10 by default: the paper's Eq. 2, unchanged) is the reward of a step that ends
the episode invalid (an object fell out, the scene did not come to rest). Why: with γ = 0.9 the
paper's -10 is exactly -1 / (1 - γ), the value of never finishing, so for a Q-function that is
right a step that risks a fall with probability p beats a safe step that costs one more action
whenever p < 1 - γ = 10 %, at every N (the safe step costs γ^(k-1) when k actions are left, the
fall 10 γ^(k-1) more than the risky step's success). Over the 14+ actions of a large scene, 10 %
per action ends three episodes in four with a fall. A harsher ``r`` lowers that threshold to
γ^(k-1) / (V_k - r) (V_k = -(1 - γ^(k-1)) / (1 - γ), the value with k actions left): with 3 to 15
actions left, 2.9-1.0 % at r = -30 and 0.8-0.25 % at r = -100. A training signal only, like
``progress_reward``.

``sleeping=True`` (default) lets objects at rest sleep in Bullet between contacts, which makes
actions cheaper with many objects (`benchmarks/sleeping.py`); ``sleeping=False`` simulates every object at every physics
step (see `shelf_env.world.cabinet`).

``physics="fast"`` (default; `shelf_env.world.cabinet.Physics`) caps Bullet's constraint solver at 20
sweeps with an early exit and does not simulate the arm's motion where nothing can happen;
``physics="reference"`` simulates every motion with PyBullet's default solver, the physics of
every result before 2026-11-23. ``benchmarks/env_step.py --compare`` measures both.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from numbers import Integral, Real
from typing import Any

import gymnasium as gym
import numpy as np
import pybullet as pb

from shelf_env import params
from shelf_env.actions import PRIMITIVES, ActionCodec, clip_target, map_names, occupancy_masks
from shelf_env.camera.heightmap import CLASS_RGB, CameraConfig, HeightmapCamera, recolour, region_masks
from shelf_env.conditions.closed_loop import DragWatch, WatchedPrimitives
from shelf_env.conditions.perception_noise import PerceptionNoise
from shelf_env.conditions.safe_picks import carry_clear, carry_path
from shelf_env.robot.arm import Robot, carry_height
from shelf_env.robot.placement import place_position
from shelf_env.robot.primitives import Primitives
from shelf_env.world import task
from shelf_env.world.cabinet import Physics, Region, World, sample_regions
from shelf_env.world.objects import OBJECT_SETS, ObjectSpec, sample_specs

SPAWN_TRIES = 100
#: What (scene seed, actions) produce: bump it whenever a change alters any episode's observations,
#: rewards or infos, so that data labelled by an older env (`shelf_env.privileged.dataset`) is refused.
DYNAMICS_VERSION = 1
__all__ = ["PRIMITIVES", "ShelfSortEnv", "map_names"]


def check_progress_reward(value: float) -> float:
    """``value`` as the env's ``progress_reward`` (a finite number >= 0), or ValueError naming it."""
    if isinstance(value, bool) or not isinstance(value, Real) or not math.isfinite(value) or value < 0:
        raise ValueError(f"progress_reward must be a finite number >= 0, got {value!r}")
    return float(value)


def check_invalid_reward(value: float) -> float:
    """``value`` as the env's ``invalid_reward`` (a finite number < 0), or ValueError naming it."""
    if isinstance(value, bool) or not isinstance(value, Real) or not math.isfinite(value) or value >= 0:
        raise ValueError(f"invalid_reward must be a finite number < 0, got {value!r}")
    return float(value)


def check_object_count(n: Any, maximum: int, name: str = "num_objects") -> int:
    """``n`` as an int when it is an integer in [1, ``maximum``]; a `ValueError` naming ``name`` otherwise."""
    if isinstance(n, bool) or not isinstance(n, Integral):
        raise ValueError(f"{name} must be an integer, got {n!r}")
    if not 1 <= int(n) <= maximum:
        raise ValueError(f"{name} must be in [1, {maximum}], got {n}")
    return int(n)


class ShelfSortEnv(gym.Env):
    """Gymnasium env of the confined-shelf sorting task (see module docstring)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 2}
    observation_space: gym.spaces.Box
    action_space: gym.spaces.Discrete
    client: int | None
    perception_noise: PerceptionNoise | None
    drag_watch: DragWatch | None
    _noise_rng: np.random.Generator | None
    max_objects: int
    num_objects: int
    min_num_objects: int | None
    object_set: str
    primitives: tuple[str, ...]
    map_names: list[str]
    max_actions: int
    render_mode: str | None
    sleeping: bool
    physics: Physics
    world: World
    robot: Robot
    primitive_runner: Primitives
    camera: HeightmapCamera
    watch_camera: HeightmapCamera | None
    codec: ActionCodec
    rows: int
    cols: int
    action_count: int
    num_unsorted_initial: int
    episode_num_objects: int
    _regions_mask: np.ndarray
    _semantic: tuple[np.ndarray, np.ndarray] | None
    _obs: np.ndarray | None
    safe_picks: bool
    progress_reward: float
    invalid_reward: float
    _region_before: dict[int, int]
    _sorted_before: int

    def __init__(
        self,
        num_objects: int = 3,
        object_set: str = "train",
        primitives: tuple[str, ...] = ("pick", "push"),
        max_actions: int = params.MAX_ACTIONS,
        render_mode: str | None = None,
        pixel_size: float = params.PIXEL_SIZE,
        camera: CameraConfig | None = None,
        max_objects: int = params.MAX_OBJECTS,
        sleeping: bool = True,
        perception_noise: PerceptionNoise | dict | None = None,
        closed_loop: bool | dict[str, Any] | DragWatch = False,
        physics: str | Physics = "fast",
        safe_picks: bool = False,
        min_num_objects: int | None = None,
        progress_reward: float = 0.0,
        invalid_reward: float = params.REWARD_INVALID,
    ) -> None:
        if object_set not in OBJECT_SETS:
            raise ValueError(f"unknown object_set {object_set!r}; expected one of {OBJECT_SETS}")
        primitives = tuple(primitives)
        unknown = [p for p in primitives if p not in PRIMITIVES]
        if unknown or not primitives or len(set(primitives)) != len(primitives):
            raise ValueError(f"primitives must be distinct names from {PRIMITIVES}, got {primitives!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"unknown render_mode {render_mode!r}; expected one of {self.metadata['render_modes']}")
        if not isinstance(max_actions, Integral) or max_actions < 1:
            raise ValueError(f"max_actions must be a positive integer, got {max_actions!r}")
        if not 1 <= max_objects <= params.MAX_OBJECTS:
            raise ValueError(f"max_objects must be in [1, {params.MAX_OBJECTS}], got {max_objects}")
        if not 0.002 <= pixel_size <= 0.02:
            raise ValueError(f"pixel_size must be in [0.002, 0.02] m, got {pixel_size}")
        #: `shelf_env.conditions.perception_noise.PerceptionNoise` applied to every capture (None: exact perception).
        self.perception_noise = PerceptionNoise.from_any(perception_noise)
        #: `shelf_env.conditions.closed_loop.DragWatch` of the carried object (None: open loop, as in the paper).
        self.drag_watch = DragWatch.from_any(closed_loop)
        if not isinstance(safe_picks, bool):
            raise ValueError(f"safe_picks must be True or False, got {safe_picks!r}")
        #: Whether `action_masks` (and the heuristics) leave out picks whose carry is blocked.
        self.safe_picks = safe_picks
        #: Reward per object a valid step sorts (and minus per object it unsorts); 0: the paper's.
        self.progress_reward = check_progress_reward(progress_reward)
        #: Reward of a step that ends the episode invalid (the paper's: -10).
        self.invalid_reward = check_invalid_reward(invalid_reward)
        #: With a progress reward: each object's region (by uid) and the sorted count after the last step.
        self._region_before = {}
        self._sorted_before = 0
        self._noise_rng = None
        self.max_objects = int(max_objects)
        self.num_objects = check_object_count(num_objects, self.max_objects)
        if min_num_objects is not None:
            min_num_objects = check_object_count(min_num_objects, self.max_objects, "min_num_objects")
        #: Lower end of each reset's draw of N (None: every episode has ``num_objects`` objects).
        self.min_num_objects = min_num_objects
        self.object_set = object_set
        self.primitives = primitives
        self.map_names = map_names(primitives)
        self.max_actions = int(max_actions)
        self.render_mode = render_mode

        self.sleeping = bool(sleeping)
        #: How much is simulated (`shelf_env.world.cabinet.Physics`): "fast" (default) or "reference".
        self.physics = Physics.named(physics)
        self.client = pb.connect(pb.DIRECT)
        cfg = camera or CameraConfig()
        #: The closed loop's small camera (the same pose, a quarter of the resolution; None: open loop);
        #: `_build_world` gives it the world's bodies and hands it to the primitives.
        self.watch_camera = None if self.drag_watch is None else HeightmapCamera(
            self.client, dataclasses.replace(cfg, width=cfg.width // 4, height=cfg.height // 4), pixel_size)
        self._build_world()
        self.camera = HeightmapCamera(self.client, camera, pixel_size, hidden_bodies=self.world.decorative,
                                      wall_uids=self.world.wall_uids)
        #: The action codec (`shelf_env.actions`): index <-> (map, row, col) <-> cabinet (x, y).
        self.codec = ActionCodec(tuple(self.map_names), self.camera.rows, self.camera.cols, pixel_size)
        self.rows, self.cols = self.codec.rows, self.codec.cols
        self.observation_space = gym.spaces.Box(0, 255, (4, self.rows, self.cols), dtype=np.uint8)
        self.action_space = gym.spaces.Discrete(self.codec.n)
        self._regions_mask = np.zeros((params.NUM_CLASSES, self.rows, self.cols), dtype=bool)
        self._semantic: tuple[np.ndarray, np.ndarray] | None = None
        self._obs: np.ndarray | None = None
        self.action_count = 0
        self.num_unsorted_initial = 0
        self.episode_num_objects = 0

    # ---- configuration ----------------------------------------------------------------
    def set_num_objects(self, n: int) -> None:
        """Number of objects from the next reset on (for a curriculum); the upper end of the draw
        when ``min_num_objects`` is set."""
        self.num_objects = check_object_count(n, self.max_objects)

    def episode_size(self) -> int:
        """N of the next episode: ``num_objects``, or with ``min_num_objects`` set a uniform draw
        from [min(min_num_objects, num_objects), num_objects] from the env's own stream
        (``np_random``), so a seeded env replays the same sizes."""
        if self.min_num_objects is None:
            return self.num_objects
        low = min(self.min_num_objects, self.num_objects)
        return int(self.np_random.integers(low, self.num_objects + 1))

    # ---- episode ----------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, Integral) or seed < 0):
            raise ValueError(f"seed must be a non-negative integer or None, got {seed!r}")
        super().reset(seed=None if seed is None else int(seed))
        options = dict(options or {})
        unknown = set(options) - {"num_objects"}
        if unknown:
            raise ValueError(f"unknown reset options {sorted(unknown)}; known: ['num_objects']")
        if "num_objects" in options:
            self.set_num_objects(options["num_objects"])
        self._spawn(self.episode_size())
        return self._begin_episode()

    def _build_world(self) -> None:
        """An empty simulation with the cabinet and the robot at home, as in a fresh env.

        Called by every `reset` and `set_scene`, which is what makes episodes history-free: after
        ``resetSimulation`` the cabinet, the robot and then the objects are created in the same
        order, so they get the same body ids, and no contact cache, solver warm-start, sleeping
        state or collision shape survives from earlier episodes. Bullet is deterministic given
        the same bodies created in the same order, so an episode's observations, rewards and
        infos depend only on (scene, actions). It costs ~10 ms per reset
        (``benchmarks/reset_cost.py``).
        """
        if self.client is None:
            raise RuntimeError("this ShelfSortEnv is closed")
        pb.resetSimulation(physicsClientId=self.client)
        self.world = World(self.client, sleeping=self.sleeping, physics=self.physics)
        self.robot = Robot(self.client, skip_free_motion=self.physics.skip_free_motion)
        if self.drag_watch is None:  # the paper's open loop
            self.primitive_runner = Primitives(self.robot)
        else:  # the closed loop: the same primitives, watched (shelf_env.conditions.closed_loop)
            watched = WatchedPrimitives(self.robot, self.drag_watch,
                                        look=None if self.watch_camera is None else self.watch_camera.front_edges)
            if self.drag_watch.lane:
                watched.plan_carry = self._carry_shift
            if self.drag_watch.place_check:
                watched.plan_place = functools.partial(self._place_for, min_front=self.drag_watch.stack_front)
            self.primitive_runner = watched
        for camera in (getattr(self, "camera", None), self.watch_camera):
            if camera is not None:  # same bodies in the same order: same ids, but say so rather than assume
                camera.hidden_bodies = self.world.decorative
                camera.wall_uids = np.asarray(self.world.wall_uids, dtype=np.int64)

    def _clear_scene(self) -> None:
        self.robot.release()
        self.robot.go_home()
        self.world.clear_objects()

    def _begin_episode(self) -> tuple[np.ndarray, dict]:
        """Counters, masks and first observation of a freshly built scene (reset, set_scene)."""
        self._regions_mask = region_masks(self.world.regions, self.rows, self.cols, self.camera.pixel_size)
        self.action_count = 0
        # N of this episode: set_num_objects during an episode only affects the next reset
        self.episode_num_objects = len(self.world.objects)
        if self.perception_noise is not None and self.perception_noise.active:  # its own stream, per episode
            self._noise_rng = np.random.default_rng(int(self.np_random.integers(2**63)))
        judgement = task.judge(self.world)
        self.num_unsorted_initial = int((judgement.region != judgement.classes).sum())
        if self.progress_reward:
            self._region_before, self._sorted_before = self._region_of_uid(judgement), judgement.num_sorted
        self._obs = self._observe()
        return self._obs.copy(), self._info(None, judgement)

    def _spawn(self, n: int) -> None:
        rng = self.np_random
        self._build_world()
        for _ in range(SPAWN_TRIES):
            self._clear_scene()
            specs = sample_specs(self.object_set, n, rng)
            classes = rng.integers(0, params.NUM_CLASSES, size=n)
            area = np.array([sum(s.footprint_area for s, c in zip(specs, classes) if c == k)
                             for k in range(params.NUM_CLASSES)])
            regions = sample_regions(rng, area)
            if regions is None:
                continue
            layout = self.world.sample_layout(specs, rng)
            if layout is None:
                continue
            self.world.regions = regions
            for spec, cls, (x, y, yaw) in zip(specs, classes, layout):
                self._add_object(spec, int(cls), x, y, yaw)
            self.world.settle()
            pos = self.world.positions()
            if self.world.inside(pos).all() and self.world.at_rest().all() and not self.world.in_own_region(pos).all():
                return
        raise RuntimeError(f"could not spawn {n} {self.object_set!r} objects in {SPAWN_TRIES} tries")

    def _add_object(self, spec: ObjectSpec, cls: int, x: float, y: float, yaw: float) -> None:
        obj = self.world.add_object(spec, cls, x, y, yaw)
        # the person's view shows each object in its class colour, as in Fig. 7
        rgba = tuple(CLASS_RGB[cls] / 255.0) + (1.0,)
        pb.changeVisualShape(obj.uid, -1, rgbaColor=rgba, physicsClientId=self.client)

    def set_scene(self, objects: list[tuple[ObjectSpec, int, float, float, float]],
                  regions: list[Region]) -> tuple[np.ndarray, dict]:
        """Replace the episode's scene by a crafted one (for tests, demos and evaluation of
        hand-made cases): ``objects`` as (spec, class, x, y, yaw) resting on the floor,
        one :class:`Region` per class. Returns the new (observation, info), like reset."""
        if len(regions) != params.NUM_CLASSES:
            raise ValueError(f"need {params.NUM_CLASSES} regions, got {len(regions)}")
        if not 1 <= len(objects) <= self.max_objects:
            raise ValueError(f"need 1..{self.max_objects} objects, got {len(objects)}")
        bad = [cls for _, cls, *_ in objects if not 0 <= cls < params.NUM_CLASSES]
        if bad:
            raise ValueError(f"class must be in [0, {params.NUM_CLASSES}), got {bad[0]}")
        self._build_world()
        self.world.regions = list(regions)
        for spec, cls, x, y, yaw in objects:
            self._add_object(spec, int(cls), x, y, yaw)
        self.world.settle()
        return self._begin_episode()

    def _class_of_uid(self, classes: np.ndarray | None = None) -> dict[int, int]:
        classes = self.world.classes() if classes is None else classes
        return {o.uid: int(c) for o, c in zip(self.world.objects, classes)}

    def _observe(self) -> np.ndarray:
        uids = np.array([o.uid for o in self.world.objects], dtype=np.int64)
        cell_uid, height = self.camera.semantic_map(uids)
        shown = self._class_of_uid()
        if self._noise_rng is not None:
            assert self.perception_noise is not None
            cell_uid, height, shown = self.perception_noise.apply(cell_uid, height, shown, self._noise_rng)
        self._semantic = (cell_uid, height)
        return recolour(cell_uid, height, shown, self._regions_mask)

    def _observed_semantic(self) -> tuple[np.ndarray, np.ndarray]:
        """The semantic map (cell uid, height) of the last observation."""
        if self._semantic is None:
            raise RuntimeError("call reset() first")
        return self._semantic

    @property
    def observation(self) -> np.ndarray:
        """A copy of the current observation (what the last reset, `set_scene` or step returned)."""
        if self._obs is None:
            raise RuntimeError("call reset() first")
        return self._obs.copy()

    def decode_action(self, action) -> tuple[str, int, int]:
        """(map name, row, col) of a flat action index; ValueError if it is not one (`ActionCodec.decode`)."""
        return self.codec.decode(action)

    def step(self, action):
        """One action, as the paper's pipeline (§IV-B, Eq. 2): decode the pixel -> run the primitive
        (push; or pick -> place pose from the object the cup holds -> place) -> settle -> the task's
        rules (`shelf_env.world.task`) -> camera."""
        before = self._semantic
        name, judgement, reward, relabel_reward = self._act(action)
        truncated = not judgement.terminated and self.action_count >= self.max_actions
        self._obs = self._observe()
        info = self._info(name, judgement)
        if self.drag_watch is not None:
            info["interventions"] = list(self.primitive_runner.interventions)
        if judgement.relabel:
            assert before is not None
            relabel = self._class_of_uid(judgement.region)
            info["relabelled"] = {
                "obs": recolour(*before, relabel, self._regions_mask),
                "next_obs": recolour(*self._observed_semantic(), relabel, self._regions_mask),
                "reward": relabel_reward,
                "terminated": True,
            }
        if judgement.terminated or truncated:  # a VecEnv resets before the learner can ask for the final mask
            info["action_mask"] = self.action_masks()
        return self._obs.copy(), reward, judgement.terminated, bool(truncated), info

    def step_outcome(self, action) -> dict[str, Any]:
        """The outcome of `step` without the camera: ``reward``, ``terminated``, ``fell``, ``is_success`` and
        ``num_sorted`` exactly as `step` returns them (the camera runs after the physics and the task's rules,
        so it changes none of them), at about 0.6x the cost of a forked step. It leaves the env without an
        observation of its new state, so only a copy that is thrown away after may call it: a forked probe
        (`shelf_env.privileged.lookahead.probe_outcome`) that needs the outcome, not the next image."""
        name, judgement, reward, _ = self._act(action)
        self._obs = self._semantic = None  # stale: step() and action_masks() now ask for a reset
        info = self._info(name, judgement)
        return {"reward": float(reward), "terminated": bool(judgement.terminated), "fell": bool(info["fell"]),
                "is_success": bool(info["is_success"]), "num_sorted": int(info["num_sorted"])}

    def _act(self, action) -> tuple[str, task.Judgement, float, float]:
        """The physics and the rules of one step, before the camera: the primitive's name, the task's
        judgement, the reward and the hindsight reward of a relabelled transition."""
        before = self._semantic
        if self._obs is None or before is None:
            raise RuntimeError("call reset() before step()")
        name, row, col = self.decode_action(action)
        x, y = clip_target(*self.codec.cell_centre(row, col))
        self.world.sleep_resting()
        self.primitive_runner.interventions.clear()
        if name == "pick":
            self._pick_and_place(x, y, float(before[1][row, col]))
        else:
            self.primitive_runner.push(x, y, +1.0 if name == "push_left" else -1.0)
        self.robot.release()
        self.world.settle(step_fn=self.robot.step)
        self.action_count += 1

        judgement = task.judge(self.world)
        reward = judgement.reward_with(self.invalid_reward)
        relabel_reward = params.REWARD_SORTED
        if self.progress_reward and judgement.valid:  # every object inside: arrays line up with world.objects
            region_after = self._region_of_uid(judgement)
            reward += self.progress_reward * (judgement.num_sorted - self._sorted_before)
            relabel_reward += self.progress_reward * sum(
                region != self._region_before.get(uid, -1) for uid, region in region_after.items())
            self._region_before, self._sorted_before = region_after, judgement.num_sorted
        for obj, ok in zip(list(self.world.objects), judgement.inside):
            if not ok:  # it left the cabinet: remove it so it cannot roll around forever
                self.world.remove_object(obj)
        return name, judgement, reward, relabel_reward

    def _region_of_uid(self, judgement: task.Judgement) -> dict[int, int]:
        """Region index (-1: none) of each object, by uid, when every object is inside."""
        return {o.uid: int(r) for o, r in zip(self.world.objects, judgement.region)}

    def _pick_and_place(self, x: float, y: float, surface_z: float) -> None:
        """Pick at (x, y); if the cup holds an object, place it where `_place_for` puts it."""
        grasp = self.primitive_runner.pick(x, y, surface_z, {o.uid for o in self.world.objects})
        if grasp is not None:
            target = self._place_for(grasp.uid)
            assert target is not None  # always one without min_front
            self.primitive_runner.place(grasp, *target)

    @property
    def detour_reach(self) -> float:
        """Metres the closed loop's lane check may carry an object sideways to a clear way out
        (`DragWatch.detour_max`; 0 without the lane check): what ``safe_picks`` counts as clear."""
        return self.drag_watch.detour_max if self.drag_watch is not None and self.drag_watch.lane else 0.0

    def _carry_shift(self, x: float, y: float) -> float | None:
        """The closed loop's lane check (`DragWatch.lane`) for a pick at (x, y): the sideways shift in
        metres of the nearest carry that clears the neighbours seen in the last observation
        (`shelf_env.conditions.safe_picks.carry_path`), 0.0 for straight out, None when none is clear."""
        assert self.drag_watch is not None
        labels, height = self._observed_semantic()
        row, col = self.codec.cell_of(x, y)
        shift = carry_path(labels, height, row, col, self.camera.pixel_size, z_carry=carry_height(self.robot.motion),
                           max_shift=self.drag_watch.detour_max)
        return None if shift is None else -shift * self.camera.pixel_size  # columns run towards -y

    def action_masks(self) -> np.ndarray:
        """The actions allowed in the current observation: a bool array of ``action_space.n``,
        True = allowed (sb3-contrib's MaskablePPO convention, used by `sb3_pixeldqn.PixelDoubleDQN`
        for exploration, greedy actions and its double-DQN target).

        Allowed: a pick on a visible object cell; a push whose blade (one row either side of the
        start cell) meets a visible object cell within the push length in the push direction.
        Everything else — picking or pushing empty floor, occluded cells or walls — cannot move an
        object, so it can only waste an action (an object covers ~1 % of the map). It reads only
        what the observation shows: the visible object cells. It is mirror-symmetric across the
        cabinet's width (push-left at col c <-> push-right at col W-1-c) and blind to classes.
        When no object is visible at all, every action is allowed (the mask has nothing to say).

        With ``safe_picks=True`` a pick is allowed only where its object can be carried out of the
        opening clear of every other visible object (`shelf_env.conditions.safe_picks.carry_clear`; with the
        closed loop's lane check, also by a sideways detour of up to `detour_reach`), unless no
        pick is: then every pick on an object stays allowed (a pick-only policy must act).
        """
        if self._semantic is None:
            raise RuntimeError("call reset() before action_masks()")
        occupied = self._semantic[0] >= 0
        pick = None
        if self.safe_picks:
            clear = carry_clear(*self._semantic, self.camera.pixel_size, z_carry=carry_height(self.robot.motion),
                                max_shift=self.detour_reach)
            pick = clear if clear.any() else occupied
        return occupancy_masks(occupied, self.camera.pixel_size, self.map_names, pick)

    def _place_for(self, uid: int, min_front: float = 0.0) -> tuple[float, float] | None:
        """Tool (x, y) that puts the held object's centre where the place heuristic wants it; with
        ``min_front`` (the closed loop's place check, `DragWatch.stacked`) where it wants it with the
        footprint's front edge that far behind the opening, None when no centre in the region allows it.

        The heuristic chooses where the object's footprint goes; the cup may hold the object off
        centre (it grips where the pick pixel was), so the tool target is shifted by the object's
        offset from the tool. Without the shift an object gripped near its edge could be carried
        into a side wall and left outside the cabinet.
        """
        obj = next(o for o in self.world.objects if o.uid == uid)
        cell_uid, _ = self._observed_semantic()
        aabb_min, aabb_max = (np.asarray(v) for v in pb.getAABB(uid, physicsClientId=self.client))
        footprint = (aabb_max[0] - aabb_min[0], aabb_max[1] - aabb_min[1])
        centre_x, centre_y = place_position(cell_uid, self._class_of_uid(), self._regions_mask[obj.cls],
                                            obj.cls, footprint, self.camera.pixel_size, ignore_uid=uid,
                                            min_front=min_front)
        if min_front > 0 and centre_x - footprint[0] / 2 < min_front:
            return None
        offset = (aabb_min[:2] + aabb_max[:2]) / 2 - self.robot.tcp_position()[:2]
        return clip_target(centre_x - offset[0], centre_y - offset[1])

    def _info(self, primitive: str | None, judgement: task.Judgement) -> dict:
        """Info dict of the objects still in the world, from the task's judgement."""
        return {
            "is_success": judgement.is_success(self.episode_num_objects),
            "num_objects": self.episode_num_objects,
            "num_sorted": judgement.num_sorted,
            "num_unsorted_initial": self.num_unsorted_initial,
            "fell": judgement.fell,
            "primitive": primitive,
            "action_count": self.action_count,
        }

    # ---- viewing ------------------------------------------------------------------------
    def render(self):
        if self.render_mode != "rgb_array":
            return None
        view = pb.computeViewMatrix((-0.80, 0.30, 0.58), (0.20, 0.0, 0.0), (0, 0, 1), physicsClientId=self.client)
        proj = pb.computeProjectionMatrixFOV(50, 4 / 3, 0.05, 6.0, physicsClientId=self.client)
        _, _, rgb, _, _ = pb.getCameraImage(640, 480, view, proj, renderer=pb.ER_TINY_RENDERER,
                                            physicsClientId=self.client)
        return np.asarray(rgb, dtype=np.uint8).reshape(480, 640, 4)[..., :3].copy()

    def close(self) -> None:
        if getattr(self, "client", None) is not None and pb.isConnected(self.client):
            pb.disconnect(self.client)
        self.client = None
