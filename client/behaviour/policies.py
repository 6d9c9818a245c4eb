"""Scripted experts (teachers) and perturbed demonstrations.

    policy = make_policy("wall-following")     # or "maze" (client.behaviour.tasks)
    policy.reset()
    name = policy.act(ranges, pose)            # ranges: 360-beam float32 scan, ranges[0] at -90 deg
                                               # (robot's right); pose: odometry (x, y, yaw)
    demo = Demonstrator(policy, perturb=0.2, rng=np.random.default_rng(0))
    label, executed = demo.step(ranges, pose)  # label: the expert's choice; executed: what to drive

Experts see only the scan and the odometry heading (they run in a process that sees zenoh data,
never the map). They are SMOOTH like a human's key presses: the continuous steering command has
hysteresis and every label is held for a minimum dwell, so the label stream does not flicker
(which also keeps trees small).

``WallFollower(side="right")`` follows the wall on the robot's right at about ``target`` metres.
``MazeTeacher`` solves a tiered maze by keeping its right hand on the wall (scan only), which takes
every tier's outlet in turn and never re-enters a visited tier.

Both handle: an open followed side (a convex corner, a fin's tip, an opening: arc towards it even
with a wall ahead), a wall ahead (turn away), and no wall in reach (drive straight until one is
ahead, then turn so that it ends up on the followed side).
"""

from __future__ import annotations

import math

import numpy as np

from .actions import DEFAULT_ACTIONS, ActionSet

__all__ = [
    "Policy",
    "WallFollower",
    "MazeTeacher",
    "Demonstrator",
    "ReactiveFollower",
    "ReactiveMazeTeacher",
    "STYLES",
    "scan_points",
    "side_wall_distance",
    "TAKEOVER",
    "takes_over",
    "ReactiveDoorwayFollower",
    "DoorwayTeacher",
    "DeadEndEscaper",
    "CorridorCentrer",
    "Wanderer",
]

def _bearings(count: int, fov_deg: float = 180.0) -> np.ndarray:
    half = math.radians(fov_deg) / 2.0
    return np.linspace(-half, half, count)


_BEARING_CACHE: dict[tuple[int, float], tuple[np.ndarray, np.ndarray, np.ndarray]] = {}


def _trig(count: int, fov_deg: float = 180.0):
    key = (count, fov_deg)
    t = _BEARING_CACHE.get(key)
    if t is None:
        b = _bearings(count, fov_deg)
        t = (b, np.cos(b), np.sin(b))
        _BEARING_CACHE[key] = t
    return t


def scan_points(ranges, fov_deg: float = 180.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(bearings, x, y) of every beam's end point in the robot frame (x forward, y left)."""
    r = np.asarray(ranges, dtype=np.float64)
    b, c, s = _trig(r.size, fov_deg)
    return b, r * c, r * s


def side_wall_distance(ranges, side: str = "right", fov_deg: float = 180.0,
                       sector_deg: float = 60.0) -> float:
    """Distance to the nearest wall point on one side: the minimum range over the beams within
    ``sector_deg`` of that side's perpendicular (-90 deg for right, +90 for left)."""
    r = np.asarray(ranges, dtype=np.float64)
    n = r.size
    k = int(round(sector_deg / fov_deg * (n - 1)))
    part = r[: k + 1] if side == "right" else r[n - 1 - k:]
    return float(part.min())


class Policy:
    """Base of the scripted experts: ``reset()`` and ``act(ranges, pose) -> action name``."""

    task = ""

    def __init__(self, actions: ActionSet = DEFAULT_ACTIONS):
        self.actions = actions

    def reset(self) -> None:  # pragma: no cover - trivial
        pass

    def act(self, ranges, pose) -> str:  # pragma: no cover - abstract
        raise NotImplementedError


class WallFollower(Policy):
    """Follow the wall on ``side`` (default the robot's right) at about ``target`` metres.

    Steering: the nearest wall point on the followed side and ahead gives the distance d and the
    wall's angle alpha (0 when parallel, > 0 when the robot heads into it); a command
    w = k_d (target - d) + k_a alpha (for the right side; mirrored for the left) plus a front term
    is discretised into the five actions with hysteresis and a minimum dwell.
    """

    task = "wall-following"

    def __init__(self, side: str = "right", target: float = 0.6, k_d: float = 2.0,
                 k_a: float = 1.6, front_stop: float = 0.45, front_slow: float = 0.9,
                 lost: float = 1.2, on: float = 0.45, off: float = 0.2, dwell: int = 3,
                 robot_half_width: float = 0.26, fov_deg: float = 180.0, sector_deg: float = -40.0,
                 max_arc: int = 60, search: float | None = None,
                 actions: ActionSet = DEFAULT_ACTIONS):
        super().__init__(actions)
        if side not in ("right", "left"):
            raise ValueError(f"side must be 'right' or 'left', got {side!r}")
        self.side = side
        self.target, self.k_d, self.k_a = target, k_d, k_a
        self.front_stop, self.front_slow, self.lost = front_stop, front_slow, lost
        self.on, self.off, self.dwell = on, off, dwell
        self.half_width = robot_half_width
        self.fov = fov_deg
        self.sector = math.radians(sector_deg)
        self.max_arc = max_arc
        self.search = search
        self.reset()

    def reset(self) -> None:
        self._label = "fwd"
        self._held = self.dwell  # the first choice is free
        self._lost = self.max_arc + 1  # until a wall is found, search straight ahead
        self._far = False

    def resume_following(self) -> None:
        """After a restart during a training run: treat a missing wall as a wall that just ended
        (arc towards it), as in the middle of a demonstration, instead of searching straight
        ahead; otherwise the same scan would get two labels depending on the teacher's memory."""
        self._lost = 0

    # -- the continuous expert, always for the RIGHT side (the left side mirrors the scan) --
    def _command(self, r: np.ndarray) -> tuple[float, float, bool]:
        """(w, front, lost): desired turn (> 0 = left), front clearance, and whether the
        followed wall has ended / is out of reach. Sets ``self._far``: nothing within
        ``search`` metres on the followed half of the scan (open space)."""
        b, c, s = _trig(r.size, self.fov)
        x, y = r * c, r * s
        # clearance straight ahead in the robot's swept corridor
        ahead = (x > 0.0) & (np.abs(y) < self.half_width)
        front = float(x[ahead].min()) if ahead.any() else float(r.max())
        # nearest point on the right side (bearings -90 .. sector_deg); walls ahead are the
        # front term's business, so an opening on the followed side is taken even with a wall ahead
        sel = b <= self.sector
        i = int(np.argmin(np.where(sel, r, np.inf)))
        d = float(r[i])
        alpha = float(b[i]) + math.pi / 2.0  # 0 when the wall's foot is at -90 deg (parallel)
        # the followed wall ended (nothing beside the robot: a convex corner, a fin's tip, an
        # opening) or no wall in reach: arc towards the followed side, whatever lies ahead
        beside = float(r[b <= -math.pi / 2.0 + math.radians(15.0)].min())
        self._far = self.search is not None and float(r[b <= 0.0].min()) > self.search
        if d > self.lost or beside > self.lost:
            return -1.0, front, True
        w = self.k_d * (self.target - d) + self.k_a * alpha
        if front < self.front_slow:
            w = max(w, 0.0) + (self.front_slow - front) * 3.0
        return w, front, False

    def _discretise(self, w: float, front: float, lost: bool = False) -> str:
        cur = self._label
        if cur in ("rot-left", "rot-right") and front < self.front_slow:
            # committed: keep rotating the same way until the way ahead is clear (a human does
            # not dither between rotate-left and rotate-right in a tight spot)
            return cur
        if lost and (self._far or self._lost > self.max_arc):
            # nothing within ``search`` on the followed half (open space, a start far from walls:
            # a reactive test the learner's clamped beams can see) or no wall for a long time:
            # drive straight until one is ahead, then turn so that it ends up on the followed side
            if front < self.front_stop:
                return "rot-left"
            return "fwd-left" if front < self.front_slow else "fwd"
        if lost:
            # the followed wall ended (a convex corner, a fin's tip, an opening): turn towards
            # it, in place when something is close ahead
            return "rot-right" if front < self.front_stop else "fwd-right"
        if front < self.front_stop or (w > 2.0 and front < self.front_slow):
            want = "rot-left"
        elif cur in ("fwd-left", "rot-left"):
            want = cur if w > self.off else ("fwd-right" if w < -self.on else "fwd")
            if want == "rot-left" and front >= self.front_slow and w < 1.2:
                want = "fwd-left"
        elif cur in ("fwd-right", "rot-right"):
            want = "fwd-right" if w < -self.off else ("fwd-left" if w > self.on else "fwd")
        else:
            want = "fwd-left" if w > self.on else ("fwd-right" if w < -self.on else "fwd")
        return want

    def reactive(self, ranges) -> str:
        """The label this expert gives the scan with no history (no hysteresis, dwell, committed
        rotation or lost-wall memory): a pure function of the scan. Where ``act`` agrees with it
        the label is learnable by a reactive tree; where it does not, the label came from the
        expert's memory (the same scan gets other labels at other times)."""
        r = np.asarray(ranges, dtype=np.float64)
        if self.side == "left":
            r = r[::-1]
        w, front, lost = self._command(r)
        if lost:
            name = "rot-right" if front < self.front_stop else "fwd-right"
        elif front < self.front_stop or (w > 2.0 and front < self.front_slow):
            name = "rot-left"
        else:
            name = "fwd-left" if w > self.on else ("fwd-right" if w < -self.on else "fwd")
        return self.actions.mirror(name) if self.side == "left" else name

    def act(self, ranges, pose=None) -> str:
        r = np.asarray(ranges, dtype=np.float64)
        if self.side == "left":
            r = r[::-1]
        w, front, lost = self._command(r)
        self._lost = self._lost + 1 if lost else 0
        want = self._discretise(w, front, lost)
        urgent = front < self.front_stop
        if want != self._label and (self._held >= self.dwell or urgent):
            self._label, self._held = want, 0
        self._held += 1
        name = self._label
        if self.side == "left":
            name = self.actions.mirror(name)
        return name


class MazeTeacher(WallFollower):
    """Tiered-maze expert from the scan only: a right-wall follower tuned for 2 m corridors.

    In a tiered maze (every tier one inlet and one outlet) keeping the right hand on the wall takes
    every tier's outlet in turn and never re-enters a visited tier, wherever the openings are and
    however many tiers there are. The learner still gets the paper's heading feature (0.33/0.66),
    which separates the tiers' two travel directions in feature space. (An earlier teacher that
    switched walls with the heading failed at the openings, where the heading flips: see
    docs/experiments.md.)
    """

    task = "maze"

    def __init__(self, target: float = 0.55, actions: ActionSet = DEFAULT_ACTIONS, **kw):
        kw.setdefault("side", "right")
        super().__init__(target=target, actions=actions, **kw)


STYLES = ("reactive", "smooth")  # the experts' styles (client.behaviour.tasks.make_policy)


TAKEOVER = 0.3  # m: the corrective rounds' takeover distance (docs/experiments.md)


def takes_over(ranges, takeover: float = TAKEOVER) -> bool:
    """Corrective (DAgger) rounds: the learned tree drives while the teacher labels every state;
    the teacher takes the wheels for a scan when any beam is closer than ``takeover`` metres
    (0 = never). The one rule of the in-process harness and of ``rhbl teacher --correct``."""
    return takeover > 0 and float(np.min(ranges)) < takeover


class Demonstrator:
    """Perturbed demonstrations (noise injection, like DART).

    ``step(ranges, pose) -> (label, executed)``: ``label`` is always the expert's choice; about
    ``perturb`` of the time ``executed`` is a random action held for ``hold`` seconds (uniform in
    the given range), so the learner also sees how to recover from off-path states. A perturbation
    ends early when any beam is closer than ``safety`` metres.
    """

    def __init__(self, policy: Policy, perturb: float = 0.2, rng=None,
                 hold: tuple[float, float] = (0.5, 1.5), dt: float = 0.1, safety: float = 0.35):
        if not 0.0 <= perturb < 1.0:
            raise ValueError(f"perturb must be in [0, 1), got {perturb}")
        self.policy = policy
        self.perturb = perturb
        self.rng = rng if rng is not None else np.random.default_rng()
        self.hold = hold
        self.dt = dt
        self.safety = safety
        mean_steps = (hold[0] + hold[1]) / 2.0 / dt
        self._p_start = perturb / max(1e-9, (1.0 - perturb)) / mean_steps if perturb > 0 else 0.0
        self.reset()

    def reset(self) -> None:
        self.policy.reset()
        self._left = 0
        self._action: str | None = None
        self.consistent = True

    @property
    def perturbing(self) -> bool:
        return self._left > 0

    def step(self, ranges, pose) -> tuple[str, str]:
        label = self.policy.act(ranges, pose)
        reactive = getattr(self.policy, "reactive", None)
        # True when the label is a function of the scan alone (see WallFollower.reactive)
        # (rotations are always kept: a committed rotation in a tight spot is how the expert
        # gets out, and dropping it leaves the learner pinned)
        self.consistent = (reactive is None or label.startswith("rot")
                           or getattr(self.policy, "acts_reactively", False)
                           or reactive(ranges) == label)
        if self._left > 0 and float(np.min(ranges)) < self.safety:
            self._left = 0
        if self._left == 0 and self._p_start > 0 and self.rng.random() < self._p_start \
                and float(np.min(ranges)) >= self.safety:
            names = self.policy.actions.names
            self._action = names[int(self.rng.integers(len(names)))]
            lo, hi = self.hold
            self._left = max(1, int(round(self.rng.uniform(lo, hi) / self.dt)))
        if self._left > 0:
            self._left -= 1
            return label, self._action  # type: ignore[return-value]
        return label, label


class ReactiveFollower(Policy):
    """A REACTIVE right-wall follower: every label is a pure function of the scan it is given,
    computed through a feature spec's sector minima (so the learner, which sees the same
    sectors, can represent the teacher exactly: the same feature vector never gets two labels).

    Sectors (metres, each the minimum over its window of the 360-beam scan, clamped), for the
    default spec (beams 0, 22.5, 45, 67.5, 90 deg from the right edge, window 11.25 deg, i.e.
    contiguous sectors covering -90..+11 deg): ``R`` beside, ``RD`` right-behind-diagonal,
    ``D`` diagonal ahead, ``FR`` ahead-right, ``F`` ahead.

    A fixed partition, no hysteresis, dwell or counters:
      blocked ahead (F < stop or FR < stop_fr)              -> rot-left
      wall approaching ahead (F < slow or FR < slow_fr)      -> fwd-left
      nothing beside (min(R, RD, D) > lost)                  -> fwd-right (arc towards the
                                                               followed side: a convex corner,
                                                               a fin's tip, an opening, no wall)
      otherwise u = (near - target) + k_a (D - ratio * side) (distance error + angle proxy:
      the diagonal sector reads ``ratio`` times the side distance along a parallel wall, less
      when heading into the wall, more when heading away or when the wall ends ahead)
                                        u > band -> fwd-right, u < -band -> fwd-left, else fwd
    The left side (``side="left"``) mirrors the scan and the labels.
    """

    task = "wall-following"

    def __init__(self, features=None, side: str = "right", target: float = 0.6,
                 band: float = 0.08, k_a: float = 0.7, ratio: float = 1.2, cap: float = 0.3,
                 stop: float = 0.45, stop_fr: float = 0.45, slow: float = 0.9,
                 slow_fr: float = 0.7, lost: float = 1.2, open_d: float = 99.0,
                 search: float = 1.7, actions: ActionSet = DEFAULT_ACTIONS):
        super().__init__(actions)
        from .features import FEATURES

        self.features = features if features is not None else FEATURES["wall"]
        if self.features.dim - (1 if self.features.heading else 0) < 5:
            raise ValueError("ReactiveFollower needs a feature spec with >= 5 beams")
        if side not in ("right", "left"):
            raise ValueError(f"side must be 'right' or 'left', got {side!r}")
        self.side = side
        self.target, self.band, self.k_a, self.ratio = target, band, k_a, ratio
        self.cap = cap
        self.stop, self.stop_fr, self.slow, self.slow_fr = stop, stop_fr, slow, slow_fr
        self.lost, self.open_d, self.search = lost, open_d, search

    def sectors(self, ranges) -> np.ndarray:
        """The first five sector minima in metres (R, RD, D, FR, F)."""
        r = np.asarray(ranges)
        if self.side == "left":
            r = r[::-1]
        f = self.features
        return f.extract(r, 0.0)[:5] * f.scale

    def decide(self, s) -> str:
        """The label of sector minima ``s`` = (R, RD, D, FR, F) in metres (right side)."""
        rr, rd, d, fr, f = (s[:5].tolist() if isinstance(s, np.ndarray)
                            else [float(v) for v in s[:5]])
        if f < self.stop or fr < self.stop_fr:
            return "rot-left"
        near = min(rr, rd, d)
        side = min(rr, rd)
        opening = d > self.open_d and side <= self.lost
        if (f < self.slow or fr < self.slow_fr) and not opening:
            return "fwd-left"
        if near > self.lost:
            return "fwd" if self.lost < near < self.search else "fwd-right"
        ang = min(max(d - self.ratio * side, -self.cap), self.cap)
        u = (near - self.target) + self.k_a * ang
        if u > self.band:
            return "fwd-right"
        if u < -self.band:
            return "fwd-left"
        return "fwd"

    def label(self, ranges) -> str:
        name = self.decide(self.sectors(ranges))
        return self.actions.mirror(name) if self.side == "left" else name

    reactive = label

    def act(self, ranges, pose=None) -> str:
        return self.label(ranges)

    @property
    def acts_reactively(self) -> bool:
        """True when ``act`` is ``label``: every label is then the reactive one (the
        :class:`Demonstrator` need not compute it twice)."""
        return type(self).act is ReactiveFollower.act


class ReactiveMazeTeacher(ReactiveFollower):
    """Tiered maze by the right-hand rule with the reactive follower (scan only, no heading)."""

    task = "maze"

    def __init__(self, target: float = 0.55, **kw):
        super().__init__(target=target, **kw)


class ReactiveDoorwayFollower(ReactiveFollower):
    """Room to room through doorways, by the right-hand rule (scan only, no heading, no map).

    In a suite of rooms whose walls are all joined to the outer one (rooms in a row, or round a
    ring), keeping the wall on the robot's right leads from the first room through every
    doorway in turn: along a room's wall to the wall that parts it from the next room, along
    that to the doorway, round the door jamb's end (nothing beside: arc towards the right) and
    through, then along the next room's wall to its next doorway. A doorway at the foot of a
    wall is passed straight through. It is the reactive right-wall follower held a little
    closer to its wall (``target`` 0.55 m, as in the maze), so that in a doorway as narrow as
    1.2 m it keeps clear of the far jamb; every label is a pure function of the scan's sectors.
    It does not look for a wall: from the middle of a room, with every wall out of its reach
    (``search``), it arcs round where it is, so its start poses are within reach of a wall.
    """

    task = "doorways"

    def __init__(self, target: float = 0.55, **kw):
        super().__init__(target=target, **kw)


class DoorwayTeacher(WallFollower):
    """Room to room through doorways, the smooth style (``rhbl teacher --policy doorway
    --style smooth``): the history-dependent right-wall follower at 0.55 m (see
    :class:`ReactiveDoorwayFollower` for why keeping the right-hand wall leads through every
    doorway)."""

    task = "doorways"

    def __init__(self, target: float = 0.55, actions: ActionSet = DEFAULT_ACTIONS, **kw):
        kw.setdefault("side", "right")
        super().__init__(target=target, actions=actions, **kw)


class DeadEndEscaper(Policy):
    """Out of a dead end: drive on straight ahead, keeping off the walls on either side, and
    where the way ahead is blocked (a blind corridor's end) turn round on the spot, to the left,
    until it is open again; then drive back out the way it came.

    Its labels are a pure function of a feature spec's nine sector minima from the robot's right
    to its left (default ``around``; metres): ``F`` the sector straight ahead, ``FR``/``FL`` the
    two beside it, ``R`` the two rightmost, ``L`` the two leftmost. A fixed partition:

      F < stop or min(FR, FL) < stop_diag      -> rot-left  (blocked: turn round on the spot)
      min(R) < near and min(R) <= min(L)       -> fwd-left  (too close on the right: steer off)
      min(L) < near                            -> fwd-right (too close on the left: steer off)
      FR, FL both within ``align`` and FR - FL > tol  -> fwd-right (turn to the corridor's line:
      ... and FL - FR > tol                          -> fwd-left   the diagonals read alike when
                                                                   it heads along a corridor)
      otherwise                                -> fwd       (straight on: it holds its heading,
                                                             it does not centre itself)

    A wall follower never faces a blind end: it turns along the wall long before. This expert
    is for a robot that has driven into one and must come back out, in a corridor too narrow
    to turn round in an arc (``rot-left`` turns on the spot).
    """

    task = "dead-end"

    def __init__(self, features=None, stop: float = 1.0, stop_diag: float = 0.45,
                 near: float = 0.35, align: float = 1.8, tol: float = 0.2,
                 actions: ActionSet = DEFAULT_ACTIONS):
        super().__init__(actions)
        from .features import FEATURES

        self.features = features if features is not None else FEATURES["around"]
        if self.features.dim - (1 if self.features.heading else 0) < 9:
            raise ValueError(f"DeadEndEscaper needs a feature spec with >= 9 sectors (right to "
                             f"left, e.g. 'around'), got {self.features.dim} inputs")
        for name, v in (("stop", stop), ("stop_diag", stop_diag), ("near", near),
                        ("align", align), ("tol", tol)):
            if isinstance(v, bool) or not isinstance(v, int | float) or not 0 < v < math.inf:
                raise ValueError(f"{name} must be a number of metres > 0, got {v!r}")
        self.stop, self.stop_diag, self.near = float(stop), float(stop_diag), float(near)
        self.align, self.tol = float(align), float(tol)

    def sectors(self, ranges) -> np.ndarray:
        """The nine sector minima in metres, from the robot's right to its left."""
        f = self.features
        return f.extract(np.asarray(ranges), 0.0)[:9] * f.scale

    def decide(self, s) -> str:
        """The label of nine sector minima ``s`` (metres, right to left)."""
        v = s.tolist() if isinstance(s, np.ndarray) else [float(x) for x in s]
        if v[4] < self.stop or min(v[3], v[5]) < self.stop_diag:
            return "rot-left"
        right, left = min(v[0], v[1]), min(v[7], v[8])
        if right < self.near and right <= left:
            return "fwd-left"
        if left < self.near:
            return "fwd-right"
        fr, fl = v[3], v[5]
        if max(fr, fl) < self.align:
            if fr - fl > self.tol:
                return "fwd-right"
            if fl - fr > self.tol:
                return "fwd-left"
        return "fwd"

    def label(self, ranges) -> str:
        return self.decide(self.sectors(ranges))

    reactive = label

    def act(self, ranges, pose=None) -> str:
        return self.label(ranges)

    acts_reactively = True


class CorridorCentrer(Policy):
    """Centring along a winding corridor: keep midway between the walls, reactively (every label
    a pure function of the scan, through the sector minima of a feature spec, by default the
    all-round ``around``: nine sectors of 22.5 degrees, right ``s[0]`` .. ahead ``s[4]`` ..
    left ``s[8]``, metres, so a tree with that perception can represent it exactly).

    ``right`` = min(s[0], s[1], s[2]) and ``left`` = min(s[6], s[7], s[8]) are the nearest walls on
    each side (the 60 degrees from each side's edge, as the ``centred`` rule measures them):
      blocked ahead (s[4] < stop)        -> rot towards the more open ahead-diagonal (s[5] vs s[3])
      otherwise u = (left - right) + k_a * clip(s[5] - s[3], +/- cap)
      (the sides' difference, plus the ahead-diagonals' difference: the corridor bending)
                                  u > band -> fwd-left, u < -band -> fwd-right, else fwd
    """

    task = "corridor-centring"

    def __init__(self, features=None, band: float = 0.1, k_a: float = 0.5, cap: float = 1.0,
                 stop: float = 0.45, actions: ActionSet = DEFAULT_ACTIONS):
        super().__init__(actions)
        from .features import FEATURES

        self.features = features if features is not None else FEATURES["around"]
        if len(self.features.beams) != 9:
            raise ValueError(f"CorridorCentrer needs a feature spec of 9 sectors, got "
                             f"{len(self.features.beams)}")
        self.band, self.k_a, self.cap, self.stop = band, k_a, cap, stop

    def sectors(self, ranges) -> np.ndarray:
        """The nine sector minima in metres, right to left."""
        f = self.features
        return f.extract(np.asarray(ranges), 0.0)[:9] * f.scale

    def decide(self, s) -> str:
        """The label of sector minima ``s`` (nine, metres, right to left)."""
        s = [float(v) for v in s[:9]]
        if s[4] < self.stop:
            return "rot-left" if s[5] >= s[3] else "rot-right"
        right, left = min(s[0], s[1], s[2]), min(s[6], s[7], s[8])
        u = (left - right) + self.k_a * min(max(s[5] - s[3], -self.cap), self.cap)
        if u > self.band:
            return "fwd-left"
        if u < -self.band:
            return "fwd-right"
        return "fwd"

    def act(self, ranges, pose=None) -> str:
        return self.decide(self.sectors(ranges))

    reactive = act
    acts_reactively = True


class Wanderer(Policy):
    """Wandering a cluttered room without touching anything: drive straight while the way ahead
    is clear, turn away from the nearer side when something is close ahead, reactively (every
    label a pure function of the scan, through the sector minima of a feature spec, by default
    the all-round ``around``: nine sectors of 22.5 degrees, right ``s[0]`` .. ahead ``s[4]`` ..
    left ``s[8]``, metres, so a tree with that perception can represent it exactly). It covers
    ground the way a ball on a table does: each obstacle sends it off at another angle.

      something in the way (min(s[3], s[4], s[5]) < stop)   -> rotate towards ``prefer``
                                                               (left or right; one way always:
                                                               a tree cannot then dither
                                                               between the two rotations)
      something close ahead (min(s[3], s[4], s[5]) < slow) -> fwd-left / fwd-right, away from
                                                               the nearer ahead-diagonal
      something close beside (s[0] or s[8] < side)         -> fwd-left / fwd-right, away from it
      otherwise                                            -> fwd
    """

    task = "wandering"

    def __init__(self, features=None, stop: float = 0.6, slow: float = 1.1, side: float = 0.35,
                 prefer: str = "left", actions: ActionSet = DEFAULT_ACTIONS):
        super().__init__(actions)
        from .features import FEATURES

        self.features = features if features is not None else FEATURES["around"]
        if len(self.features.beams) != 9:
            raise ValueError(f"Wanderer needs a feature spec of 9 sectors, got "
                             f"{len(self.features.beams)}")
        if prefer not in ("left", "right"):
            raise ValueError(f"prefer must be 'left' or 'right', got {prefer!r}")
        self.stop, self.slow, self.side = stop, slow, side
        self.rotate = f"rot-{prefer}"

    def sectors(self, ranges) -> np.ndarray:
        """The nine sector minima in metres, right to left."""
        f = self.features
        return f.extract(np.asarray(ranges), 0.0)[:9] * f.scale

    def decide(self, s) -> str:
        """The label of sector minima ``s`` (nine, metres, right to left)."""
        s = [float(v) for v in s[:9]]
        ahead = min(s[3], s[4], s[5])
        if ahead < self.stop:
            return self.rotate
        if ahead < self.slow:
            return "fwd-left" if s[3] <= s[5] else "fwd-right"
        if min(s[0], s[8]) < self.side:
            return "fwd-left" if s[0] <= s[8] else "fwd-right"
        return "fwd"

    def act(self, ranges, pose=None) -> str:
        return self.decide(self.sectors(ranges))

    reactive = act
    acts_reactively = True
