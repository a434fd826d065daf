"""The closed loop: a robot that watches what it carries and reacts (``ShelfSortEnv(closed_loop=...)``).

Not the paper's task (§V is open loop); a condition chosen at construction. `DragWatch` holds its
settings; `WatchedPrimitives` is `shelf_env.robot.primitives.Primitives` with the watches in its
hooks: the lane check before the carry out, the force and camera watches during it, the put-down
on a catch, and the place check at the landing.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pybullet as pb

from shelf_env.robot.arm import Robot, carry_height
from shelf_env.robot.primitives import Grasp, Primitives

#: What the lane check (`DragWatch.lane`) does when no way out is clear.
BLOCKED_REACTIONS = ("carry", "put back")
#: What the place check (`DragWatch.place_check`) does with a refused landing (`DragWatch.stacked`).
STACKED_REACTIONS = ("deeper", "put back")


@dataclass(frozen=True)
class DragWatch:
    """Closed-loop watch of a carried object (``ShelfSortEnv(closed_loop=True)``, or a dict of these
    fields, or a DragWatch).

    Signals a real robot has, no object poses: a look at the carry's way out before it starts, two
    watches during it, and where the place's descent stopped.

    - **Lane** (``lane``): after the lift, before the carry out, the camera's heightmap (the
      observation the policy acted on: object cells and their heights) says whether the object,
      hanging under the cup at carry height, clears every visible neighbour between it and the
      opening (`shelf_env.conditions.safe_picks.carry_path`; straight out exactly where
      `shelf_env.conditions.safe_picks.carry_clear` says so). If not, the nearest sideways shift up to
      ``detour_max`` m whose sideways carry (at carry height) and way out are both clear is taken:
      the object is carried sideways, then out. If none is, ``blocked`` says what happens:
      ``"put back"`` lowers it where it was picked (the step ends with nothing moved) and
      ``"carry"`` carries it straight out, watched as below. Most falls the two watches below still
      let through are rams: the carried object hits a taller neighbour near the opening, the sensor
      reads 5-30 N within a few millimetres, and the neighbour is already tipping out when the
      carry stops (`results/closed_loop_seed0/on/falls.md`: 44 of 61 objects that left during a
      pick left after such a catch). Looking first avoids the ram instead of catching it.

    - **Force** (``force``): the force on the suction cup (a 6-axis force sensor between wrist and
      cup on a real robot; here the suction constraint's force). While the cup carries an object
      out of the cabinet, the only horizontal force on it should be the motion's own inertia: short
      spikes at waypoint changes (≤ 0.16 N for 1-2 physics steps with a 0.3 kg box). An object that
      drags a neighbour feels the neighbour's friction steadily (0.35 to 0.48 N for a 0.15 kg box on
      wood, on the crafted scene of tests/test_closed_loop.py); one that rams a neighbour reads
      5-30 N. Each move starts with the arm jumping to its speed, which the sensor reads as up to
      ~23 N for a few steps: the first ``blank`` steps of a move are not judged. Rule: after that, a
      force component against the move's horizontal direction above ``threshold`` N for ``sustain``
      consecutive physics steps is a drag (vertical moves, the lift, cannot drag anything out of
      the opening and are not judged). With ``judge_outside=False`` it is not judged once the
      commanded TCP is in front of the opening (there the held object's own exit reads 0.5-0.9 N).
    - **Camera** (``camera_every``): the side-view camera at a quarter of its resolution (~3 ms a
      frame), every ``camera_every`` physics steps (8: 30 frames per second). Before the arm goes in,
      the front edge (smallest x of the visible points, `HeightmapCamera.front_edges`) of every
      object; during the move, an object that was ahead of the held one and whose front edge has
      come more than ``camera_shift`` m closer to the opening has been moved towards it. Occlusion by
      the arm can only hide points, never bring an edge closer. It sees little in practice: a
      dragged neighbour is mostly hidden under the carried object (tests/test_closed_loop.py: seen
      3.4 cm late).

    - **Place check** (``place_check``): the place lowers the held object until it touches
      something. Where the descent stopped (the commanded TCP height less the object's hang under
      the cup) tells the robot whether the object landed on the floor or on other objects; with the
      grasp's offset it also knows where the object's front edge is. A landing more than
      ``stack_height`` m above the floor with the front edge less than ``stack_front`` m behind the
      opening is refused: the object is not released. ``stacked`` says what happens instead:
      ``"put back"`` lifts it, carries it out the way it came, in again along the lane its pick
      carried it out, and puts it down where it was picked; ``"deeper"`` lifts it and places it
      again where the place heuristic puts it with its front edge at least ``stack_front`` behind
      the opening (on the same observation; put back where the region has no such place). Why: with the
      lane check, most objects that still left the cabinet were the held object at the place (26 of
      38, `results/closed_loop_seed0/on_lane_pb/falls.md`). Replayed, all 26 had been placed by the
      place heuristic's fallback for a full region (no free footprint: the least covered one, which
      is near the opening), landed on other objects and slid out forwards after the release. Of
      H-a's 19 landings on other objects in seed 0's 30 scenes at N = 8 (an ad-hoc replay), the 4
      that fell had their front edge within 2 cm of the opening and none behind 5.5 cm fell; fallen
      ones in the 26 had it up to ~8.5 cm behind: hence 0.10 m.

    Reaction to a drag the watches catch: stop, carry the object back ``back_off`` m along the path
    it came (free a moment ago; the default 1 m is the whole way, so it is put back where it was
    picked), lower it straight down until something carries it (a contact pushing it up), release
    it, lift the cup to carry height (where it touches nothing) and go home; the step then ends as
    usual, with the event in ``info["interventions"]``. Putting the object down where it was caught instead
    (``back_off=0.02``) dropped the neighbour it had pushed while being lowered onto it (4 of H-d's 5
    falls after an intervention at N = 8).

    Measured (``bash scripts/closed_loop_seed0.sh``, `results/closed_loop_seed0/table.md`: H-a and
    H-d on seed 0's 30 YCB scenes per N, one machine; episodes with a fall at N = 8..14 and sorted
    episodes at N = 3..5, of 60, against open loop):

    - these defaults (folder ``on_deeper``): falls -85 % (H-a) and -82 % (H-d), sorted +2 and +4;
      sorted over N = 3..14 (5 N) 67 and 70 of 150, open loop 64 and 66; with the env's
      ``safe_picks=True`` too (``on_deeper_safe``, no pick is put back): falls -78 % / -63 %,
      sorted +4 / +8, over N = 3..14 74 / 79 of 150;
    - ``stacked="put back"`` (``on_place``): falls -95 % / -93 %, sorted +1 / +3, but over N = 3..14
      60 / 63 of 150: a heuristic that picks the put-back object again loops until the time-out;
    - no place check (``place_check=False``, ``on_lane_pb``): falls -65 % / -72 %, sorted +3 / +4;
      sorted at N = 8 13 -> 9 (H-a) and 12 -> 7 (H-d) of 30, loops again;
    - ``lane`` with ``blocked="carry"`` and no place check (``on_lane``): falls -36 % / -21 %,
      sorted +6 / +7;
    - no lane and no place check (``on``): falls -27 % / -22 %, sorted +4 / +3;
      ``{"sustain": 2, "threshold": 0.5, "judge_outside": False}`` (``on_s2in``): -38 % / -45 %,
      sorted +5 / -2.
    """

    threshold: float = 0.25
    sustain: int = 6
    blank: int = 24  # physics steps ignored at the start of each move (0.1 s): the arm accelerating
    force: bool = True  # judge the cup's force sensor
    camera_every: int = 8  # physics steps between camera frames (240 Hz / 8 = 30 fps); 0: no camera check
    camera_shift: float = 0.01  # metres an object's front may come towards the opening before it is a drag
    back_off: float = 1.0  # metres carried back before the put-down (1 m: the whole way, where it was picked)
    speed_scale: float = 1.0  # watched moves run at this fraction of their open-loop speed
    judge_outside: bool = True  # judge the force also once the cup is out of the opening (TCP x < 0)
    lane: bool = True  # before the retreat, check the carry's way out in the camera's heightmap
    detour_max: float = 0.2  # metres the lane check may shift the carry sideways to find a clear way out
    blocked: str = "put back"  # no clear way out: "put back" (where picked) or "carry" (straight, watched)
    place_check: bool = True  # refuse a place landing on other objects at the opening (put back instead)
    stack_height: float = 0.02  # metres above the floor the held object's bottom may land and count as on the floor
    stack_front: float = 0.10  # metres behind the opening within which a landing on other objects is refused
    stacked: str = "deeper"  # a refused landing: "deeper" (placed again further in) or "put back" (where picked)

    def __post_init__(self) -> None:
        for name in ("threshold", "camera_shift", "back_off", "detour_max", "stack_height", "stack_front"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value < float("inf"):
                raise ValueError(f"DragWatch.{name} must be a finite number >= 0, got {value!r}")
        for name in ("sustain", "blank", "camera_every"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"DragWatch.{name} must be an integer >= 0, got {value!r}")
        if self.sustain < 1:
            raise ValueError(f"DragWatch.sustain must be >= 1, got {self.sustain}")
        if self.blocked not in BLOCKED_REACTIONS:
            raise ValueError(f"DragWatch.blocked must be one of {BLOCKED_REACTIONS}, got {self.blocked!r}")
        if self.stacked not in STACKED_REACTIONS:
            raise ValueError(f"DragWatch.stacked must be one of {STACKED_REACTIONS}, got {self.stacked!r}")
        for name in ("force", "judge_outside", "lane", "place_check"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"DragWatch.{name} must be True or False, got {getattr(self, name)!r}")
        if isinstance(self.speed_scale, bool) or not isinstance(self.speed_scale, (int, float)) \
                or not 0 < self.speed_scale <= 1:
            raise ValueError(f"DragWatch.speed_scale must be in (0, 1], got {self.speed_scale!r}")

    @classmethod
    def from_any(cls, value: bool | dict | DragWatch) -> DragWatch | None:
        """The watch of the env's ``closed_loop`` argument: False -> None (open loop), True -> the
        defaults, a dict -> those fields changed (unknown keys are a ValueError), a DragWatch as is."""
        if isinstance(value, DragWatch):
            return value
        if isinstance(value, bool):
            return cls() if value else None
        if not isinstance(value, dict):
            raise ValueError(f"closed_loop must be True, False, a dict of DragWatch fields or a DragWatch, "
                             f"got {value!r}")
        known = [f.name for f in dataclasses.fields(cls)]
        unknown = sorted(set(value) - set(known))
        if unknown:
            raise ValueError(f"unknown closed_loop keys {unknown}; known: {known}")
        return cls(**value)




class WatchedPrimitives(Primitives):
    """`Primitives` under a `DragWatch` (see the module docstring and `DragWatch`)."""

    def __init__(self, robot: Robot, watch: DragWatch,
                 look: Callable[[list[int]], dict[int, float]] | None = None):
        super().__init__(robot)
        self.watch = watch
        #: The camera check: the front edge (smallest x) of each visible object of the given uids
        #: (`shelf_env.camera.heightmap.HeightmapCamera.front_edges`); None: no camera check.
        self.look = look
        #: The camera check's reference (set before the arm goes in to pick, when nothing but
        #: the objects themselves hides them): each visible object's front edge.
        self._front_before: dict[int, float] = {}
        #: The lane check (`DragWatch.lane`): for a pick at (x, y), the sideways shift in metres
        #: (along y) of the nearest carry out of the opening that clears every visible neighbour,
        #: 0.0 for straight out, None when none is clear (set by the env from its heightmap).
        self.plan_carry: Callable[[float, float], float | None] | None = None
        #: The place check's ``stacked="deeper"`` (`DragWatch.stacked`): for the held object's uid,
        #: the tool (x, y) where the place heuristic puts it with its front edge ``stack_front``
        #: behind the opening, None where the region allows none (set by the env).
        self.plan_place: Callable[[int], tuple[float, float] | None] | None = None

    def _before_pick(self, objects: set[int]) -> None:
        if self.look is not None and self.watch.camera_every > 0:
            self._front_before = self.look(sorted(objects))

    def _carry_move(self, start: np.ndarray, end: np.ndarray, speed: float, phase: str) -> bool:
        return self._watched_move(start, end, speed, phase)

    def _way_out(self, x: float, y: float, lifted: np.ndarray, z_carry: float) -> tuple[np.ndarray, float] | None:
        """The lane check (`DragWatch.lane`): straight out, sideways first, or put back."""
        m = self.robot.motion
        if self.watch.lane and self.plan_carry is not None:
            shift = self.plan_carry(x, y)
            event = {"primitive": "pick", "phase": "lane", "signal": "lane",
                     "tcp": [round(float(v), 4) for v in lifted]}
            if shift is None and self.watch.blocked == "put back":
                self._put_down_here(lifted)
                self.interventions.append({**event, "reaction": "no clear way out: put back where picked"})
                return None
            if shift:  # the nearest clear way out is beside this one: carry sideways first
                aside = np.array([x, y + shift, z_carry])
                self.interventions.append({**event, "reaction": f"carried {shift:+.3f} m sideways, then out"})
                if self._carry_move(lifted, aside, m.approach_speed, "detour"):
                    return None
                lifted, y = aside, y + shift
        return lifted, y

    def _landing_check(self, obj: int, hang: float) -> Callable[[], bool] | None:
        if not self.watch.place_check:
            return None
        # the held object's front edge relative to the cup (it hangs rigidly under it)
        behind = pb.getAABB(obj, physicsClientId=self.robot.client)[0][0] - self._commanded_tcp()[0]
        return functools.partial(self._landed_on_others, hang, behind)

    def _refused_landing(self, grasp: Grasp, y: float, z_release: float) -> None:
        """`DragWatch.stacked`: place it again deeper in, or put it back where it was picked."""
        r, m = self.robot, self.robot.motion
        obj, z_carry = grasp.uid, grasp.z_carry
        deeper = self.plan_place(obj) if self.watch.stacked == "deeper" and self.plan_place is not None else None
        if deeper is None:
            self._put_back(grasp, y)
            self.interventions[-1]["reaction"] = "landed on objects at the opening: put back where picked"
            return
        # lift it, carry it over to the deeper place at carry height and place it there
        here = self._commanded_tcp()
        top = np.array([here[0], here[1], z_carry])
        r.move_linear(here, top, m.vertical_speed)
        start = np.array([deeper[0], deeper[1], z_carry])
        r.move_linear(top, start, m.approach_speed)
        self.interventions[-1]["reaction"] = (f"landed on objects at the opening: placed again at "
                                              f"({deeper[0]:.3f}, {deeper[1]:.3f})")
        self._lower_and_release(obj, start, np.array([deeper[0], deeper[1], z_release]))

    def _watched_move(self, start: np.ndarray, end: np.ndarray, speed: float, phase: str) -> bool:
        """Move the held object; with a `DragWatch`, stop on a drag (its force or camera rule), carry
        the object back and put it down (`_put_down_here`). True if that happened (the object is no
        longer held)."""
        r = self.robot
        if r.held is None:
            r.move_linear(start, end, speed)
            return False
        watch, run, peak, steps = self.watch, [0], [0.0], [0]
        heading = np.asarray(end[:2], float) - np.asarray(start[:2], float)
        if np.linalg.norm(heading) < 1e-9:  # a vertical move cannot drag anything out of the opening
            r.move_linear(start, end, speed)
            return False
        heading /= np.linalg.norm(heading)
        # objects whose front was ahead of the held object's (those the carry can push out); the
        # ones behind it may show more of themselves once it has gone, which is not a motion
        held_front = self._front_before.get(r.held[0], np.inf)
        reference = {u: x for u, x in self._front_before.items() if u != r.held[0] and x < held_front}
        others = sorted(reference)
        look = self.look if watch.camera_every > 0 and others else None
        moved: list[tuple[int, float]] = []

        def dragging() -> bool:
            steps[0] += 1
            if look is not None and steps[0] % watch.camera_every == 0:
                front = look(others)
                moved[:] = [(u, reference[u] - x) for u, x in front.items()
                            if u in reference and x < reference[u] - watch.camera_shift]
                if moved:
                    return True
            if not watch.force or steps[0] <= watch.blank:
                return False
            if not watch.judge_outside and self._commanded_tcp()[0] < 0:
                run[0] = 0
                return False
            force = float(np.dot(r.cup_force()[:2], -heading))  # the part that holds the motion back
            run[0] = run[0] + 1 if force > watch.threshold else 0
            peak[0] = max(peak[0], force) if run[0] else peak[0]
            return run[0] >= watch.sustain

        if not r.move_linear(start, end, speed * watch.speed_scale, stop=dragging, check_every=1, skip_free=False):
            return False
        event: dict = {"primitive": "pick", "phase": phase,
                       "tcp": [round(float(v), 4) for v in self._commanded_tcp()]}
        if moved:
            uid, shift = max(moved, key=lambda item: item[1])
            event.update(signal="camera", object=int(uid), shift_m=round(float(shift), 4))
        else:
            event.update(signal="force", force_n=round(peak[0], 3))
        event["reaction"] = f"carried back {self._put_down_here(start):.3f} m, put down"
        self.interventions.append(event)
        return True

    def _put_down_here(self, start: np.ndarray) -> float:
        """Carry the held object back ``back_off`` along the path it came (from ``start``, free a
        moment ago: off whatever it pressed on), lower it straight down until it rests on something,
        release it, lift the cup to carry height and go home. Returns how far it was carried back.

        Not `_lower_and_release` with another landing rule: its lift and exit start from other
        (equal up to float noise) points, and the committed closed-loop results reproduce bit for
        bit only along this path."""
        r, m = self.robot, self.robot.motion
        assert r.held is not None
        obj = r.held[0]
        here = self._commanded_tcp()
        way_back = np.asarray(start, float) - here
        way_back[2] = 0.0
        if np.linalg.norm(way_back) > self.watch.back_off:
            way_back *= self.watch.back_off / np.linalg.norm(way_back)
        if np.linalg.norm(way_back) > 1e-6:
            r.move_linear(here, here + way_back, m.approach_speed / 2)
            here = here + way_back
        hang = here[2] - pb.getAABB(obj, physicsClientId=r.client)[0][2]
        low = np.array([here[0], here[1], min(max(hang + m.release_gap, 0.0), here[2])])

        def resting() -> bool:  # something under the held object carries it (contact normal upwards)
            pts = pb.getContactPoints(bodyA=obj, physicsClientId=r.client)
            return any(p[2] != r.uid and p[7][2] > 0.5 for p in pts)

        r.move_linear(here, low, m.lift_speed, stop=resting)
        r.release()
        r.hold_still(12)
        here = self._commanded_tcp()
        top = np.array([here[0], here[1], max(here[2], carry_height(m))])
        r.move_linear(here, top, m.vertical_speed)
        r.move_linear(top, np.array([min(m.outside_x, top[0]), top[1], top[2]]), m.approach_speed)
        r.go_home()
        return float(np.linalg.norm(way_back))

    def _landed_on_others(self, hang: float, behind: float) -> bool:
        """The place check (`DragWatch.place_check`), when the lowering has stopped: the held object's
        bottom (the commanded TCP height less the hang) is more than ``stack_height`` above the floor,
        so it rests on other objects, and its front edge is less than ``stack_front`` behind the
        opening. Records the intervention (its reaction is the caller's) when it refuses the landing."""
        tcp = self._commanded_tcp()
        bottom, front = float(tcp[2] - hang), float(tcp[0] + behind)
        if bottom <= self.watch.stack_height or front >= self.watch.stack_front:
            return False
        self.interventions.append({
            "primitive": "place", "phase": "land", "signal": "height", "bottom_m": round(bottom, 4),
            "front_m": round(front, 4), "tcp": [round(float(v), 4) for v in tcp]})
        return True

    def _put_back(self, grasp: Grasp, y: float) -> None:
        """The place check's ``stacked="put back"``: lift the still-held object to carry height, carry it out the
        way it came in (at ``y``), in again along the lane its pick carried it out (free then), over
        the spot where it was picked, and put it down there (`_put_down_here`)."""
        r, m = self.robot, self.robot.motion
        here = self._commanded_tcp()
        top = np.array([here[0], here[1], grasp.z_carry])
        r.move_linear(here, top, m.vertical_speed)
        outside = np.array([grasp.out_x, y, grasp.z_carry])
        r.move_linear(top, outside, m.approach_speed)
        lane = np.array([grasp.out_x, grasp.lane_y, grasp.z_carry])
        r.teleport(lane)
        inside = np.array([grasp.x, grasp.lane_y, grasp.z_carry])
        r.move_linear(lane, inside, m.approach_speed)
        if grasp.lane_y != grasp.y:
            above = np.array([grasp.x, grasp.y, grasp.z_carry])
            r.move_linear(inside, above, m.approach_speed)
            inside = above
        self._put_down_here(inside)

