"""Models of people teaching at the console (``rhbl console``): benchmark code, not product code
(``benchmarks/bench_teach.py``, ``benchmarks/bench_teach_study.py`` and the tests import it).

Two families. ``ANY`` (:class:`Follower`, the end of this module) teach ANY behaviour: what they
mean is the behaviour file's scripted expert on the scan they read off the page's map, what they
press is a person's hands on it; ``ANY_DEV`` is their development set, ``ANY_HELD_OUT`` was
written after it and is measured, never tuned on. ``person(name, behaviour, seed)`` makes
either family's model; for a behaviour with goals in order it is a :class:`GoalFollower` (the
goal the page shows, the beacon read off the map, G pressed when the robot is there). The rest of this docstring is about the right-hand wall's own models
(``PEOPLE``: wall following only).

A model is a person who follows the RIGHT-hand wall by looking at the page's map (the robot, the
walls, the laser hits) with a key held down. It knows nothing of the scripted teacher (it imports
nothing from ``client``): its notion of "keep the wall on my right" is its own, read off the map
geometry (the nearest wall point on the robot's right and that wall's direction, the free run
ahead), and it teaches as people do: late (a reaction time of 200-450 ms on a view that is itself
a frame old), with wrong keys, over-steering, hesitations (keys released: the console stops the
robot and sends no label), in a cautious or a hurried style.

One small interface, fed with what the page shows at each frame:

    person = PEOPLE["steady"](seed=0)
    person.reset()
    key = person.observe(view)     # "fwd" | "fwd-left" | "rot-left" | "fwd-right" | "rot-right" | None

``view`` is a :class:`View`: the page's clock, the robot as drawn, the map's walls, the page's
mode ("demonstrate" or "correct"), who drives and the action executed (the side panel). ``None``
means no key is held. The model holds a key until it decides otherwise (the page then repeats it
with every scan it displays); the same object can drive the real page in a browser (read the
displayed state, call ``observe``, press or release keys) or the in-process study.

In correct mode (the learned tree drives) the person keeps the hands off and takes over only
when they judge it necessary, as in HG-DAgger: the robot too close to a wall, drifting off the
wall, spinning in place (rotating without getting anywhere, or the action flickering between
rot-left and rot-right) or going round in circles; they drive until the robot is back on the wall, then let go.

Models: ``DEV`` are the ones methods may be chosen on; ``HELD_OUT`` are evaluated once, at the
end (docs/teaching.md). ``FRESH`` (:class:`Pilot`) were written after every method and default
was chosen and are measured, never tuned on: their steering is their own (pure pursuit of a point
along the wall, not the models' distance-and-heading rule), their reaction times are skewed
(log-normal) with lapses of attention during which the key stays held, one presses no arc keys
at all (forward or a rotation in place, never both) and one drifts in how far from the wall it
likes to be.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field, replace

import numpy as np

__all__ = ["ANY", "ANY_DEV", "ANY_HELD_OUT", "DEV", "FRESH", "HELD_OUT", "KEYS", "PEOPLE",
           "Follower", "FollowerStyle", "GoalFollower", "Person", "Pilot", "PilotStyle", "Seen", "Style", "View",
           "percept", "person", "scan_of"]

KEYS = ("fwd", "fwd-left", "rot-left", "fwd-right", "rot-right")
_MIRROR = {"fwd": "fwd", "fwd-left": "fwd-right", "fwd-right": "fwd-left",
           "rot-left": "rot-right", "rot-right": "rot-left"}
# a finger on the neighbouring key: forward <-> its arc, an arc <-> the rotation on its side
_NEIGHBOUR = {"fwd": ("fwd-left", "fwd-right"), "fwd-left": ("fwd", "rot-left"),
              "fwd-right": ("fwd", "rot-right"), "rot-left": ("fwd-left",),
              "rot-right": ("fwd-right",)}
_TURNS = ("fwd-left", "rot-left", "fwd-right", "rot-right")


@dataclass(frozen=True)
class View:
    """What the page shows at one frame.

    ``t``: the page's clock (s); ``pose``: the robot as drawn (x, y, yaw); ``walls``: the map's
    wall segments (S, 4) as x0, y0, x1, y1; ``mode``: the page's mode; ``driver``: who drives
    (``"teacher"``, ``"controller"`` or ``""``); ``action``: the action executed now (the side
    panel's "action"); ``scan_id``: the scan displayed (for the record only); ``stuck``: the
    page's notice that the robot is stuck; ``goal``: the world's goal as drawn."""

    t: float
    pose: tuple[float, float, float]
    walls: np.ndarray
    mode: str = "demonstrate"
    driver: str = ""
    action: str | None = None
    scan_id: int | None = None
    stuck: str | None = None        # the page's "the robot is stuck here" notice (why), if any
    goal: tuple[float, float, float] | None = None  # the world's goal drawn (x, y, radius)
    # goals in order: the beacons drawn (id -> x, y) and the goal the page says the person
    # drives to (its "your goal": (visit, beacon id)), None without goals
    beacons: dict | None = None
    yours: tuple[int, int] | None = None


@dataclass(frozen=True)
class Percept:
    """What a person reads off the map (metres, radians)."""

    front: float        # free run straight ahead within the robot's width
    front_right: float  # free run along a line 40 deg to the right of the heading
    right: float        # nearest wall point on the robot's right (bearing -150..-30 deg)
    angle: float        # heading against that wall's direction (> 0: heading away from it)
    behind: float       # nearest wall point behind-right (bearing -180..-100 deg)
    tip: bool = False   # that right-hand point is a wall's free end (a fin's or an inner
                        # wall's tip), abeam or behind (bearing -150..-60 deg): the wall ends


def _wrap(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


def _ray(walls: np.ndarray, ox: float, oy: float, ang: float, far: float = 8.0) -> float:
    """Distance from (ox, oy) along direction ``ang`` to the first wall (``far`` if none)."""
    ux, uy = math.cos(ang), math.sin(ang)
    x0, y0 = walls[:, 0] - ox, walls[:, 1] - oy
    dx, dy = walls[:, 2] - walls[:, 0], walls[:, 3] - walls[:, 1]
    den = ux * dy - uy * dx
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (x0 * dy - y0 * dx) / den      # along the ray
        u = (x0 * uy - y0 * ux) / den      # along the segment
    hit = (np.abs(den) > 1e-12) & (s >= 0) & (u >= 0) & (u <= 1)
    return float(min(far, s[hit].min())) if hit.any() else far


def _free_ends(walls: np.ndarray) -> np.ndarray:
    """(S, 2) booleans: the start and the end of each segment is a free end (a point no other
    segment's end meets: a fin's or an inner wall's tip, not a corner)."""
    ends = np.round(np.concatenate([walls[:, :2], walls[:, 2:]]), 6)
    _, inverse, counts = np.unique(ends, axis=0, return_inverse=True, return_counts=True)
    return (counts[inverse.reshape(-1)] == 1).reshape(2, -1).T


def percept(view: View) -> Percept:
    """The person's reading of the map at ``view`` (their own geometry, not the laser's)."""
    x, y, yaw = view.pose
    w = view.walls
    p0 = w[:, :2]
    d = w[:, 2:] - p0
    rel = np.array([x, y]) - p0
    t = np.clip((rel * d).sum(1) / np.maximum((d * d).sum(1), 1e-12), 0.0, 1.0)
    q = p0 + t[:, None] * d
    v = q - np.array([x, y])
    dist = np.hypot(v[:, 0], v[:, 1])
    bearing = np.arctan2(v[:, 1], v[:, 0]) - yaw
    bearing = np.arctan2(np.sin(bearing), np.cos(bearing))
    right_side = (bearing > math.radians(-150)) & (bearing < math.radians(-30))
    right = angle = math.inf
    tip = False
    if right_side.any():
        k = int(np.argmin(np.where(right_side, dist, np.inf)))
        right = float(dist[k])
        # the wall's direction as the person sees it: across the line to its nearest point,
        # with the wall on the right (along a straight wall: the wall itself; round a corner
        # or a fin's tip: the circle about it)
        angle = _wrap(yaw - math.atan2(v[k, 0], -v[k, 1]))
        end = 0 if t[k] <= 1e-9 else 1 if t[k] >= 1.0 - 1e-9 else None
        tip = (end is not None and bool(_free_ends(w)[k, end])
               and bearing[k] < math.radians(-60))
    behind_side = (bearing > math.radians(-180)) & (bearing < math.radians(-100))
    behind = float(dist[behind_side].min()) if behind_side.any() else math.inf
    c, s = math.cos(yaw), math.sin(yaw)
    front = min(_ray(w, x - s * o, y + c * o, yaw) for o in (-0.2, 0.0, 0.2))
    front_right = _ray(w, x, y, yaw - math.radians(40))
    return Percept(front=front, front_right=front_right, right=right,
                   angle=0.0 if math.isinf(angle) else angle, behind=behind, tip=tip)


@dataclass(frozen=True)
class Style:
    """How one person drives and teaches (times in s, distances in m)."""

    name: str
    # timing
    reaction: float = 0.25          # mean reaction time on what the page showed
    reaction_sd: float = 0.04       # its spread (it drifts slowly over a session)
    period: float = 0.1             # how often the person re-decides
    min_hold: float = 0.15          # a key is held at least this long
    # errors
    wrong: float = 0.10             # probability that a key press is the wrong key
    mirror: float = 0.5             # of the wrong keys: left/right confused (else a neighbour)
    notice: float = 0.15            # extra time to notice a wrong key, on top of the reaction
    oversteer: float = 0.2          # a turn key is released up to this much too late
    hesitate: float = 0.02          # rate (per s) of letting go of every key
    pause: tuple[float, float] = (0.3, 0.8)   # how long a hesitation lasts
    taps: float = 0.0               # a turn is pressed in taps: held this long, then let go ...
    tap_gap: tuple[float, float] = (0.1, 0.25)  # ... for this long
    noise: float = 0.08             # relative error of judging a distance on the map
    # the person's own wall following
    target: float = 0.65            # where they like the wall on their right
    stop: float = 0.55              # wall ahead closer than this: rotate left in place
    slow: float = 1.0               # wall ahead closer than this: arc left
    diag: float = 0.6               # a wall ahead-right closer than this: arc left
    lost: float = 1.3               # nothing on the right within this: turn right to find it
    k_d: float = 2.0                # steering on the distance error ...
    k_a: float = 1.5                # ... and on the heading against the wall
    band: float = 0.25              # dead band of the steering
    sharp: bool = False             # round a wall's end rotating in place (else arcing)
    corner_rot: bool = False        # a wall ahead: always rotate in place, never arc
    # correct mode (HG-DAgger: take over only when needed)
    close: float = 0.35             # the robot nearer than this to a wall: take over
    far: float = 1.6                # ... farther than this from the right wall ...
    patience: float = 2.0           # ... for this long: take over
    spin_window: float = 4.0        # spinning: moved less than ``spin_move`` in this window
    spin_move: float = 0.3
    circle_window: float = 8.0      # circling: turned a full circle in this window without
    circle_move: float = 1.5        # getting farther than this from where it began
    settle: float = 1.5             # drive at least this long once taken over, then let go when fine


@dataclass
class _Memory:
    views: deque = field(default_factory=lambda: deque(maxlen=200))
    seen_t: float = -math.inf       # the page time of the view perceived last
    rt: float = 0.25
    next_decision: float = -math.inf
    intent: str | None = None       # what the person means to press
    key: str | None = None          # what is pressed
    pressed_at: float = -math.inf
    wrong_key: str | None = None
    wrong_until: float = -math.inf
    late_key: str | None = None     # a turn held too long (over-steering)
    late_until: float = -math.inf
    pause_until: float = -math.inf
    tap_on_until: float = -math.inf
    tap_off_until: float = -math.inf
    # correct mode
    in_control: bool = False
    took_at: float = -math.inf
    far_since: float | None = None
    fine_since: float | None = None
    trail: deque = field(default_factory=lambda: deque(maxlen=120))
    actions: deque = field(default_factory=lambda: deque(maxlen=60))


class Person:
    """A person at the console (see the module's docstring): ``observe(view) -> key or None``.

    ``wrong_now`` is True while the key pressed is a wrong key (for the study's record);
    ``intent`` is the key the person meant."""

    def __init__(self, style: Style, seed: int = 0):
        self.style = style
        self.seed = seed
        self.reset()

    def reset(self) -> None:
        self.rng = np.random.default_rng(self.seed)
        self.m = _Memory(rt=self.style.reaction)

    @property
    def intent(self) -> str | None:
        return self.m.intent

    @property
    def wrong_now(self) -> bool:
        return self.m.wrong_key is not None and self.m.key == self.m.wrong_key

    # -- perception: the view of one reaction time ago ------------------------------------
    def _looking(self, now: float) -> bool:
        """Whether the person looks at the page now (always), this decision's reaction time
        set in ``m.rt``: it drifts slowly around the person's mean (never below 0.15 s)."""
        m, s = self.m, self.style
        m.rt += 0.2 * (s.reaction - m.rt) + float(self.rng.normal(0.0, s.reaction_sd * 0.45))
        m.rt = max(0.15, m.rt)
        return True

    def _perceived(self, now: float) -> View | None:
        m = self.m
        if not self._looking(now):
            return None
        seen = None
        for v in m.views:
            if v.t <= now - m.rt + 1e-9 and v.t >= m.seen_t:
                seen = v
        if seen is None:
            return None
        m.seen_t = seen.t
        return seen

    def _judge(self, view: View) -> Percept:
        p = percept(view)
        n = self.style.noise

        def j(v: float) -> float:
            return v if math.isinf(v) else v * (1.0 + float(self.rng.normal(0.0, n)))

        return replace(p, front=j(p.front), front_right=j(p.front_right), right=j(p.right),
                       behind=j(p.behind), angle=p.angle + float(self.rng.normal(0.0, n)))

    # -- the person's own wall following ---------------------------------------------------
    def wanted(self, p: Percept) -> str:
        """The key this person means for what they see."""
        s = self.style
        if p.tip and p.right < s.lost:
            # the wall on the right ends here (an inner wall's or a fin's tip): go round its
            # end, keeping it at the liked distance, whatever lies ahead beyond the turn (a
            # wall too close ahead: rotate towards the way round, to the right)
            if p.front < s.stop:
                return "rot-right"
            u = s.k_d * (p.right - s.target) + s.k_a * p.angle
            if u > s.band:
                return "rot-right" if s.sharp and p.right > s.target + 0.2 else "fwd-right"
            return "fwd-left" if u < -s.band else "fwd"
        if p.front < s.stop:
            return "rot-left"
        if p.front < s.slow or p.front_right < s.diag:
            return "rot-left" if s.corner_rot else "fwd-left"
        if p.right > s.lost:
            if p.behind < s.lost + 0.3:  # the wall just ended (a corner, a fin's tip): round it
                return "rot-right" if s.sharp else "fwd-right"
            return "fwd"  # out in the open: straight on until a wall is ahead, then put it right
        u = s.k_d * (p.right - s.target) + s.k_a * p.angle
        if u > s.band:
            return "fwd-right"
        if u < -s.band:
            return "fwd-left"
        return "fwd"

    # -- correct mode: hands off unless needed ---------------------------------------------
    def _trouble(self, p: Percept, seen: View) -> bool:
        s, m = self.style, self.m
        if p.front < s.stop * 0.9 or min(p.right, p.front_right) < s.close:
            return True
        if p.right > s.far:
            if m.far_since is None:
                m.far_since = seen.t
            if seen.t - m.far_since >= s.patience:
                return True
        else:
            m.far_since = None
        window = [(t, xy) for t, xy, _ in m.trail if t >= seen.t - s.spin_window]
        if len(window) >= 2 and seen.t - window[0][0] >= s.spin_window * 0.9:
            moved = max(math.dist(window[0][1], xy) for _, xy in window)
            if moved < s.spin_move:
                return True
        circle = [(xy, yaw) for t, xy, yaw in m.trail if t >= seen.t - s.circle_window]
        if len(circle) >= 2:
            turned = sum(abs(_wrap(b[1] - a[1])) for a, b in zip(circle, circle[1:], strict=False))
            moved = max(math.dist(circle[0][0], xy) for xy, _ in circle)
            if turned > 2 * math.pi and moved < s.circle_move:
                return True
        acts = [a for t, a in m.actions if t >= seen.t - 3.0]
        flips = sum(1 for a, b in zip(acts, acts[1:], strict=False)
                    if {a, b} == {"rot-left", "rot-right"})
        return flips >= 3

    def _fine(self, p: Percept) -> bool:
        s = self.style
        return (p.front > s.slow and p.front_right > s.diag and s.close < p.right < s.lost
                and abs(p.right - s.target) < 0.3 and abs(p.angle) < 0.4)

    def _correcting(self, p: Percept, seen: View) -> str | None:
        """The key meant in correct mode (None: hands off)."""
        m, s = self.m, self.style
        m.trail.append((seen.t, (seen.pose[0], seen.pose[1]), seen.pose[2]))
        if seen.action:
            m.actions.append((seen.t, seen.action))
        if not m.in_control:
            if not self._trouble(p, seen):
                return None
            m.in_control, m.took_at, m.fine_since = True, seen.t, None
            m.trail.clear()
            m.actions.clear()
            m.far_since = None
        if self._fine(p):
            if m.fine_since is None:
                m.fine_since = seen.t
        else:
            m.fine_since = None
        if (seen.t - m.took_at >= s.settle and m.fine_since is not None
                and seen.t - m.fine_since >= 0.5):
            m.in_control = False
            m.trail.clear()
            m.actions.clear()
            return None
        return self.wanted(p)

    # -- the hands: intent -> the key held -------------------------------------------------
    def _confuse(self, key: str) -> str:
        if self.rng.random() < self.style.mirror and _MIRROR[key] != key:
            return _MIRROR[key]
        options = _NEIGHBOUR[key]
        return options[int(self.rng.integers(len(options)))]

    def _press(self, now: float, intent: str | None) -> str | None:
        m, s = self.m, self.style
        if now < m.pause_until:
            return None
        if now < m.wrong_until:
            return m.wrong_key
        m.wrong_key = None
        if now < m.late_until and intent != m.late_key:
            return m.late_key
        if intent is None:
            return None
        if intent in _TURNS and s.taps > 0:  # tapping a turn: on, off, on ...
            if m.tap_on_until <= now < m.tap_off_until:
                return None  # between two taps
            if now >= m.tap_off_until:  # the next tap
                m.tap_on_until = now + s.taps * float(self.rng.uniform(0.7, 1.3))
                m.tap_off_until = m.tap_on_until + float(self.rng.uniform(*s.tap_gap))
        return intent

    def observe(self, view: View) -> str | None:
        """The key held after this frame (None: no key)."""
        m, s = self.m, self.style
        m.views.append(view)
        now = view.t
        if now >= m.next_decision:
            m.next_decision = now + s.period
            seen = self._perceived(now)
            if seen is not None:
                p = self._judge(seen)
                intent = (self._correcting(p, seen) if seen.mode == "correct"
                          else self.wanted(p))
                if seen.mode != "correct":
                    m.in_control = False
                if intent is not None and self.rng.random() < s.hesitate * s.period:
                    m.pause_until = now + float(self.rng.uniform(*s.pause))  # lets go a moment
                old = m.intent
                if intent != old:
                    if old in _TURNS and s.oversteer > 0:
                        m.late_key = old  # the turn key is let go of late
                        m.late_until = now + float(self.rng.uniform(0.0, s.oversteer))
                    if intent is not None and self.rng.random() < s.wrong:
                        m.wrong_key = self._confuse(intent)
                        m.wrong_until = now + m.rt + s.notice * float(self.rng.uniform(0.5, 1.5))
                    m.intent = intent
        key = self._press(now, m.intent)
        if key != m.key:
            if now - m.pressed_at < s.min_hold and m.key is not None and key is not None:
                return m.key  # fingers are not faster than this
            m.key, m.pressed_at = key, now
        return m.key


@dataclass(frozen=True)
class PilotStyle(Style):
    """A :class:`Pilot`'s style: :class:`Style`'s hands and correct mode, and its own steering
    and attention."""

    lookahead: float = 1.0          # the point aimed at lies this far ahead along the wall
    aim: float = 0.12               # |bearing to that point| below this (rad): straight on
    spin: float = 0.9               # above this: rotate in place (between: an arc)
    arcs: bool = True               # False: never an arc key (forward or a rotation, not both)
    rt_sigma: float = 0.3           # log-normal spread of the reaction time (its median: reaction)
    lapse: float = 0.0              # rate (per s) of looking away, the key held meanwhile ...
    lapse_for: tuple[float, float] = (0.5, 1.2)  # ... for this long
    drift: float = 0.0              # the liked wall distance wanders this much (m, sd) ...
    drift_time: float = 30.0        # ... over about this long


class Pilot(Person):
    """A person who steers by aiming at a point on the path they want (pure pursuit of a point
    ``lookahead`` ahead along the right-hand wall at the distance they like), with skewed reaction
    times and lapses of attention (:class:`PilotStyle`). The hands (wrong keys, over-steering,
    hesitations, a key held at least ``min_hold``) and correct mode are :class:`Person`'s."""

    style: PilotStyle

    def reset(self) -> None:
        super().reset()
        self._lapse_until = -math.inf
        self._target = self.style.target
        self._last_t = None

    def _looking(self, now: float) -> bool:
        """Not during a lapse of attention (nothing new decided, the key stays held); the
        reaction time drawn afresh for each decision, log-normal about ``reaction``; the liked
        distance wandering meanwhile."""
        m, s = self.m, self.style
        step = 0.0 if self._last_t is None else max(0.0, now - self._last_t)
        self._last_t = now
        if s.drift > 0 and step > 0:  # an Ornstein-Uhlenbeck wander around the liked distance
            a = step / s.drift_time
            self._target += a * (s.target - self._target) + s.drift * math.sqrt(2 * a) * float(
                self.rng.normal())
        if now < self._lapse_until:
            return False
        if s.lapse > 0 and self.rng.random() < s.lapse * step:
            self._lapse_until = now + float(self.rng.uniform(*s.lapse_for))
            return False
        m.rt = max(0.15, s.reaction * math.exp(s.rt_sigma * float(self.rng.normal())))
        return True

    def _confuse(self, key: str) -> str:
        wrong = super()._confuse(key)
        if self.style.arcs or wrong not in ("fwd-left", "fwd-right"):
            return wrong
        side = "rot-left" if wrong == "fwd-left" else "rot-right"  # the key beside it
        return "fwd" if side == key else side

    def wanted(self, p: Percept) -> str:
        s = self.style
        target = min(max(self._target, 0.4), 1.0)
        if p.front < s.stop:
            return "rot-left"
        if p.front < s.slow or p.front_right < s.diag:
            return "fwd-left" if s.arcs else "rot-left"
        if p.right > s.lost:
            if p.behind < s.lost + 0.3:  # the wall fell away behind: round its end
                return "fwd-right" if s.arcs else "rot-right"
            return "fwd"
        # the bearing of the point aimed at: off the wall by (right - target), lookahead ahead
        turn = -(math.atan2(p.right - target, s.lookahead) + p.angle)  # > 0: to the left
        if abs(turn) < s.aim:
            return "fwd"
        if abs(turn) >= s.spin or not s.arcs:
            return "rot-left" if turn > 0 else "rot-right"
        return "fwd-left" if turn > 0 else "fwd-right"


def _model(style: Style):
    def make(seed: int = 0) -> Person:
        return (Pilot if isinstance(style, PilotStyle) else Person)(style, seed=seed)

    make.style = style  # type: ignore[attr-defined]
    return make


# the models methods may be chosen on
DEV = {
    "steady": _model(Style("steady", reaction=0.25, wrong=0.08, oversteer=0.2, hesitate=0.02)),
    "hurried": _model(Style(
        "hurried", reaction=0.21, reaction_sd=0.03, wrong=0.15, notice=0.1, oversteer=0.3,
        hesitate=0.005, target=0.5, stop=0.45, slow=0.75, diag=0.5, band=0.35, k_a=1.0,
        close=0.3, far=1.8, patience=3.0, settle=1.0)),
    "cautious": _model(Style(
        "cautious", reaction=0.40, reaction_sd=0.05, period=0.15, wrong=0.05, oversteer=0.1,
        hesitate=0.06, pause=(0.5, 1.5), target=0.8, stop=0.8, slow=1.3, diag=0.75, lost=1.5,
        band=0.2, corner_rot=True, sharp=True, close=0.45, far=1.5, patience=1.5, settle=2.0)),
    "oversteerer": _model(Style(
        "oversteerer", reaction=0.30, reaction_sd=0.05, wrong=0.12, oversteer=0.5,
        hesitate=0.02, target=0.65, k_d=3.0, k_a=2.5, band=0.15)),
}

# evaluated once, at the end, never looked at while choosing methods
HELD_OUT = {
    "novice": _model(Style(
        "novice", reaction=0.45, reaction_sd=0.08, period=0.12, wrong=0.13, mirror=0.7,
        notice=0.3, oversteer=0.35, hesitate=0.08, pause=(0.4, 1.2), target=0.7, slow=1.1,
        band=0.3, noise=0.12, far=1.7, patience=2.5, settle=2.0)),
    "tapper": _model(Style(
        "tapper", reaction=0.24, reaction_sd=0.04, wrong=0.10, oversteer=0.15, hesitate=0.03,
        taps=0.3, tap_gap=(0.1, 0.3), target=0.55, stop=0.5, slow=0.9, band=0.2,
        sharp=True, close=0.3)),
}

# written after every default was chosen: measured, never tuned on (see the module's docstring)
FRESH = {
    "pilot": _model(PilotStyle(
        "pilot", reaction=0.32, rt_sigma=0.35, wrong=0.10, oversteer=0.2, hesitate=0.02,
        lapse=0.03, lapse_for=(0.6, 1.5), target=0.7, drift=0.12, drift_time=40.0,
        lookahead=1.0, close=0.35, far=1.6)),
    "bang": _model(PilotStyle(
        "bang", reaction=0.28, rt_sigma=0.25, wrong=0.12, oversteer=0.15, hesitate=0.03,
        min_hold=0.2, arcs=False, aim=0.35, lookahead=1.2, target=0.65, lapse=0.01,
        close=0.35, far=1.6)),
    "jitter": _model(PilotStyle(
        "jitter", reaction=0.22, rt_sigma=0.5, period=0.05, min_hold=0.08, wrong=0.15,
        mirror=0.4, notice=0.1, oversteer=0.1, hesitate=0.1, pause=(0.3, 1.5), aim=0.06,
        spin=0.7, lookahead=0.8, target=0.55, lapse=0.02, close=0.3, far=1.5, settle=1.0)),
    "wide": _model(Style(
        "wide", reaction=0.38, reaction_sd=0.06, period=0.12, wrong=0.10, oversteer=0.4,
        hesitate=0.03, target=0.8, stop=0.6, slow=1.2, diag=0.7, lost=1.5, k_d=1.2, k_a=1.0,
        band=0.35, close=0.4, far=1.9, patience=3.0, settle=2.0)),
}

PEOPLE = {**DEV, **HELD_OUT, **FRESH}


# -- a person for any behaviour ------------------------------------------------------------
#
# The models above follow the right-hand wall by a geometry of their own. A :class:`Follower`
# follows whatever behaviour it is given: what it MEANS to press is what the behaviour file's
# scripted expert (its ``[expert]``, reactive style) answers for the scan the person reads off
# the page's map (the walls ray-cast from the robot as drawn, a frame and a reaction time old,
# with the person's misjudgement of distances and bearings); what it PRESSES is a person's
# hands on that intent (:class:`FollowerStyle`): a skewed reaction time and its spread, lapses
# of attention with the key held, wrong keys, a key held at least so long (taps or long
# holds), turns let go of late (over-steering), hesitations, and for some never an arc key.
# In correct mode it takes over as the right-hand wall's models do (HG-DAgger): the robot too
# close to something, going its own way against the person's for a while, stuck (the page's
# "stuck" notice), spinning, circling or flickering; then it lets go once it is fine.

SCAN_BEAMS, SCAN_FOV, SCAN_REACH = 360, 180.0, 8.0  # the robot's laser, as the page draws it


def scan_of(view: View, beams: int = SCAN_BEAMS, fov: float = SCAN_FOV,
            reach: float = SCAN_REACH) -> np.ndarray:
    """The ranges a laser at the robot as drawn would read off the map's walls (float32,
    ``beams`` over ``fov`` degrees, the first at the robot's right), ``reach`` where none."""
    x, y, yaw = view.pose
    w = view.walls
    ang = yaw + np.radians(np.linspace(-fov / 2.0, fov / 2.0, beams))
    ux, uy = np.cos(ang)[:, None], np.sin(ang)[:, None]
    x0, y0 = (w[:, 0] - x)[None, :], (w[:, 1] - y)[None, :]
    dx, dy = (w[:, 2] - w[:, 0])[None, :], (w[:, 3] - w[:, 1])[None, :]
    den = ux * dy - uy * dx
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (x0 * dy - y0 * dx) / den
        u = (x0 * uy - y0 * ux) / den
    hit = (np.abs(den) > 1e-12) & (s >= 0) & (u >= 0) & (u <= 1)
    r = np.where(hit, s, np.inf).min(axis=1)
    return np.minimum(r, reach).astype(np.float32)


@dataclass(frozen=True)
class Seen:
    """What a :class:`Follower` reads off the map: the scan it judges, its nearest return."""

    scan: np.ndarray
    nearest: float


@dataclass(frozen=True)
class FollowerStyle(PilotStyle):
    """A :class:`Follower`'s hands and eyes (:class:`PilotStyle`'s reaction time, lapses,
    wrong keys, holds, taps, over-steering, hesitations and correct mode; its steering fields
    play no part: the behaviour's expert steers)."""

    bearing: float = 3.0            # misjudged bearings: the scan turned by this much (deg, sd)
    arc_turn: tuple[float, float] = (0.15, 0.3)  # arcs=False: an arc is a rotation this long ...
    arc_fwd: tuple[float, float] = (0.2, 0.4)    # ... then forward this long, again and again
    commit: float = 10.0            # once turned round on the spot (>= ``round_turn`` rad), no
    round_turn: float = 2.0         # ... new rotation for this long (s) unless blocked ahead
    blocked: float = 0.5            # ... (the way straight ahead shorter than this, m)
    close: float = 0.3              # correct mode: something nearer than this: take over
    against: float = 0.7            # ... the robot turning against the person's wish this
    patience: float = 2.0           # ... fraction of the last ``patience`` s: take over


_TURN_SIGN = {"fwd": 0, "fwd-left": 1, "rot-left": 1, "fwd-right": -1, "rot-right": -1}


class Follower(Pilot):
    """A person following ``behaviour`` (a shipped behaviour's name or a
    ``client.behaviour.spec.Behaviour``) at the page: see the section's comment above."""

    style: FollowerStyle

    def __init__(self, style: FollowerStyle, behaviour, seed: int = 0):
        from client.behaviour.spec import Behaviour
        from client.behaviour.spec import behaviour as load

        self.behaviour = behaviour if isinstance(behaviour, Behaviour) else load(behaviour)
        self.expert = self.behaviour.expert("reactive")
        super().__init__(style, seed=seed)

    def reset(self) -> None:
        super().reset()
        self.expert.reset()
        self._against: deque = deque(maxlen=400)  # (t, the robot turned against the wish)
        self._arc_phase: tuple[str, float] | None = None
        self._seen_t, self._yaw = 0.0, None     # the view judged last: its time, heading
        self._turning = 0.0                      # heading turned in the rotation meant now
        self._turned_round_at = -math.inf

    def _judge(self, view: View) -> Seen:
        s = self.style
        # how far the rotation the person means has turned the robot (a turn-round remembered)
        if self._yaw is not None and self.m.intent in ("rot-left", "rot-right"):
            self._turning += abs(_wrap(view.pose[2] - self._yaw))
        elif self._turning:
            if self._turning >= s.round_turn:
                self._turned_round_at = self._seen_t
            self._turning = 0.0
        self._seen_t, self._yaw = view.t, view.pose[2]
        r = scan_of(view).astype(np.float64)
        r *= max(0.5, 1.0 + float(self.rng.normal(0.0, s.noise)))  # distances misjudged
        shift = int(round(float(self.rng.normal(0.0, s.bearing)) * (r.size - 1) / SCAN_FOV))
        if shift:  # bearings misjudged: the picture turned a little
            r = np.roll(r, shift)
            if shift > 0:
                r[:shift] = r[shift]
            else:
                r[shift:] = r[shift - 1]
        r = np.minimum(r, SCAN_REACH).astype(np.float32)
        return Seen(scan=r, nearest=float(r.min()))

    def wanted(self, p: Seen) -> str:
        """The expert's answer, but a person who has just turned round on the spot does not
        turn round again at once (``commit``) while the way straight ahead is open."""
        want = self.expert.act(p.scan, None)
        s = self.style
        if want.startswith("rot") and self._seen_t - self._turned_round_at < s.commit:
            n = p.scan.size
            ahead = p.scan[int(n * 0.4):int(n * 0.6) + 1]  # +-18 deg about the heading
            if float(ahead.min()) > s.blocked:
                return "fwd"
        return want

    def _trouble(self, p: Seen, seen: View) -> bool:
        s, m = self.style, self.m
        if p.nearest < s.close or getattr(seen, "stuck", None):
            return True
        wish = self.wanted(p)
        if seen.action in _TURN_SIGN:
            self._against.append((seen.t, _TURN_SIGN[seen.action] * _TURN_SIGN[wish] < 0
                                  or (_TURN_SIGN[wish] != 0 and seen.action == "fwd"
                                      and wish.startswith("rot"))))
        recent = [a for t, a in self._against if t >= seen.t - s.patience]
        if (len(recent) >= 5 and self._against[0][0] <= seen.t - s.patience
                and sum(recent) >= s.against * len(recent)):
            return True
        window = [(t, xy) for t, xy, _ in m.trail if t >= seen.t - s.spin_window]
        if (len(window) >= 2 and seen.t - window[0][0] >= s.spin_window * 0.9
                and max(math.dist(window[0][1], xy) for _, xy in window) < s.spin_move):
            return True
        circle = [(xy, yaw) for t, xy, yaw in m.trail if t >= seen.t - s.circle_window]
        if len(circle) >= 2:
            turned = sum(abs(_wrap(b[1] - a[1])) for a, b in zip(circle, circle[1:], strict=False))
            if turned > 2 * math.pi and max(math.dist(circle[0][0], xy)
                                            for xy, _ in circle) < s.circle_move:
                return True
        acts = [a for t, a in m.actions if t >= seen.t - 3.0]
        return sum(1 for a, b in zip(acts, acts[1:], strict=False)
                   if {a, b} == {"rot-left", "rot-right"}) >= 3

    def _fine(self, p: Seen) -> bool:
        self._against.clear()
        return p.nearest > self.style.close + 0.05 and not self.wanted(p).startswith("rot")

    def _press(self, now: float, intent: str | None) -> str | None:
        key = super()._press(now, intent)
        if self.style.arcs or key not in ("fwd-left", "fwd-right"):
            self._arc_phase = None
            return key
        # no arc keys: an arc is pressed as a short rotation, then forward, and so on
        rot = "rot-left" if key == "fwd-left" else "rot-right"
        phase = self._arc_phase
        if phase is None or now >= phase[1]:
            nxt = rot if phase is None or phase[0] == "fwd" else "fwd"
            span = self.style.arc_turn if nxt == rot else self.style.arc_fwd
            phase = self._arc_phase = (nxt, now + float(self.rng.uniform(*span)))
        return phase[0]


# A person for any behaviour, the DEVELOPMENT set: the figures of docs/studies/
# people-for-every-behaviour.md were looked at for these while the benchmark was being made
ANY_DEV = {
    # unhurried and accurate: a log-normal reaction time about 0.3 s, few wrong keys
    "calm": FollowerStyle("calm", reaction=0.30, rt_sigma=0.25, wrong=0.05, oversteer=0.15,
                          hesitate=0.02, noise=0.06),
    # fast and sloppy: wrong keys (half of them left/right confused), turns let go of late
    "rushed": FollowerStyle("rushed", reaction=0.20, rt_sigma=0.3, min_hold=0.1, wrong=0.15,
                            mirror=0.5, notice=0.1, oversteer=0.35, hesitate=0.01,
                            noise=0.10, close=0.28, patience=3.0, settle=1.0),
    # slow, spread-out reactions and lapses of attention (the key stays held meanwhile)
    "lapsing": FollowerStyle("lapsing", reaction=0.45, rt_sigma=0.45, period=0.15,
                             wrong=0.08, oversteer=0.2, hesitate=0.05, pause=(0.4, 1.2),
                             lapse=0.05, lapse_for=(0.5, 1.5), noise=0.08, close=0.35,
                             settle=2.0),
    # never an arc key: forward, or a rotation in place, in turns
    "arcless": FollowerStyle("arcless", reaction=0.28, rt_sigma=0.3, wrong=0.08,
                             oversteer=0.15, hesitate=0.02, arcs=False, min_hold=0.15),
}

# A person for any behaviour, HELD OUT: written after ANY_DEV and after the benchmark's
# settings were fixed; measured, never tuned on (nothing was changed after their figures)
ANY_HELD_OUT = {
    # turns in taps: held 0.25 s, let go for 0.1-0.3 s, and so on
    "tapping": FollowerStyle("tapping", reaction=0.26, rt_sigma=0.3, wrong=0.10,
                             oversteer=0.1, hesitate=0.03, taps=0.25, tap_gap=(0.1, 0.3),
                             noise=0.08),
    # long holds: every key held at least half a second, turns let go of up to 0.5 s late
    "heavy": FollowerStyle("heavy", reaction=0.35, rt_sigma=0.25, min_hold=0.5, wrong=0.10,
                           oversteer=0.5, hesitate=0.02, noise=0.08, settle=2.0),
    # a muddle: left and right confused, distances and bearings misjudged, lapses
    "muddled": FollowerStyle("muddled", reaction=0.32, rt_sigma=0.4, wrong=0.14, mirror=0.8,
                             notice=0.3, oversteer=0.25, hesitate=0.04, lapse=0.03,
                             noise=0.14, bearing=6.0),
}

ANY = {**ANY_DEV, **ANY_HELD_OUT}


class GoalFollower(Follower):
    """A :class:`Follower` teaching goals in order (a behaviour with ``[goals]``): the goal it
    drives to is the one the page shows ("your goal"); it reads off the map where that beacon
    is and whether the robot could see it (in front, within the fiducial finder's reach, no
    wall in between) and steers as the behaviour's expert does for that sighting; when it
    judges the robot within the goal's distance of the beacon (distances misjudged as any),
    it presses G one reaction time later (``mark``), once per goal the page shows."""

    REACH = 8.0  # m: the fiducial finder's (server.robot, max_range_id)
    # a person heading for a beacon gives walls a wider berth than the script (its 0.45 m
    # beside, 1 m ahead to call the way open): 0.9 m and 1.5 m, chosen on the development set
    # driving alone (benchmarks/bench_teach.py's person_alone): the script's margins with a
    # person's reaction time graze the boxes beside the way
    NEAR, CLEAR = 0.9, 1.5

    def __init__(self, style: FollowerStyle, behaviour, seed: int = 0):
        super().__init__(style, behaviour, seed=seed)
        from client.behaviour.goals import BeaconSeeker

        e = self.expert
        self.expert = BeaconSeeker(features=e.features, near=self.NEAR, clear=self.CLEAR,
                                   aim=e.aim, ahead=e.ahead, lost=e.lost, arc=e.arc)

    def reset(self) -> None:
        super().reset()
        self._shown = None          # the page's goal last frame
        self._marked = False        # G pressed for it
        self._mark_at: float | None = None

    def sighting(self, view: View):
        """The goal beacon as the robot would see it, read off the map (None: not in view)."""
        from client.behaviour.goals import Sighting

        if view.yours is None or not view.beacons or view.yours[1] not in view.beacons:
            return None
        bid = view.yours[1]
        bx, by = view.beacons[bid]
        x, y, yaw = view.pose
        rng = math.hypot(bx - x, by - y)
        bearing = _wrap(math.atan2(by - y, bx - x) - yaw)
        if rng > self.REACH or abs(bearing) > math.pi / 2:
            return None
        if _ray(view.walls, x, y, yaw + bearing, far=rng + 0.5) < rng - 0.2:
            return None  # a wall in between
        j = 1.0 + float(self.rng.normal(0.0, self.style.noise))
        return Sighting(bid, rng * max(0.5, j),
                        bearing + math.radians(float(self.rng.normal(0.0, self.style.bearing))))

    def _judge(self, view: View) -> Seen:
        # a person steering at a target leads it: the robot as it will be when the key they
        # press now takes effect, its motion under the key held carried on for their
        # reaction time (the view they judge is that much old)
        from client.behaviour.actions import DEFAULT_ACTIONS

        key = self.m.key
        if key is not None:
            vx, va = DEFAULT_ACTIONS[key]
            x, y, yaw = view.pose
            dt = self.m.rt
            mid = yaw + va * dt / 2
            view = replace(view, pose=(x + vx * dt * math.cos(mid), y + vx * dt * math.sin(mid),
                                       yaw + va * dt))
        p = super()._judge(view)
        self.expert.see(self.sighting(view))
        return p

    def wanted(self, p: Seen) -> str:
        """The expert's answer for the beacon as seen: a person heading for a beacon turns
        to it whenever it comes into view (no ``commit`` to straight on after a turn)."""
        return self.expert.act(p.scan, None)

    def mark(self, view: View) -> bool:
        """Whether the person presses G now (the goal the page shows is reached)."""
        if view.yours != self._shown:
            self._shown, self._marked, self._mark_at = view.yours, False, None
        if view.yours is None or self._marked or view.mode == "watch":
            return False
        if self._mark_at is None:
            bx, by = view.beacons[view.yours[1]]
            within = self.behaviour.goals.within[self.behaviour.goals.index_of(view.yours[1])]
            judged = math.hypot(bx - view.pose[0], by - view.pose[1]) * (
                1.0 + float(self.rng.normal(0.0, self.style.noise)))
            if judged <= within:
                self._mark_at = view.t + float(self.style.reaction * math.exp(
                    self.rng.normal(0.0, self.style.rt_sigma)))
            return False
        if view.t >= self._mark_at:
            self._marked = True
            return True
        return False


def person(name: str, behaviour="wall-following", seed: int = 0) -> Person:
    """The person model ``name`` teaching ``behaviour`` (a name or a Behaviour): one of
    ``ANY`` (any behaviour), or of ``PEOPLE`` (the right-hand wall's own, wall following only).
    ValueError naming the models otherwise."""
    if name in ANY:
        goals = getattr(behaviour, "goals", None) if not isinstance(behaviour, str) else None
        if isinstance(behaviour, str):
            from client.behaviour.spec import behaviour as load

            goals = load(behaviour).goals
        return (GoalFollower if goals is not None else Follower)(ANY[name], behaviour,
                                                                  seed=seed)
    bname = getattr(behaviour, "name", behaviour)
    if name in PEOPLE:
        if bname != "wall-following":
            raise ValueError(f"person model {name!r} follows the right-hand wall only "
                             f"(wall following), not {bname!r}; for any behaviour: "
                             f"{', '.join(ANY)}")
        return PEOPLE[name](seed=seed)
    raise ValueError(f"no person model {name!r}; for any behaviour: {', '.join(ANY)}; "
                     f"wall following only: {', '.join(PEOPLE)}")
