"""Goals in order: a behaviour that pursues a sequence (or a patrol's cycle) of beacons, and the
learner that learns both what to do while pursuing each goal and when a goal is done.

The paper's RHBL is purely reactive (its section 8.1: it "cannot solve a temporal set of goals"
and should "emulate a state machine"). Here the state machine is the behaviour file's own list
of goals and the learning stays RHBL's (docs/goals.md has the design and why):

* the state is the current goal (an index into the behaviour's goals, ``GoalTracker``), as
  options pair a policy with a termination condition;
* the action tree sees the laser's sectors and the current goal's beacon (the perception's
  ``beacon = "goal"``, ``client.behaviour.features``: in view or "none in view", range,
  bearing): the state selects which beacon the inputs report,
  so one tree serves every goal (the paper put its maze mode into the vector as a value; here
  the mode points the perception at a beacon), and a goal's reflexes learned at one beacon
  serve at the others;
* the completion tree (an RHBL tree of its own, labels ``done`` / ``not-done``) learns from the
  teacher's "reached" marks when a goal is done, from the same beacon inputs; the robot moves
  on to the next goal when it says ``done``.

    goals = Goals(beacons=(1, 2), within=(0.6, 0.6))          # or parse_goals(table) (a file's)
    tracker = GoalTracker(goals); tracker.beacon; tracker.advance("reached", t=3.2)
    c = goals.completion_inputs(sightings, tracker.goal)       # the completion tree's 2 inputs
    expert = BeaconSeeker(); expert.see(sightings.get(beacon)); expert.act(ranges, pose)
    learner = GoalLearner(b.features, goals)                  # both trees (beacon = "goal")
    learner = PersonGoalLearner(b.features, goals)            # a person's labels: the person rule
    policy = learner.policy()  /  GoalPolicy.load(path)        # see(sightings), act(ranges, pose)

A snapshot of a goal behaviour is the action tree's snapshot (``rhbl-tree``, msgpack) whose
metadata holds ``goals``: the goals, the inputs' settings and the completion tree's own
snapshot (bytes, loadable with ``rhbl.loads``); a snapshot without it is today's single tree
and loads as before (``client.behaviour.learning.TreePolicy``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from protocol.messages import MAX_VX

from .actions import DEFAULT_ACTIONS, ActionSet
from .features import BEACON_GOAL, FEATURES, FeatureSpec
from .learning import DemonstrationLearner
from .policies import Policy
from .rule import PERSON, SCRIPT, LearningRule, for_goals
from .teaching import PersonLearner

__all__ = [
    "DONE",
    "NOT_DONE",
    "BeaconSeeker",
    "GoalExpert",
    "GoalLearner",
    "GoalPolicy",
    "PersonGoalLearner",
    "GoalStep",
    "GoalTracker",
    "Goals",
    "ReactiveBeaconPolicy",
    "Relocation",
    "Sighting",
    "learner_of",
    "load_policy",
    "parse_goals",
    "resume_learner",
]

DONE, NOT_DONE = "done", "not-done"
PUT = 0.5  # m from one tick to the next: the robot was put there (set_pose), not driven
NEAR = 4.0  # the completion tree sees a goal's beacon's range up to this many times its distance
GOALS_FORMAT = 1  # metadata["goals"]["version"]: a reader refuses a newer one by name


@dataclass(frozen=True)
class Sighting:
    """One beacon seen: its ``id``, ``range`` (m) and ``bearing`` (rad, > 0 to the left)."""

    id: int
    range: float
    bearing: float


@dataclass(frozen=True)
class Goals:
    """A behaviour's goals: ``beacons`` (their ids, in order), ``within`` (metres: a goal is
    reached within this distance of its beacon, one per goal), ``cycle`` (a patrol: after the
    last goal the first again, ``laps`` times round and back to the first)."""

    beacons: tuple[int, ...]
    within: tuple[float, ...]
    cycle: bool = False
    laps: int = 1

    def __post_init__(self) -> None:
        if not self.beacons:
            raise ValueError("goals need at least one beacon")
        if len(self.within) != len(self.beacons):
            raise ValueError(f"{len(self.beacons)} goals but {len(self.within)} distances")
        if not all(w > 0 and math.isfinite(w) for w in self.within):
            raise ValueError(f"every goal's distance must be > 0 m, got {list(self.within)}")
        if self.laps < 1 or (self.laps > 1 and not self.cycle):
            raise ValueError(f"laps must be >= 1 (more than 1 only for a cycle), got {self.laps}")

    @property
    def visits(self) -> tuple[int, ...]:
        """The goals (indices into ``beacons``) in the order they are reached: each once for a
        sequence; for a cycle ``laps`` times round and back to the first."""
        n = len(self.beacons)
        if not self.cycle:
            return tuple(range(n))
        return (*(k % n for k in range(self.laps * n)), 0)

    @property
    def distinct(self) -> tuple[int, ...]:
        """The beacons the goals name, each once, in the order first named."""
        return tuple(dict.fromkeys(self.beacons))

    def completion_inputs(self, sightings: Mapping[int, Sighting] | None, goal: int
                          ) -> np.ndarray:
        """The completion tree's inputs for goal ``goal`` (an index into ``beacons``): in view
        (1, or 0: none in view) and the range of its beacon in units of ``NEAR`` times the
        goal's distance, clamped to 1 (1 when not seen): the same value at every goal's own
        distance, so what the tree learns at one goal holds at the others."""
        beacon = self.beacons[goal]
        s = None if sightings is None else sightings.get(beacon)
        if s is None:
            return np.array([0.0, 1.0])
        return np.array([1.0, min(max(float(s.range), 0.0) / (NEAR * self.within[goal]), 1.0)])

    def index_of(self, beacon: int) -> int:
        """The first goal (an index into ``beacons``) whose beacon is ``beacon``; ValueError
        naming the goals when none is (a label of another behaviour)."""
        try:
            return self.beacons.index(int(beacon))
        except ValueError:
            raise ValueError(f"beacon {beacon} is not one of the goals' beacons "
                             f"{list(self.beacons)}") from None

    def reached(self, sighting: Sighting | None, goal: int) -> bool:
        """The scripted teacher's rule: goal ``goal``'s beacon seen within its distance."""
        return sighting is not None and sighting.range <= self.within[goal]

    def to_dict(self) -> dict:
        return {"beacons": list(self.beacons), "within": list(self.within),
                "cycle": self.cycle, "laps": self.laps}

    @classmethod
    def from_dict(cls, data: Mapping) -> Goals:
        try:
            return cls(beacons=tuple(int(b) for b in data["beacons"]),
                       within=tuple(float(w) for w in data["within"]),
                       cycle=bool(data.get("cycle", False)), laps=int(data.get("laps", 1)))
        except (KeyError, TypeError) as exc:
            raise ValueError(f"goals need 'beacons' and 'within', got {data!r}") from exc


_GOAL_KEYS = {"beacons", "within", "cycle", "laps"}


def parse_goals(t: Any) -> Goals:
    """A behaviour file's ``[goals]`` table: ``beacons`` (beacon ids, in order), ``within``
    (metres, one number for every goal or a list, default 0.6), ``cycle`` (default false),
    ``laps`` (a cycle's, default 1). ValueError naming the field."""
    if not isinstance(t, dict):
        raise ValueError(f"field 'goals': expected a table, got {t!r}")
    extra = sorted(set(t) - _GOAL_KEYS)
    if extra:
        raise ValueError(f"field 'goals.{extra[0]}': unknown; allowed: {', '.join(sorted(_GOAL_KEYS))}")
    beacons = t.get("beacons")
    if (not isinstance(beacons, list) or not beacons
            or any(isinstance(b, bool) or not isinstance(b, int) or b < 1 for b in beacons)):
        raise ValueError(f"field 'goals.beacons': expected a non-empty list of beacon ids "
                         f"(integers >= 1), got {beacons!r}")
    within = t.get("within", 0.6)
    within = within if isinstance(within, list) else [within] * len(beacons)
    if len(within) != len(beacons) or any(
            isinstance(w, bool) or not isinstance(w, int | float) or not 0 < w < math.inf
            for w in within):
        raise ValueError(f"field 'goals.within': expected a distance > 0 (m) or one per goal "
                         f"({len(beacons)}), got {t.get('within')!r}")
    for k, b in enumerate(beacons):
        first = beacons.index(b)
        if within[k] != within[first]:
            raise ValueError(f"field 'goals.within': beacon {b} is named twice with other "
                             f"distances ({within[first]!r} and {within[k]!r}): a goal is "
                             f"told by its beacon, give it one distance")
    cycle = t.get("cycle", False)
    if not isinstance(cycle, bool):
        raise ValueError(f"field 'goals.cycle': expected true or false, got {cycle!r}")
    laps = t.get("laps", 1)
    if isinstance(laps, bool) or not isinstance(laps, int) or laps < 1 or (laps > 1 and not cycle):
        raise ValueError(f"field 'goals.laps': expected an integer >= 1 (more than 1 with "
                         f"cycle = true), got {laps!r}")
    return Goals(beacons=tuple(beacons), within=tuple(float(w) for w in within), cycle=cycle,
                 laps=laps)


@dataclass
class GoalTracker:
    """The state: which goal is being pursued. ``visit`` counts the goals reached (an index
    into ``goals.visits``); ``events`` records each change: ``{"t", "visit", "goal",
    "beacon", "next", "why"}`` (``next``: the beacon pursued from then on, None: finished)."""

    goals: Goals
    visit: int = 0
    events: list = field(default_factory=list)

    def reset(self) -> None:
        self.visit = 0
        self.events = []

    @property
    def finished(self) -> bool:
        return self.visit >= len(self.goals.visits)

    @property
    def goal(self) -> int | None:
        """The current goal (an index into ``goals.beacons``), None when finished."""
        return None if self.finished else self.goals.visits[self.visit]

    @property
    def beacon(self) -> int | None:
        g = self.goal
        return None if g is None else self.goals.beacons[g]

    def advance(self, why: str, t: float | None = None) -> dict:
        """The current goal is done (``why``): on to the next; returns the event."""
        goal, beacon = self.goal, self.beacon
        self.visit += 1
        ev = {"t": None if t is None else round(float(t), 3), "visit": self.visit - 1,
              "goal": goal, "beacon": beacon, "next": self.beacon, "why": why}
        self.events.append(ev)
        return ev

    def describe(self) -> str:
        """``goal 2/4: beacon 7`` (or ``finished``), for a trace or a status line."""
        if self.finished:
            return f"finished ({len(self.goals.visits)} goals)"
        return f"goal {self.visit + 1}/{len(self.goals.visits)}: beacon {self.beacon}"


class Relocation:
    """Whether the robot was put elsewhere (the simulator's ``set_pose``: a new episode) since
    the last fiducial message seen: ``moved(msg)`` is True when it is farther than ``PUT`` m
    beyond what it can drive (``MAX_SPEED``) in the sim time between the two (its true pose
    when the message holds one, else odometry, which such a move resets): ten times a tick's
    drive for consecutive messages, and no false move after a gap (a paused teacher)."""

    def __init__(self) -> None:
        self.last: tuple | None = None  # (where, ts)

    def moved(self, msg) -> bool:
        where = msg.truth if msg.truth is not None else msg.pose
        last, self.last = self.last, (where, float(msg.ts))
        if last is None:
            return False
        reach = PUT + MAX_VX * max(0.0, float(msg.ts) - last[1])  # (the server's speed limit)
        return math.hypot(where[0] - last[0][0], where[1] - last[0][1]) > reach


class BeaconSeeker(Policy):
    """The goal behaviours' scripted expert: to the current goal's beacon, keeping off the
    walls, from the laser's nine sector minima (``around``: right ``s[0]`` .. ahead ``s[4]`` ..
    left ``s[8]``, 22.5 degrees each, metres) and what it sees of the beacon (``see``: a
    ``Sighting`` or None). Every label is a pure function of those two (so a tree with the
    same inputs can represent it). As the Bug algorithms do, it heads for the beacon where the
    way to it is open and follows a wall where it is not:

      the way to the beacon open (the sector of its bearing clear for ``clear`` m or up to it;
      behind the robot: only with nothing within ``clear`` m in front):
        a wall close beside (< near)    -> fwd-left / fwd-right, away from it (first: near a
                                           wall the label hangs on the laser alone)
        |bearing| > aim                 -> rotate towards it
        |bearing| > ahead               -> fwd-left / fwd-right, towards it
        otherwise                       -> fwd
      none in view, or the way to it not open:
        a wall close on the left        -> fwd-right
        nothing within ``lost`` m on the right and the way ahead clear -> fwd (past the end of
        a wall straight on, not round it; in open space straight on until a wall is near); with
        ``arc`` > 0 only when nothing is within ``arc`` m ahead or on the left either, else
        the follower arcs round the wall's end (into a doorway: a task that goes from room
        to room; a follower also circles a lone obstacle or the open floor for ever, so the
        rooms' worlds have neither where a beacon is out of sight)
        otherwise the reactive right-wall follower on s[0..4] (round the obstacle that hides
        the beacon, along the room's wall, until the way to it opens)
    """

    task = "red-green"
    acts_reactively = True

    def __init__(self, features=None, near: float = 0.45, aim: float = 0.7,
                 ahead: float = 0.2, clear: float = 1.0, lost: float = 1.2, arc: float = 0.0,
                 actions: ActionSet = DEFAULT_ACTIONS):
        super().__init__(actions)
        from .policies import ReactiveFollower

        self.features = features if features is not None else FEATURES["around"]
        if len(self.features.beams) != 9:
            raise ValueError(f"BeaconSeeker needs a feature spec of 9 sectors, got "
                             f"{len(self.features.beams)}")
        for name, v in (("near", near), ("aim", aim), ("ahead", ahead), ("clear", clear),
                        ("lost", lost)):
            if isinstance(v, bool) or not isinstance(v, int | float) or not 0 < v < math.inf:
                raise ValueError(f"{name} must be a number > 0, got {v!r}")
        if isinstance(arc, bool) or not isinstance(arc, int | float) or not 0 <= arc < math.inf:
            raise ValueError(f"arc must be a number >= 0, got {arc!r}")
        self.near, self.aim, self.ahead = float(near), float(aim), float(ahead)
        self.clear, self.lost, self.arc = float(clear), float(lost), float(arc)
        self._follow = ReactiveFollower(features=FeatureSpec(
            beams=self.features.beams[:5], window=self.features.window, fov=self.features.fov,
            clamp=self.features.clamp, scale=self.features.scale), actions=actions)
        self.sighting: Sighting | None = None

    def reset(self) -> None:
        self.sighting = None

    def see(self, sighting: Sighting | None) -> None:
        """What it sees of the current goal's beacon (None: none in view) until the next."""
        self.sighting = sighting

    def sectors(self, ranges) -> np.ndarray:
        f = self.features
        return f.extract(np.asarray(ranges), 0.0)[:9] * f.scale

    def open_towards(self, s, sighting: Sighting) -> bool:
        """Whether the way to the beacon is open: the sector of its bearing clear for
        ``clear`` metres (or up to the beacon); a beacon behind the robot: nothing within
        ``clear`` metres in front (room to turn towards it)."""
        k = round((sighting.bearing + math.pi / 2) / (math.pi / 8))
        if not 0 <= k <= 8:
            return min(s) > self.clear
        return s[k] > min(self.clear, sighting.range)

    def decide(self, s, sighting: Sighting | None) -> str:
        s = [float(v) for v in s[:9]]
        right, left = min(s[0], s[1], s[2]), min(s[6], s[7], s[8])
        if sighting is not None and self.open_towards(s, sighting):
            b = sighting.bearing
            if min(right, left) < self.near:
                return "fwd-left" if right <= left else "fwd-right"
            if abs(b) > self.aim:
                return "rot-left" if b > 0 else "rot-right"
            if abs(b) > self.ahead:
                return "fwd-left" if b > 0 else "fwd-right"
            return "fwd"
        f = self._follow
        if left < self.near and left < right and s[4] >= f.slow and s[3] >= f.slow_fr:
            return "fwd-right"
        if right > self.lost and (min(s[3:]) >= self.arc if self.arc > 0 else
                                  s[4] >= f.slow and min(s[3], s[5]) >= f.slow_fr):
            return "fwd"
        return f.decide(s[:5])

    def act(self, ranges, pose=None) -> str:
        return self.decide(self.sectors(ranges), self.sighting)

    reactive = act


class GoalExpert:
    """The scripted teacher of a goal behaviour: its ``BeaconSeeker`` and its own state. It
    says a goal is reached when it sees the goal's beacon within the goal's distance
    (``Goals.reached``), then pursues the next. ``see(sightings, t)`` returns that event (None:
    the goal stays), ``act(ranges, pose)`` the seeker's action for the current goal."""

    def __init__(self, goals: Goals, seeker: BeaconSeeker | None = None):
        self.goals = goals
        self.seeker = seeker if seeker is not None else BeaconSeeker()
        self.actions = self.seeker.actions
        self.tracker = GoalTracker(goals)
        self._sightings: Mapping[int, Sighting] = {}

    def reset(self, visit: int = 0) -> None:
        """Start over, pursuing the goal of ``visit`` (0: the first)."""
        self.seeker.reset()
        self.tracker.reset()
        self.tracker.visit = int(visit)
        self._sightings = {}

    def see(self, sightings: Mapping[int, Sighting], t: float | None = None) -> dict | None:
        self._sightings = sightings
        goal = self.tracker.goal
        ev = None
        if goal is not None:
            s = sightings.get(self.tracker.beacon)
            if self.goals.reached(s, goal):
                ev = self.tracker.advance(
                    f"teacher: reached beacon {self.tracker.beacon} (range {s.range:.2f} m "
                    f"<= {self.goals.within[goal]:g} m)", t)
        b = self.tracker.beacon
        self.seeker.see(None if b is None else sightings.get(b))
        return ev

    def label_state(self, sightings: Mapping[int, Sighting], t: float | None = None
                    ) -> tuple[int, int | None]:
        """For a teacher that demonstrates on and on (``rhbl teacher``): ``see`` this step's
        sightings; once every goal is reached, start over with the first. Returns the goal
        pursued (its beacon: what the next action is for) and the goal reached at this step
        (its beacon, None: none), a label's ``goal`` and ``reached``."""
        ev = self.see(sightings, t)
        if self.tracker.finished:  # (the step that finished it: ``ev`` says which)
            self.reset()
            self.see(sightings, t)  # (at a cycle's end the first goal is reached again)
            if self.tracker.finished:  # every goal reached at this one spot: the first again
                self.reset()
                self.seeker.see(sightings.get(self.tracker.beacon))
        return self.tracker.beacon, None if ev is None else ev["beacon"]

    def act(self, ranges, pose=None) -> str:
        return self.seeker.act(ranges, pose)

    reactive = act
    acts_reactively = True


# ------------------------------------------------------------------------------ the learner


def _check_goal_features(features: FeatureSpec) -> None:
    if features.beacon != BEACON_GOAL:
        raise ValueError(f"a goal behaviour's perception sees the current goal's beacon "
                         f"(beacon = {BEACON_GOAL!r}), got beacon = {features.beacon!r}")


def _tree(default_label: str, params: Mapping):
    from rhbl import HypersphereClassifier

    return HypersphereClassifier(default_label=default_label, **params)


def goals_metadata(goals: Goals, completion) -> dict:
    """A goal snapshot's ``metadata["goals"]``: the goals, the format, the completion tree's
    own snapshot (bytes) and its inputs."""
    from rhbl import NotFittedError

    meta = {"version": GOALS_FORMAT, **goals.to_dict(),
            "completion_inputs": ["goal-beacon-seen", "goal-beacon-range/near"], "near": NEAR}
    with contextlib.suppress(NotFittedError):  # (none yet: a new lineage's journal header)
        meta["completion"] = completion.to_bytes()
    return meta


@dataclass(frozen=True)
class GoalStep:
    """What a goal behaviour's label says beside its scan (``TeacherAction``'s ``goal``,
    ``reached`` and ``seen``): ``goal`` the beacon pursued (the one the action is for),
    ``reached`` the beacon the teacher marked reached at this scan (None: none), ``seen`` the
    beacons the fiducial finder saw then, by id."""

    goal: int
    reached: int | None
    seen: Mapping[int, Sighting]

    @classmethod
    def of(cls, goal: int, reached: int | None, items) -> GoalStep:
        """From a label's fields (``items``: ``FiducialItem``s or rows of id, range, bearing;
        a beacon seen but not identified, id 0, is left out as ``sightings`` leaves it)."""
        seen = {}
        for i, r, b in items if items is not None else ():
            if int(i):
                seen[int(i)] = Sighting(int(i), float(r), float(b))
        return cls(int(goal), None if reached is None else int(reached), seen)

    def rows(self) -> np.ndarray:
        """``seen`` as rows of id, range, bearing (what the journal keeps)."""
        return np.array([(s.id, s.range, s.bearing) for s in self.seen.values()],
                        dtype=np.float64).reshape(-1, 3)


class GoalLearner(DemonstrationLearner):
    """Learns a goal behaviour from demonstrations: the action tree (``classifier``, as every
    ``DemonstrationLearner``'s) from (laser, current goal's beacon) -> the teacher's action,
    the completion tree from the current goal's beacon -> ``done`` at the teacher's "reached"
    marks, ``not-done`` at every other step. ``observe(ranges, yaw, label, step)`` takes one
    labelled scan with its ``GoalStep``: the same code path in-process (``lab.goals``) and in
    the learner process (``client.lineage``). ``tree_params`` go to both trees."""

    def __init__(self, features: FeatureSpec, goals: Goals, actions: ActionSet = DEFAULT_ACTIONS,
                 *, completion=None, **kw):
        _check_goal_features(features)
        kw.setdefault("spawn", "winner")
        kw["rule"] = for_goals(kw.get("rule") or SCRIPT)  # the guard's path check, stored
        super().__init__(features, actions, **kw)
        self.goals = goals  # (the completion tree: marks as they come, the paper's radius)
        self.completion_tree = (completion if completion is not None
                                else _tree(NOT_DONE, {**self.tree_params, "radius": "parent"}))
        self._cx: list = []
        self._cy: list = []
        prov = kw.get("provenance") or {}
        self.marks = int(prov.get("marks", 0))  # "reached" marks learned

    def vector(self, ranges, yaw: float, step: GoalStep | None = None) -> np.ndarray:
        """The action tree's inputs: the perception's (``beacon = "goal"``: the laser's, then
        those of the goal pursued, ``step.goal``)."""
        if step is None:
            raise ValueError("a label of a behaviour with goals names the goal pursued and "
                             "what the fiducial finder saw (its goal and seen)")
        return self.features.extract(ranges, yaw, seen=list(step.seen.values()),
                                     target=step.goal)

    def observe(self, ranges, yaw: float, label: str, step: GoalStep | None = None) -> bool:
        """One labelled scan: the completion tree learns ``done`` for the goal reached at it
        (``step.reached``) or ``not-done`` for the goal pursued; the action tree the label for
        the goal pursued (the learner's sample selection, as ever). True when the action
        reached the tree."""
        return self._offer(self._marked(ranges, yaw, label, step), label)

    def _marked(self, ranges, yaw: float, label: str, step: GoalStep | None) -> np.ndarray:
        """The action tree's vector of a labelled scan, the label checked and the completion
        tree's mark (``done`` at the goal reached, ``not-done`` at the goal pursued) taken."""
        x = self.vector(ranges, yaw, step)  # (checks the step)
        self._check_label(label)
        g = step.goal if step.reached is None else step.reached
        self.observe_completion(self.goals.completion_inputs(step.seen, self.goals.index_of(g)),
                                step.reached is not None)
        return x

    def observe_completion(self, c: np.ndarray, done: bool) -> None:
        """The goal beacon's inputs ``c`` at a step the teacher marked reached (``done``) or
        not."""
        self._cx.append(np.asarray(c, dtype=np.float64))
        self._cy.append(DONE if done else NOT_DONE)
        self.marks += bool(done)

    def _flush(self) -> None:
        super()._flush()
        if self._cx:
            self.completion_tree.partial_fit(np.array(self._cx), self._cy)
            self._cx, self._cy = [], []

    def flush(self) -> None:
        """Learn every vector and mark queued."""
        self._flush()

    @property
    def action_tree(self):
        return self.classifier

    @property
    def completion(self):
        """The completion tree with every mark learned."""
        self._flush()
        return self.completion_tree

    def policy(self) -> GoalPolicy:
        """The trees as they are now, as a controller drives them."""
        return GoalPolicy(self.classifier, self.completion, self.features, self.goals,
                          self.actions, self.metadata())

    def metadata(self) -> dict:
        meta = super().metadata()
        meta["provenance"]["marks"] = self.marks
        meta["goals"] = goals_metadata(self.goals, self.completion)
        return meta

    def save(self, path: str | Path, extra: Mapping | None = None) -> Path:
        return self.policy().save(path, extra)

    @classmethod
    def _snapshot_parts(cls, clf, meta: Mapping, path) -> dict:
        """The goals and the completion tree of a goal snapshot being resumed."""
        policy = GoalPolicy.from_classifier(clf, str(path))
        return {"goals": policy.goals, "completion": policy.completion}


class PersonGoalLearner(GoalLearner, PersonLearner):
    """A ``GoalLearner`` for labels given by a person (a key on the console's page, G when a
    goal is reached): the action tree by the person rule (``PersonLearner``: the reaction lag,
    estimated or fixed, each label voted by its nearest labels, jittered copies, passes), the
    completion tree from the "reached" marks as every goal learner learns it. One rule for a
    person's labels whatever the behaviour (``client.behaviour.rule.PERSON``); a label's
    vector is the laser's and the pursued goal's beacon, and so are the scans shown before it
    (``earlier``: with the lag estimated, each of them with the beacon seen at the label's own
    scan, the goal and what the finder saw being the label's). ``rule`` (default ``PERSON``)
    gets the goal behaviours' guard (``for_goals``); ``lag``, ``background`` and the tree
    parameters as ``PersonLearner`` takes them. Sample selection (``stride``, ``min_delta``)
    does not apply: the vote needs every label."""

    def __init__(self, features: FeatureSpec, goals: Goals, actions: ActionSet = DEFAULT_ACTIONS,
                 *, completion=None, rule: LearningRule = PERSON, **kw):
        if not rule.person:
            raise ValueError(f"a PersonGoalLearner learns by a rule that edits its labels, not "
                             f"the {rule.name!r} rule")
        super().__init__(features, goals, actions, completion=completion, rule=rule, **kw)

    def earlier_vectors(self, earlier, step: GoalStep) -> np.ndarray:
        """The vectors of the scans shown before a label (``earlier``: ``(ranges, yaw)``,
        nearest first) with the label's goal and sighting (``step``): what the lag estimate
        compares."""
        out = np.zeros((len(earlier), self.features.dim), np.float32)
        for i, (r, a) in enumerate(earlier):
            out[i] = self.vector(r, a, step)
        return out

    def observe(self, ranges, yaw: float, label: str, step: GoalStep | None = None,
                earlier=None) -> bool:
        """One labelled scan with its ``GoalStep`` (the completion tree learns its mark) and,
        with the lag estimated, the vectors of the scans shown before it (``earlier_vectors``).
        Every label is kept: True."""
        x = self._marked(ranges, yaw, label, step)
        self.seen += 1
        self._learn(x, label, earlier)
        return True

    @classmethod
    def from_metadata(cls, meta: Mapping, features: FeatureSpec, actions: ActionSet,
                      parent: str | None = None, background: bool = False
                      ) -> PersonGoalLearner:
        """An empty learner by the rule and goals ``meta`` records (a journal header's): its
        labels are learned again from the journal."""
        rule = LearningRule.of(meta)
        if not rule.person:
            raise ValueError(f"not a person's tree: learning rule {rule.name!r}")
        return cls(features, Goals.from_dict(meta["goals"]), actions, rule=rule,
                   task=meta.get("task"), parent=parent, background=background)


def resume_learner(path: str | Path, features: FeatureSpec | None = None
                   ) -> DemonstrationLearner:
    """The learner that goes on from a snapshot: a ``GoalLearner`` for a goal snapshot, else a
    ``DemonstrationLearner`` (``DemonstrationLearner.resume``: errors name the file)."""
    from .learning import load_snapshot

    meta = load_snapshot(path)[3]
    cls = GoalLearner if isinstance(meta.get("goals"), dict) else DemonstrationLearner
    return cls.resume(path, features)


def learner_of(meta: Mapping) -> DemonstrationLearner:
    """A new learner (empty trees) as the one whose metadata this is (a lineage's journal
    header: perception, actions, task, rule, tree parameters), for the scripted rule: a
    ``GoalLearner`` when it holds goals."""
    goals = meta.get("goals")
    cls, kw = ((GoalLearner, {"goals": Goals.from_dict(goals)}) if isinstance(goals, dict)
               else (DemonstrationLearner, {}))
    rule = LearningRule.of(meta)
    return cls(FeatureSpec.from_dict(meta["features"]),
               actions=ActionSet.from_dict(meta["actions"]), task=meta.get("task"),
               stride=rule.stride, min_delta=rule.min_delta, rule=rule, **kw,
               **(meta.get("tree_params") or {}))


class GoalPolicy:
    """A learned goal behaviour: ``see(sightings, t)`` (every beacon seen now; the completion
    tree may finish the current goal), then ``act(ranges, pose)`` (the action tree on the
    laser and the current goal's beacon). ``tracker`` is the state; ``why`` says why the last
    goal changed; ``classifier`` is the action tree (what a report counts)."""

    def __init__(self, action_tree, completion_tree, features: FeatureSpec, goals: Goals,
                 actions: ActionSet = DEFAULT_ACTIONS, metadata: Mapping | None = None):
        self.classifier = action_tree
        self.completion = completion_tree
        self.features, self.goals, self.actions = features, goals, actions
        self.metadata = dict(metadata or {})
        self.tracker = GoalTracker(goals)
        self._sightings: Mapping[int, Sighting] = {}

    def reset(self) -> None:
        self.tracker.reset()
        self._sightings = {}

    def completion_inputs(self, sightings=None) -> np.ndarray | None:
        g = self.tracker.goal
        return None if g is None else self.goals.completion_inputs(
            self._sightings if sightings is None else sightings, g)

    def see(self, sightings: Mapping[int, Sighting], t: float | None = None) -> dict | None:
        """Take this step's sightings; when the completion tree says the current goal is done,
        move on (at most one goal a step) and return the event (None: the goal stays)."""
        self._sightings = sightings
        c = self.completion_inputs()
        if c is None or len(getattr(self.completion, "classes_", ())) < 2:
            return None
        path = self.completion.decision_path(c)
        if str(path[-1]["label"]) != DONE:
            return None
        s = sightings.get(self.tracker.beacon)
        seen = (f"range {s.range:.2f} m, bearing {math.degrees(s.bearing):.0f} deg"
                if s is not None else "none in view")
        return self.tracker.advance(
            f"completion tree: sphere {path[-1]['index']} (depth {path[-1]['depth']}) says "
            f"done at beacon {self.tracker.beacon} ({seen})", t)

    def vector(self, ranges, yaw: float) -> np.ndarray:
        return self.features.extract(ranges, yaw, seen=list(self._sightings.values()),
                                     target=self.tracker.beacon)

    def act(self, ranges, pose) -> str:
        yaw = float(pose[2]) if pose is not None else 0.0
        return str(self.classifier.predict_one(self.vector(ranges, yaw)))

    def save(self, path: str | Path, extra: Mapping | None = None) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        meta = {"features": self.features.to_dict(), "actions": self.actions.to_dict(),
                "task": self.metadata.get("task"),
                **{k: v for k, v in {**self.metadata, **dict(extra or {})}.items()
                   if k not in ("features", "actions", "task", "goals")},
                "goals": goals_metadata(self.goals, self.completion)}
        self.classifier.save(str(path), metadata=meta)
        return path

    @classmethod
    def from_classifier(cls, clf, source: str = "<snapshot>") -> GoalPolicy:
        """The goal policy of a loaded action tree whose metadata holds ``goals``."""
        from rhbl import SnapshotError, loads

        meta = dict(clf.metadata or {})
        g = meta.get("goals")
        if not isinstance(g, dict):
            raise SnapshotError(source, "its metadata holds no 'goals' (a single tree: "
                                        "client.behaviour.learning.TreePolicy loads it)")
        if int(g.get("version", 0)) > GOALS_FORMAT:
            raise SnapshotError(source, f"goals format {g.get('version')} is newer than this "
                                        f"reader's ({GOALS_FORMAT})")
        try:
            goals = Goals.from_dict(g)
            features = FeatureSpec.from_dict(meta["features"])
            actions = ActionSet.from_dict(meta["actions"])
            completion = (loads(bytes(g["completion"]), source=f"{source} (completion tree)")
                          if "completion" in g else _tree(NOT_DONE, {}))  # learned nothing yet
        except (ValueError, TypeError, KeyError) as exc:
            raise SnapshotError(source, f"invalid goals metadata: {exc}") from None
        return cls(clf, completion, features, goals, actions, meta)

    @classmethod
    def load(cls, path: str | Path) -> GoalPolicy:
        from rhbl import load

        return cls.from_classifier(load(path), str(path))


def load_policy(path: str | Path):
    """The policy of a snapshot: a ``GoalPolicy`` when its metadata holds goals, else the
    single tree's ``TreePolicy`` (today's snapshots load as before, their errors naming the
    file as ``TreePolicy.load``'s do)."""
    from .learning import TreePolicy, load_snapshot

    clf, features, actions, meta = load_snapshot(path)
    if isinstance(meta.get("goals"), dict):
        return GoalPolicy.from_classifier(clf, str(path))
    return TreePolicy(clf, features, actions, meta)


class ReactiveBeaconPolicy:
    """The purely reactive baseline: today's learner (one tree, no state) on the same
    demonstrations, seeing the laser and every beacon the goals name (``Goals.all_inputs``)
    but not which goal is current. ``see(sightings)``, ``act(ranges, pose)``. ``features`` is
    the goal behaviour's perception (``beacon = "goal"``), each beacon's values as its."""

    def __init__(self, features: FeatureSpec, goals: Goals, actions: ActionSet = DEFAULT_ACTIONS,
                 **tree_params):
        tree_params.setdefault("spawn", "winner")
        _check_goal_features(features)
        self.features, self.goals, self.actions = features, goals, actions
        self._laser = dataclasses.replace(features, beacon=None)
        self.classifier = _tree(actions.names[0], tree_params)
        self._sightings: Mapping[int, Sighting] = {}
        self._x: list = []
        self._y: list = []

    def reset(self) -> None:
        self._sightings = {}

    def see(self, sightings: Mapping[int, Sighting], t: float | None = None) -> None:
        self._sightings = sightings

    def vector(self, ranges, yaw: float, sightings=None) -> np.ndarray:
        """The laser's features, then the three beacon values of every beacon the goals
        name (``Goals.distinct`` order)."""
        seen = list((self._sightings if sightings is None else sightings).values())
        return np.concatenate([self._laser.extract(ranges, yaw), *[
            self.features.beacon_values(seen, b) for b in self.goals.distinct]])

    def observe(self, x: np.ndarray, label: str) -> None:
        self._x.append(x)
        self._y.append(label)

    def flush(self) -> None:
        """Learn the vectors observed since: the first flush fits them (a margin tree bounded
        by their margins), later ones extend the tree."""
        if self._x:
            fresh = getattr(self.classifier, "tree_", None) is None
            learn = self.classifier.fit if fresh else self.classifier.partial_fit
            learn(np.array(self._x), self._y)
            self._x, self._y = [], []

    def act(self, ranges, pose) -> str:
        self.flush()
        yaw = float(pose[2]) if pose is not None else 0.0
        return str(self.classifier.predict_one(self.vector(ranges, yaw)))
