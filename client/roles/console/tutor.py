"""The teaching session of ``rhbl console``: what a person does to a robot through a page, and
what the page is told about it (the transport, zenoh and the WebSocket, is
``client.roles.console.app``; the pure per-robot teaching, ``client.roles.console.lesson``).

- the person's commands: ``_drive`` (a key for the scan displayed: the teacher's command and one
  label per scan), ``_stop``/``_unhold`` (the robot never moves on a stale key: a last zero
  command, then the hold token is withdrawn), ``_may_act`` (one page at a time drives a robot);
- episodes, undo and placing the robot: ``_episode``, ``_undo``, ``_place_msg``, ``_reset``
  (labels withdrawn from the learner, the robot teleported with the simulator's ``set_pose``);
- prompts: the ``teach`` message (the learner, the labels, episodes, the tree's agreement,
  markers, stuck) at most every ``TEACH_EVERY`` s per robot, or at once after an event, and
  the learner's tree fetched for the agreement (``_fetch_tree``, at most every ``TREE_EVERY``
  s).

``Tutor`` is the console's base: the console (``client.roles.console.app.Console``) gives it
``session``, ``loop``, ``view_only``, ``robots`` (name -> ``Robot``), ``pages`` (id -> a
``Page``: ``id``, ``mode``, ``robot`` and ``push(kind, text)``), ``stats`` and ``_tasks`` (the
tasks ``_spawn`` keeps referenced until done).
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import os
import re
import time
from collections import OrderedDict, deque
from typing import Protocol

from client.behaviour.actions import DEFAULT_ACTIONS, ActionSet
from client.behaviour.features import FeatureSpec
from client.behaviour.goals import GoalTracker
from client.behaviour.learning import TreePolicy, check_compatible
from client.labels import Hold, LabelPublisher, Learners
from client.player import PlayerClient, RequestError
from client.roles.console.lesson import Asks, Teaching, Trouble
from client.roles.console.web import error_message
from protocol import keys
from protocol.messages import Fiducial, Scan, State

__all__ = ["SCAN_MEMORY", "TEACH_EVERY", "TREE_EVERY", "Page", "Robot", "Tutor"]

log = logging.getLogger("client.roles.console.app")

SCAN_MEMORY = 128  # scan ids remembered per robot (a page's label must name one of these)
TEACH_EVERY = 0.5  # s between two ``teach`` messages of a robot
TREE_EVERY = 2.0  # s at least between two fetches of the learner's tree (for the agreement)
FIRST = "first"  # the tree wanted when a page opens before any notice (the learner's latest)
_ROBOT_NUMBER = re.compile(r"^r(\d+)$")


class Page(Protocol):
    """What the teaching session needs of a page (``client.roles.console.app._Page``)."""

    id: int
    mode: str
    robot: str

    def push(self, kind: str, text: str) -> None: ...


class Robot:
    """What the console knows of one robot: its world, latest messages and scans, who holds
    it, the person's publishers, the teaching and the trouble."""

    def __init__(self, name: str):
        self.name = name
        self.world: str | None = None  # JSON of the WorldInfo
        self.world_name: str | None = None
        self.starts: tuple = ()  # the world's start poses
        self.world_asked = 0.0
        self.latest: dict[str, str] = {}  # kind -> JSON (for a page that starts watching)
        self.scans: OrderedDict[int, Scan] = OrderedDict()  # id -> the scan (labels carry it)
        # goals in order (docs/goals.md): the fiducial messages by the id of their tick's scan
        # (a label carries what was seen), the person's goal state (None: a behaviour without
        # goals) and the goals they marked reached, each carried by the next label in turn
        self.fiducials: OrderedDict[int, Fiducial] = OrderedDict()
        self.goals: GoalTracker | None = None
        self.reached: deque[int] = deque(maxlen=64)  # (a flood of G keeps the latest)
        self.last_scan: Scan | None = None
        self.state: State | None = None
        self.holder: Page | None = None
        self.action: str | None = None  # what the person commands now
        self.last_drive = 0.0
        self.labelled = -1  # the last scan id labelled
        self.client: PlayerClient | None = None  # the person's commands, as the teacher's
        self.pubs: LabelPublisher | None = None
        self.hold: Hold | None = None
        self.learners: Learners | None = None  # view-only: which learners are up
        self.teaching = Teaching()
        self.trouble = Trouble()
        self.asks = Asks()  # where the tree's refinement asks for the person's correction
        self.policy: TreePolicy | None = None  # the learner's tree, for the agreement
        self.policy_id = ""
        self.tree_wanted: str | None = None  # a notice's snapshot id not fetched yet
        self.tree_asked = 0.0
        self.tree_busy = False
        self.teach_said = 0.0
        self.teach_dirty = True
        self.teach_seq = 0  # teach messages composed (a page sees the one after an event)

    @property
    def start_index(self) -> int:
        """Robot ``r<i>`` starts at start pose ``i`` (cycling), as the server places it."""
        m = _ROBOT_NUMBER.match(self.name)
        return int(m.group(1)) % len(self.starts) if m and self.starts else 0


class Tutor:
    """The teaching session (see the module); the console's base class."""

    robots: dict[str, Robot]
    pages: dict

    def _spawn(self, coro) -> None:
        task = self.loop.create_task(coro)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    def _on_robot_state(self, r: Robot, st: State) -> None:
        r.state = st
        pose = st.truth if st.truth is not None else st.pos
        r.trouble.state(st.ts, pose, st.stall, st.driver.startswith("controller"))

    def _to_pages(self, r: Robot, kind: str, text: str) -> None:
        for p in self.pages.values():
            if p.robot == r.name:
                p.push(kind, text)

    def _control_text(self, r: Robot) -> str:
        h = r.holder
        return json.dumps({"t": "control", "robot": r.name, "holder": h.id if h else None,
                           "holder_mode": h.mode if h else None, "action": r.action})

    def _announce(self, r: Robot) -> None:
        self._to_pages(r, "control", self._control_text(r))

    # -- the learner's tree, for the agreement --
    def _fetch_tree(self, r: Robot, first: bool = False) -> None:
        """Fetch the learner's latest tree (at most every ``TREE_EVERY`` s, one at a time);
        ``first``: a page opens and no tree is held yet (one try: the learner's tree, its asks,
        before any notice)."""
        if first and r.policy is None and r.tree_wanted is None:
            r.tree_wanted = FIRST
        now = time.monotonic()
        if r.tree_busy or r.tree_wanted in (None, r.policy_id) or now - r.tree_asked < TREE_EVERY:
            return
        r.tree_busy, r.tree_asked, wanted = True, now, r.tree_wanted

        def fetch() -> TreePolicy | None:
            from rhbl import loads

            try:
                for reply in self.session.get(keys.learner_snapshot_key(r.name), timeout=5.0):
                    if reply.ok is None:
                        continue
                    clf = loads(reply.ok.payload.to_bytes(), source="learner snapshot")
                    meta = dict(clf.metadata or {})
                    check_compatible(meta)
                    policy = TreePolicy(clf, FeatureSpec.from_dict(meta["features"]),
                                        ActionSet.from_dict(meta["actions"]), meta)
                    if r.last_scan is not None:  # compiled here, not in the page's loop
                        policy.act(r.last_scan.ranges, r.last_scan.pose)
                    return policy
            except Exception as exc:  # noqa: BLE001 - no agreement until a tree loads
                log.info("the learner's tree of robot %s did not load: %s", r.name, exc)
            return None

        async def get() -> None:
            try:
                policy = await self.loop.run_in_executor(None, fetch)
            finally:
                r.tree_busy = False
            if policy is not None:
                r.policy, r.policy_id = policy, wanted
                r.asks.update(policy.metadata, r.world_name)
                r.teach_dirty = True
            elif wanted == FIRST and r.tree_wanted == FIRST:
                r.tree_wanted = None  # no learner, or no tree yet: its first notice says so
            if r.tree_wanted != r.policy_id and r.tree_wanted is not None:  # a newer notice
                self.loop.call_later(TREE_EVERY, self._fetch_tree, r)

        self._spawn(get())

    # -- what the page says about teaching --
    def _teach_text(self, r: Robot) -> str:
        box = r.pubs.outbox if r.pubs is not None else None
        learners = r.pubs.learners if r.pubs is not None else r.learners
        now = r.state.ts if r.state is not None else None
        labels = None if box is None else {
            "given": box.stats["published"],
            "held": box.stats["acked"] - box.stats["refused"], "refused": box.stats["refused"],
            "waiting": len(box), "cap": box.cap, "withdrawn": box.stats["withdrawn"],
            "withdrawals_waiting": box.unacknowledged_withdrawals}
        r.teach_seq += 1
        return json.dumps({
            "t": "teach", "robot": r.name, "seq": r.teach_seq,
            "learner": None if learners is None else {"up": bool(learners)},
            "labels": labels, "tree": r.policy_id or None,
            "goals": None if r.goals is None else {
                "visit": r.goals.visit, "of": len(r.goals.goals.visits),
                "beacon": r.goals.beacon, "text": r.goals.describe()},
            **r.teaching.summary(now), **r.trouble.summary(), **r.asks.summary()})

    def _say_teaching(self, force: bool = False) -> None:
        now = time.monotonic()
        for r in self.robots.values():
            if not any(p.robot == r.name for p in self.pages.values()):
                continue
            learners = r.pubs.learners if r.pubs is not None else r.learners
            if r.policy is None and learners:  # a learner came up after the page opened
                self._fetch_tree(r, first=True)  # (at most every TREE_EVERY s)
            if force or r.teach_dirty or now - r.teach_said >= TEACH_EVERY:
                r.teach_said, r.teach_dirty = now, False
                text = self._teach_text(r)
                r.latest["teach"] = text
                self._to_pages(r, "teach", text)

    # -- the person's commands --
    def _publishers(self, r: Robot) -> None:
        """The robot's teacher keys: commands, labels (kept until a learner acknowledges
        them, also before any learner is up), the hold token."""
        if r.pubs is None:
            r.client = PlayerClient(session=self.session, robot=r.name, source="teacher",
                                    express=True, block=True)
            # labels marked as a person's: a learner's --teacher auto takes the person rule
            r.pubs = LabelPublisher(self.session, r.name, source="console")
            # the teacher's hold token, one per robot driven (its ident names that robot)
            r.hold = Hold(self.session, f"{r.name}-{os.getpid()}")

    def _may_act(self, page: Page, r: Robot | None, what: str) -> str | None:
        """Why ``page`` may not ``what`` (drive, place, undo...) the robot now, or None."""
        if self.view_only:
            return "this console is view-only (--view-only): it publishes nothing"
        if page.mode == "watch":
            return f"watch mode: switch to demonstrate or correct to {what}"
        if r is None:
            return "no robot"
        if r.holder is not None and r.holder is not page:
            return (f"page #{r.holder.id} holds robot {r.name}: watch, or take over "
                    f"explicitly")
        return None

    def _drive(self, page: Page, action, scan_id) -> str | None:
        """Publish the page's command and label; an error text when refused."""
        r = self.robots.get(page.robot)
        why = self._may_act(page, r, "drive")
        if why:
            return why
        if action not in DEFAULT_ACTIONS.names:
            return f"unknown action {action!r}; one of {', '.join(DEFAULT_ACTIONS.names)}"
        if isinstance(scan_id, bool) or not isinstance(scan_id, int):
            return f"'scan_id' must be the integer id of the scan displayed, got {scan_id!r}"
        scan = r.scans.get(scan_id)
        if scan is None:
            return (f"scan {scan_id} is not among the last {SCAN_MEMORY} scans of robot "
                    f"{r.name}: the page is behind, not driving on a stale view")
        self._publishers(r)
        box = r.pubs.outbox
        if box.full:
            who = ("no learner is up" if not r.pubs.learners
                   else "the learner acknowledges nothing")
            return (f"{len(box)} labels wait for a learner's acknowledgement (at most "
                    f"{box.cap}; {who}): not driving until one acknowledges them (they are kept "
                    f"and sent once a learner is up)")
        changed = r.holder is not page or r.action != action
        r.holder = page
        vx, va = DEFAULT_ACTIONS[action]
        r.hold.acquire()  # before the command: the server may release the teacher at once
        r.client.answer(scan, vx, va)
        if scan_id > r.labelled:  # one label per scan (the learner learns it like any other)
            self._label(r, scan, action)
        r.action, r.last_drive = action, time.monotonic()
        if changed:
            log.info("page #%d drives robot %s: %s (%s)", page.id, r.name, action, page.mode)
            self._announce(r)
        return None

    def _label(self, r: Robot, scan: Scan, action: str) -> None:
        goal = {}
        if r.goals is not None:  # the goal the person pursues, the one marked, what was seen
            seen = r.fiducials.get(scan.id)
            if seen is None:  # (sent before its scan: lost, or far behind): not labelled
                self.stats["no_fiducial"] += 1
                log.debug("robot %s: no fiducial message of scan %d: not labelled", r.name,
                          scan.id)
                return
            goal = {"goal": r.goals.beacon, "seen": seen.items}
            if r.reached:
                goal["reached"] = r.reached.popleft()
        pose = scan.truth if scan.truth is not None else scan.pose
        if r.policy is not None:  # what the tree would have done on this very scan
            try:
                r.teaching.scored(scan.ts, r.policy.act(scan.ranges, scan.pose) == action)
            except Exception as exc:  # noqa: BLE001 - a tree of other features: no score
                log.debug("agreement not scored: %s", exc)
        seq = r.pubs.label(scan, action, action, **goal)
        r.asks.labelled()
        was = r.teaching.current
        r.teaching.labelled(seq, scan.ts, pose)
        r.labelled = scan.id
        if r.teaching.current is not was or r.asks.changed:
            r.asks.changed = False
            r.teach_dirty = True

    def _reached(self, page: Page) -> str | None:
        """The person says the goal they pursue is reached (the page's G): the next label
        carries the mark and is for the next goal (after the last, the first again)."""
        r = self.robots.get(page.robot)
        why = self._may_act(page, r, "mark a goal reached")
        if why:
            return why
        if r.goals is None:
            return "the behaviour taught has no goals in order: no goal to mark reached"
        ts = r.last_scan.ts if r.last_scan is not None else None
        ev = r.goals.advance("the person marked it reached at the page", ts)
        r.reached.append(ev["beacon"])
        if r.goals.finished:  # (never left finished: after the last, the first again)
            r.goals.reset()
        log.info("page #%d: robot %s reached goal %d (beacon %d); now %s", page.id, r.name,
                 ev["visit"] + 1, ev["beacon"], r.goals.describe())
        self._info(page, f"goal {ev['visit'] + 1} (beacon {ev['beacon']}) reached: now "
                         f"{r.goals.describe()}")
        r.teach_dirty = True
        return None

    def _restart_goals(self, r: Robot) -> None:
        """The robot is put somewhere (a start, an ask, a reset): from the first goal again."""
        if r.goals is not None:
            r.goals.reset()
            r.reached.clear()
            r.teach_dirty = True

    def _stop(self, r: Robot, why: str) -> None:
        """End the person's commands on ``r`` now: a zero command, then the hold is withdrawn."""
        if r.action is None:
            return
        r.action = None
        if r.client is not None and r.last_scan is not None:
            with contextlib.suppress(Exception):
                r.client.answer(r.last_scan, 0.0, 0.0)
        if r.hold is not None:
            r.hold.release()
        log.info("robot %s: the person's commands stopped (%s)", r.name, why)
        self._announce(r)

    def _unhold(self, r: Robot, why: str) -> None:
        self._stop(r, why)
        if r.holder is not None:
            r.holder = None
            self._announce(r)

    # -- episodes, undo, placing the robot --
    def _withdraw(self, r: Robot, first: int, upto: int, reason: str) -> int:
        """Withdraw the labels ``first <= seq < upto``; how many stood."""
        r.pubs.withdraw(first, upto, reason)
        n = r.teaching.withdrawn_range(first, upto)
        self.stats["withdrawals"] += 1
        self.stats["withdrawn"] += n
        r.teach_dirty = True
        return n

    def _episode(self, page: Page, do) -> str | None:
        r = self.robots.get(page.robot)
        why = self._may_act(page, r, "record episodes")
        if why:
            return why
        t = r.teaching
        ts = r.state.ts if r.state is not None else None
        pose = self._pose(r)
        if do == "start":
            self._stop(r, "a new episode")
            e = t.start(pose, ts)
            self._info(page, f"episode {e.n} records: drive to teach")
        elif do == "stop":
            self._stop(r, "the episode stopped")
            e = t.stop(ts)
            if e is None:
                return "no episode records now"
            self._info(page, f"episode {e.n} stopped: {e.labels} labels kept")
        elif do in ("discard", "rerecord"):
            self._stop(r, f"the episode is {'discarded' if do == 'discard' else 're-recorded'}")
            found = t.discard()
            if found is None:
                return "no episode with labels to discard"
            e, first, upto = found
            n = self._withdraw(r, first, upto, f"discard episode {e.n}") if r.pubs else 0
            t.discarded(e)
            if do == "rerecord":
                if e.start_pose is not None:
                    self._place(page, r, e.start_pose, f"the start of episode {e.n}")
                t.start(e.start_pose, ts)
            self._info(page, f"episode {e.n} discarded: {n} labels withdrawn"
                       + ("; recording it again" if do == "rerecord" else ""))
        else:
            return f"unknown episode action {do!r}; one of start, stop, discard, rerecord"
        r.teach_dirty = True
        return None

    def _undo(self, page: Page, seconds) -> str | None:
        r = self.robots.get(page.robot)
        why = self._may_act(page, r, "undo")
        if why:
            return why
        try:
            found = r.teaching.undo(seconds)
        except ValueError as exc:
            return str(exc)
        if found is None or r.pubs is None:
            return "nothing to undo: no label given yet (or all withdrawn)"
        self._stop(r, "undo")
        n = self._withdraw(r, *found, f"undo {seconds:g} s")
        self._info(page, f"undone: the last {seconds:g} s of teaching, {n} labels withdrawn")
        return None

    def _pose(self, r: Robot):
        st = r.state
        if st is None:
            return None
        return st.truth if st.truth is not None else st.pos

    def _place_msg(self, page: Page, msg: dict) -> str | None:
        r = self.robots.get(page.robot)
        why = self._may_act(page, r, "move the robot")
        if why:
            return why
        if "ask" in msg:  # "show me here": where refinement could not fix the tree
            try:
                a = r.asks.place(msg["ask"])
            except ValueError as exc:
                return str(exc)
            r.teach_dirty = True
            self._place(page, r, a.pose, f"ask {a.n}: show it the way from here")
            return None
        r.asks.moved()
        if "start" in msg:
            i = msg["start"]
            if isinstance(i, bool) or not isinstance(i, int) or not 0 <= i < len(r.starts):
                return (f"'start' must be the number of a start pose of the world, 0.."
                        f"{len(r.starts) - 1}, got {i!r}" if r.starts else _no_starts(r))
            self._place(page, r, r.starts[i], f"start pose {i + 1}")
            return None
        pose = msg.get("pose")
        if (not isinstance(pose, list) or len(pose) != 3
                or not all(isinstance(v, int | float) and not isinstance(v, bool)
                           and math.isfinite(v) for v in pose)):
            return f"'pose' must be [x, y, yaw], three finite numbers, got {pose!r:.80}"
        self._place(page, r, tuple(float(v) for v in pose), "where it was dropped")
        return None

    def _reset(self, page: Page) -> str | None:
        r = self.robots.get(page.robot)
        why = self._may_act(page, r, "reset the scene")
        if why:
            return why
        if not r.starts:
            return _no_starts(r)
        self._stop(r, "the scene is reset")
        r.teaching.stop()
        r.trouble.clear()
        r.asks.moved()
        r.teach_dirty = True
        self._place(page, r, r.starts[r.start_index], "its start pose (reset)", reset=True)
        return None

    def _place(self, page: Page, r: Robot, pose, where: str, reset: bool = False) -> None:
        """Teleport the robot (``set_pose``, in a thread); the result said to the page."""
        self._publishers(r)
        self._restart_goals(r)
        x, y, yaw = (float(v) for v in pose)

        async def go() -> None:
            try:
                ack = await self.loop.run_in_executor(
                    None, lambda: r.client.simulation.set_pose2d(x, y, yaw))
            except RequestError as exc:
                page.push("error", error_message(f"cannot put the robot {where}: {exc}"))
                return
            self.stats["placed"] += 1
            got = ack.extra.get("pose", [x, y, yaw])
            log.info("page #%d put robot %s at (%.2f, %.2f, %.2f): %s", page.id, r.name,
                     *got, where)
            self._to_pages(r, "placed", json.dumps({"t": "placed", "robot": r.name,
                                                     "pose": got, "reset": reset,
                                                     "where": where}))

        self._spawn(go())

    def _info(self, page: Page, text: str) -> None:
        page.push("info", json.dumps({"t": "info", "info": text}))


def _no_starts(r: Robot) -> str:
    """Why robot ``r`` cannot be put at a start pose: its world not known yet, or none given."""
    if r.world is None:
        return (f"robot {r.name}'s world is not known yet (its simulator has not answered; it "
                f"is asked every few seconds): try again when the map is drawn")
    return "the world gives no start poses"
