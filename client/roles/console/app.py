"""The server side of ``rhbl console``: zenoh subscriptions -> JSON over a WebSocket, and the
person's commands -> the teacher's keys.

Threads: zenoh delivers samples in its own threads; each callback decodes and validates the
message (``protocol.messages``), turns it into one JSON text and hands it to the asyncio loop
(``call_soon_threadsafe``), which keeps only the latest text of each kind per robot and page:
a slow page skips frames, it never builds a backlog and never slows the bus down. A page that
does not read at all (a send waits ``SEND_TIMEOUT`` s) is closed; at most ``MAX_ERRORS`` of its
error replies wait to be sent, the rest are counted in one.

The robots are those a live server serves: the servers' liveliness tokens
(``rhbl/alive/server/<ident>/<robot>``, at most ``MAX_ROBOTS``) say which; a sample for any other
name is dropped in zenoh's thread before it is decoded (counted: ``unserved``), and the robot
list goes to the pages at most every ``ROBOTS_EVERY`` s. At most ``--max-pages`` pages are
served at once (one more is told why and closed, code ``PAGES_FULL``); with a token, an
address that gave too many wrong ones waits (``client.access.Throttle``: 429).

The page's messages (JSON objects, at most 4 KiB, nested at most a few levels; anything else
is answered with an ``error`` and the connection stays up):

    {"t": "view", "robot": "r1"}                 watch another robot of the server
    {"t": "mode", "mode": "demonstrate"|"watch"|"correct"}
    {"t": "drive", "action": "fwd", "scan_id": 812}   the key held now, for the scan displayed
    {"t": "release"}                              keys up / page hidden: stop commanding now
    {"t": "take"}                                 take the robot over from another page
    {"t": "episode", "do": "start"|"stop"|"discard"|"rerecord"}
    {"t": "undo", "seconds": 5}                   withdraw the labels of the last 5 s of teaching
    {"t": "place", "pose": [x, y, yaw]}           put the robot there (the simulator's set_pose)
    {"t": "place", "start": 2}                    ... at the world's start pose 2 (0 = the first)
    {"t": "place", "ask": 1}                      ... where the tree's refinement asks (from 1)
    {"t": "reset"}                                the robot back at its start pose, markers gone

One page at a time drives a robot: the first page that drives holds it until it leaves, switches
to watch or another page takes over explicitly. The robot never moves on a stale key: a release,
the page's WebSocket closing or no ``drive`` for ``STALE`` seconds end the person's commands at
once (a last zero command, then the teacher's hold token is withdrawn, so the server hands the
robot to the controller, or stops it, on the next tick). Episodes, undo and placing the robot
are refused while another page holds it.

Messages to the page: ``hello``, ``world`` (with the beacons), ``state``, ``scan``,
``fiducial`` (the beacons the robot sees, in a world with beacons), ``cmd`` (the action being
executed), ``notice``, ``decision``, ``control`` (who holds each robot), ``robots``, ``teach``
(the learner, the labels, episodes, agreement, markers, stuck: ``client.roles.console.lesson``),
``placed``, ``info``, ``error``.

Here: the transport (the zenoh side, the pages' HTTP and WebSocket, each page's queue); what a
page's teaching messages do (drive, episodes, undo, placing, the ``teach`` prompts) is the
teaching session, ``client.roles.console.tutor.Tutor``, this console's base; who may open a
page, ``client.access``.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import signal
import socket
import ssl
import threading
import time
from pathlib import Path

import zenoh
from aiohttp import WSMsgType, web

from client.access import (
    Throttle,
    access_token,
    check_host,
    check_origin,
    check_token,
    is_loopback,
)
from client.behaviour.actions import DEFAULT_ACTIONS
from client.behaviour.given import behaviour_of_world, to_page
from client.behaviour.goals import GoalTracker
from client.behaviour.spec import Behaviour, behaviour
from client.labels import DRAIN, Learners
from client.roles.console.tutor import SCAN_MEMORY, Robot, Tutor
from client.roles.console.web import (
    HEADER_TIMEOUT,
    Assets,
    Refusals,
    ServerLog,
    error_message,
    guard,
    read_message,
)
from process.runtime import EXIT_USAGE, Context, ProcessError
from protocol import keys
from protocol.decoding import Decoder
from protocol.messages import Decision, Fiducial, Scan, State, TreeNotice, VelCmd, WorldInfo

__all__ = ["SEND_TIMEOUT", "STALE", "Console", "body", "parse_http"]

log = logging.getLogger(__name__)

STATIC = Path(__file__).with_name("static")
STALE = 0.5  # s of wall time without a ``drive`` from the page: its key is stale, stop
MAX_MESSAGE = 4096  # bytes of a page's message
MODES = ("demonstrate", "watch", "correct")
SEND_TIMEOUT = 5.0  # s a send to a page may wait: a page that does not read is closed
HEARTBEAT = 5.0  # s between pings to a quiet page; one unanswered within half of it: closed
MAX_ERRORS = 8  # error replies waiting for a page at most (the rest counted in one)
# bytes the kernel may hold for a page's connection (its send buffer): on loopback it grows to
# megabytes by itself, so a page that reads nothing would be found out only after minutes, and
# every page could hold that much of the machine's memory; 128 KiB is a second of scans at 10 Hz
PAGE_SEND_BUFFER = 128 * 1024
MAX_KINDS = 64  # kinds of message waiting for a page at most
MAX_ROBOTS = 256  # robots served at once the console lists at most (the rest are refused)
ROBOTS_EVERY = 0.5  # s at least between two ``robots`` lists sent to the pages
MAX_PAGES = 32  # pages served at once (--max-pages); one more is refused with the reason
PAGES_FULL = 1013  # the WebSocket close code of a refused page: try again later
_REFUSALS = {400: web.HTTPBadRequest, 401: web.HTTPUnauthorized, 403: web.HTTPForbidden}


def parse_http(value: str) -> tuple[str, int]:
    """``HOST:PORT`` (``[v6]:PORT`` too) -> (host, port); ValueError with a clear message."""
    host, sep, port = value.rpartition(":")
    host = host.strip("[]")
    if not sep or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise ValueError(f"--http must be HOST:PORT (e.g. 127.0.0.1:8080), got {value!r}")
    return host, int(port)


def _action_of(vx: float, va: float) -> str:
    for name, (ax, aa) in DEFAULT_ACTIONS.items():
        if math.isclose(vx, ax, abs_tol=1e-6) and math.isclose(va, aa, abs_tol=1e-6):
            return name
    return "stop" if vx == 0 and va == 0 else f"vx {vx:.2f} va {va:.2f}"


class _Page:
    def __init__(self, ident: int, ws: web.WebSocketResponse, robot: str,
                 request: web.Request | None = None):
        self.id, self.ws, self.robot, self.request = ident, ws, robot, request
        self.mode = "demonstrate"
        self.pending: dict[str, str] = {}  # kind -> latest JSON text
        self.errors = 0  # error replies waiting
        self.errors_dropped = 0  # beyond MAX_ERRORS, counted
        self.unread = False  # closed because it read nothing
        self.wake = asyncio.Event()

    def push(self, kind: str, text: str) -> None:
        """Queue ``text``: the latest of each kind; every error is said, at most
        ``MAX_ERRORS`` of them waiting (then they are counted and said as one)."""
        if kind == "error":
            if self.errors >= MAX_ERRORS:
                self.errors_dropped += 1
                self.pending["error-more"] = error_message(
                    f"{self.errors_dropped} more errors (messages refused; not each said)")
                self.wake.set()
                return
            self.errors += 1
            kind = f"error-{self.errors}"
        elif kind not in self.pending and len(self.pending) >= MAX_KINDS:
            return  # a flood of kinds (sources on the bus): the known ones still come
        self.pending[kind] = text
        self.wake.set()

    def take(self) -> list[str]:
        batch, self.pending = self.pending, {}
        self.errors = self.errors_dropped = 0
        return list(batch.values())


class Console(Tutor):
    """The console: the zenoh side (subscriptions, handed to the loop) and the pages' side
    (HTTP, WebSocket, each page's queue); the teaching session is ``Tutor``'s."""

    def __init__(self, ctx: Context, loop: asyncio.AbstractEventLoop, token: str | None):
        self.ctx, self.session, self.loop = ctx, ctx.session, loop
        self.view_only = bool(ctx.args.view_only)
        # the behaviour taught (--behaviour), shown on the page; None: each world's, if any
        given = getattr(ctx.args, "behaviour", None)
        self.behaviour = None if given is None else behaviour(given)
        self.token = token
        self.throttle = Throttle()
        self.robots: dict[str, Robot] = {}
        self.pages: dict[int, _Page] = {}
        self._next_page = 1
        self._tasks: set[asyncio.Task] = set()  # kept referenced until done
        self.refusals = Refusals(log)
        self.assets = Assets(STATIC)
        self.stats = {"withdrawals": 0, "withdrawn": 0, "placed": 0, "closed_unread": 0,
                      "unserved": 0, "robots_refused": 0, "pages_refused": 0,
                      "no_fiducial": 0}  # goals in order: keys on a scan not labelled
        self.max_pages = int(getattr(ctx.args, "max_pages", MAX_PAGES))
        self.default_robot = ctx.robot
        # robot -> the liveliness tokens of the servers serving it (rhbl/alive/server/<id>/<robot>),
        # written by zenoh's liveliness thread under the lock, read anywhere: only these robots'
        # messages are taken (a name on the bus no server serves costs a counter, nothing more)
        self.served: dict[str, set[str]] = {}
        self._served_lock = threading.Lock()
        self._robots_dirty = False  # the robot list changed: said to the pages, coalesced
        self._robots_said = 0.0
        self._robot(self.default_robot)
        self.subs = []
        # a malformed message never stops the console: dropped, counted
        self.decoder = Decoder(log, level=logging.DEBUG)
        s = self.session
        self.subs.append(s.liveliness().declare_subscriber(
            keys.alive_key("server", "**"), self._on_server, history=True))
        for key_of, fn in ((keys.state_key, self._on_state), (keys.scan_key, self._on_scan),
                           (keys.fiducial_key, self._on_fiducial),
                           (keys.learner_notice_key, self._on_notice),
                           (keys.controller_decision_key, self._on_decision),
                           (keys.cmd_vel_subscription, self._on_cmd)):
            self.subs.append(s.declare_subscriber(key_of(keys.EVERY), fn))

    def _decode(self, cls, sample):
        """(the message, its robot) of a sample, or (None, robot): dropped, counted (a robot
        no live server serves: ``unserved``; a malformed message: the decoder's counts)."""
        robot = keys.parse(sample.key_expr).robot
        if robot not in self.served:
            self.stats["unserved"] += 1
            return None, robot
        return self.decoder.decode(cls, sample.payload.to_bytes()), robot

    def _on_server(self, sample) -> None:
        """A server's liveliness token of a robot it serves came or went."""
        k = keys.parse(sample.key_expr)
        if k.role != "server" or not k.name:
            return
        key, gone = str(sample.key_expr), sample.kind == zenoh.SampleKind.DELETE
        with self._served_lock:
            tokens = self.served.get(k.name)
            if gone:
                if tokens is None:
                    return
                tokens.discard(key)
                if not tokens:
                    del self.served[k.name]
            elif tokens is not None:
                tokens.add(key)
                return
            elif len(self.served) >= MAX_ROBOTS:
                self.stats["robots_refused"] += 1
                if self.stats["robots_refused"] == 1:
                    log.warning("more than %d robots served at once: robot %s (and any more) "
                                "not listed", MAX_ROBOTS, k.name)
                return
            else:
                self.served[k.name] = {key}
        with contextlib.suppress(RuntimeError):  # the loop is closing
            self.loop.call_soon_threadsafe(self._served_changed, k.name, gone)

    # ---- zenoh side (zenoh threads): decode, make JSON, hand over to the loop ----------------
    def _hand(self, robot: str, kind: str, text: str, msg=None) -> None:
        with contextlib.suppress(RuntimeError):  # the loop is closing
            self.loop.call_soon_threadsafe(self._deliver, robot, kind, text, msg)

    def _on_state(self, sample) -> None:
        st, robot = self._decode(State, sample)
        if st is None:
            return
        pose = st.truth if st.truth is not None else st.pos
        self._hand(robot, "state", json.dumps({
            "t": "state", "robot": robot, "ts": st.ts, "seq": st.seq,
            "pose": [round(x, 4) for x in pose], "vel": [round(x, 4) for x in st.vel],
            "stall": st.stall, "driver": st.driver}), st)

    def _on_scan(self, sample) -> None:
        sc, robot = self._decode(Scan, sample)
        if sc is None:
            return
        pose = sc.truth if sc.truth is not None else sc.pose
        text = json.dumps({
            "t": "scan", "robot": robot, "id": sc.id, "ts": sc.ts, "min_angle": sc.min_angle,
            "resolution": sc.resolution, "max_range": sc.max_range,
            "pose": [round(x, 4) for x in pose],
            "ranges": [round(x, 3) for x in sc.ranges.tolist()]})
        self._hand(robot, "scan", text, sc)

    def _on_fiducial(self, sample) -> None:
        f, robot = self._decode(Fiducial, sample)
        if f is None:
            return
        self._hand(robot, "fiducial", json.dumps({
            "t": "fiducial", "robot": robot, "seq": f.seq, "ts": f.ts,
            "items": [{"id": i.id, "range": round(i.range, 4), "bearing": round(i.bearing, 4)}
                      for i in f.items]}), f)

    def _on_notice(self, sample) -> None:
        n, robot = self._decode(TreeNotice, sample)
        if n is None:
            return
        self._hand(robot, "notice", json.dumps({
            "t": "notice", "robot": robot, "seq": n.seq, "nodes": n.nodes, "height": n.height,
            "vectors": n.vectors, "snapshot_id": n.snapshot_id, "ts": n.ts}), n)

    def _on_decision(self, sample) -> None:
        d, robot = self._decode(Decision, sample)
        if d is None:
            return
        path = [{"index": i, "depth": dp, "label": lab,
                 "radius": round(r, 4) if math.isfinite(r) else None}
                for i, dp, r, lab in d.path]
        self._hand(robot, "decision", json.dumps({
            "t": "decision", "robot": robot, "scan_id": d.scan_id, "ts": d.ts,
            "action": d.action, "snapshot_id": d.snapshot_id, "nodes": d.nodes, "path": path,
            "executed": d.executed, "looping": d.looping,
            "goal": None if d.goal is None else d.goal._asdict(), "goal_why": d.goal_why}), d)

    def _on_cmd(self, sample) -> None:
        c, robot = self._decode(VelCmd, sample)
        if c is None:
            return
        source = keys.source_of_cmd_key(str(sample.key_expr)) or c.source
        action = _action_of(c.vx, c.va) if c.state else "motors off"
        self._hand(robot, f"cmd-{source}", json.dumps({
            "t": "cmd", "robot": robot, "source": source, "action": action,
            "scan_id": c.scan_id}), (source, action, c))

    # ---- loop side ------------------------------------------------------------------------
    def _robot(self, name: str) -> Robot:
        r = self.robots.get(name)
        if r is None:
            r = self.robots[name] = Robot(name)
            self._ask_world(r)
            self._robots_dirty = True
        return r

    def robot_names(self) -> list[str]:
        """The robots a page may watch: those a live server serves, and the console's own."""
        return sorted(n for n in self.robots if n in self.served or n == self.default_robot)

    def _served_changed(self, name: str, gone: bool) -> None:
        """A robot's server came (its Robot made) or went (forgotten unless a page watches it,
        or labels of it wait for a learner)."""
        r = self.robots.get(name)
        if not gone:
            self._robot(name)
        elif (r is not None and name not in self.served and name != self.default_robot
              and r.pubs is None and not any(p.robot == name for p in self.pages.values())):
            del self.robots[name]
        self._robots_dirty = True

    def _say_robots(self, now: float) -> None:
        """The robot list to every page, at most every ``ROBOTS_EVERY`` s (changes coalesced)."""
        if self._robots_dirty and now - self._robots_said >= ROBOTS_EVERY:
            self._robots_dirty, self._robots_said = False, now
            self._broadcast(json.dumps({"t": "robots", "robots": self.robot_names()}))

    def _broadcast(self, text: str, kind: str = "robots") -> None:
        for p in self.pages.values():
            p.push(kind, text)

    def _ask_world(self, r: Robot) -> None:
        now = time.monotonic()
        if r.world is not None or now - r.world_asked < 5.0:
            return
        r.world_asked = now

        def fetch() -> WorldInfo | None:
            try:
                for reply in self.session.get(keys.sim_request_key(r.name, "get_world"),
                                              timeout=2.0):
                    if reply.ok is not None:
                        return WorldInfo.decode(reply.ok.payload.to_bytes())
            except Exception as exc:  # noqa: BLE001 - a real robot has no world to give
                log.info("no world for robot %s: %s", r.name, exc)
            return None

        async def get() -> None:
            w = await self.loop.run_in_executor(None, fetch)
            if w is not None:
                r.world_name = w.name
                if r.policy is not None:  # the tree came first: its asks in this world
                    r.asks.update(r.policy.metadata, w.name)
                b = self._behaviour_of(w)
                if b is not None and b.goals is not None and r.goals is None:
                    r.goals = GoalTracker(b.goals)  # the person's: G marks one reached
                # the behaviour's own start poses of the world, when it gives some (Home and
                # the keys 1-9 put the robot there), else the world's
                own = () if b is None else b.starts.get(w.name, ())
                r.starts = tuple(tuple(p) for p in own) or w.starts
                r.world = json.dumps({
                    "t": "world", "robot": r.name, "name": w.name,
                    "task": w.task if b is None else b.name,  # the behaviour's, not the world's
                    "walls": w.walls, "goal": w.goal, "starts": r.starts,
                    "beacons": [{"id": b.id, "pos": b.pos, "colour": b.colour, "size": b.size}
                                for b in w.beacons],
                    "start": r.start_index, "behaviour": None if b is None else to_page(b)})
                self._to_pages(r, "world", r.world)

        self._spawn(get())

    def _behaviour_of(self, w: WorldInfo) -> Behaviour | None:
        """The behaviour taught in world ``w``: --behaviour's, else the world's shipped behaviour
        (``client.behaviour.given.behaviour_of_world``), else None."""
        if self.behaviour is not None:
            return self.behaviour
        return behaviour_of_world(w.name, w.task or None)

    def _deliver(self, robot: str, kind: str, text: str, msg) -> None:
        if robot not in self.served:  # its server went meanwhile
            return
        r = self._robot(robot)
        if r.world is None:  # the server came up after the console (asked at most every 5 s)
            self._ask_world(r)
        if kind == "scan":
            r.scans[msg.id] = msg
            r.last_scan = msg
            while len(r.scans) > SCAN_MEMORY:
                r.scans.popitem(last=False)
        elif kind == "fiducial":
            r.fiducials[msg.seq] = msg
            while len(r.fiducials) > SCAN_MEMORY:
                r.fiducials.popitem(last=False)
        elif kind == "state":
            self._on_robot_state(r, msg)
        elif kind == "notice":
            r.tree_wanted = msg.snapshot_id or f"notice-{msg.seq}"
            self._fetch_tree(r)
        elif kind == "decision" and msg is not None:
            # the controller's loop guard: where it holds the robot from a loop, a person
            # should show the way out (the decisions come while the controller drives)
            r.trouble.guarded(msg.ts, msg.looping)
        elif kind.startswith("cmd-") and msg[0].split("-", 1)[0] == "controller":
            st = r.state
            if st is not None and st.driver.startswith("controller"):
                scan = r.scans.get(msg[2].scan_id) if msg[2].scan_id is not None else None
                r.trouble.command(scan.ts if scan is not None else st.ts, msg[1])
        r.latest[kind] = text
        self._to_pages(r, kind, text)
        if r.trouble.changed:
            r.trouble.changed = False
            r.teach_dirty = True

    async def watchdog(self) -> None:
        while True:
            await asyncio.sleep(0.05)
            now = time.monotonic()
            for r in self.robots.values():
                if r.action is not None and now - r.last_drive > STALE:
                    self._stop(r, f"no key from the page for {STALE:g} s")
            self._say_robots(now)
            self._say_teaching()

    def handle(self, page: _Page, raw) -> None:
        """One message of a page (a bad one is answered with an error, never raised)."""
        err = None
        try:
            msg = read_message(raw)
        except (ValueError, RecursionError) as exc:
            page.push("error", error_message(f"bad message: {exc}"))
            return
        t = msg.get("t")
        r = self.robots.get(page.robot)
        if t == "drive":
            err = self._drive(page, msg.get("action"), msg.get("scan_id"))
        elif t == "release":
            if r is not None and r.holder is page:
                self._stop(r, "released by the page")
        elif t == "take":
            if self.view_only:
                err = "this console is view-only (--view-only): it publishes nothing"
            elif page.mode == "watch":
                err = "watch mode: switch to demonstrate or correct to take over"
            elif r is not None and r.holder is not page:
                if r.holder is not None:
                    self._unhold(r, f"page #{page.id} took over")
                r.holder = page
                log.info("page #%d takes robot %s over", page.id, r.name)
                self._announce(r)
        elif t == "mode":
            mode = msg.get("mode")
            if mode not in MODES:
                err = f"unknown mode {mode!r}; one of {', '.join(MODES)}"
            else:
                page.mode = mode
                if r is not None and r.holder is page:
                    if mode == "watch":
                        self._unhold(r, "the page switched to watch")
                    else:
                        self._announce(r)
        elif t == "view":
            name = msg.get("robot")
            if not isinstance(name, str) or name not in self.robot_names():
                err = f"unknown robot {name!r:.80}; known: {', '.join(self.robot_names())}"
            else:
                if r is not None and r.holder is page:
                    self._unhold(r, "the page watches another robot")
                page.robot = name
                self._send_robot(page)
        elif t == "episode":
            err = self._episode(page, msg.get("do"))
        elif t == "undo":
            err = self._undo(page, msg.get("seconds"))
        elif t == "place":
            err = self._place_msg(page, msg)
        elif t == "reset":
            err = self._reset(page)
        elif t == "reached":
            err = self._reached(page)
        else:
            err = f"unknown message type {t!r}"
        if err:
            page.push("error", error_message(err))

    def _send_robot(self, page: _Page) -> None:
        r = self._robot(page.robot)
        self._ask_world(r)
        self._fetch_tree(r, first=True)
        if not self.view_only:
            self._publishers(r)  # the learner's status and the labels, before the first key
        elif r.learners is None:
            r.learners = Learners(self.session, r.name)  # only watches: publishes nothing
        if r.world is not None:
            page.push("world", r.world)
        for kind, text in r.latest.items():
            page.push(kind, text)
        page.push("control", self._control_text(r))
        r.teach_dirty = True

    # ---- HTTP ------------------------------------------------------------------------------
    def _authorised(self, request: web.Request) -> None:
        """Raise the refusal when ``request`` may not have the page, its files or its
        WebSocket (``client.access``): a request without a Host header (400), without a token
        a Host that is no loopback name (403: DNS rebinding), with a token a missing or wrong
        one (401), or any from an address that gave too many wrong ones lately (429)."""
        if self.token is None:
            # no token (loopback only): the page must be asked for by a loopback name, so a
            # site whose name an attacker points at 127.0.0.1 (DNS rebinding) gets nothing
            said = check_host(request.headers.get("Host"))
        elif not request.headers.get("Host"):
            said = check_host(None)
        else:
            # a wrong token costs its address a try: BURST at once, then one a second
            address = request.remote or "?"
            wait = self.throttle.wait(address)
            if wait > 0:
                raise web.HTTPTooManyRequests(
                    text=f"rhbl console: too many wrong tokens from {address}: try again in "
                         f"{math.ceil(wait)} s\n", headers={"Retry-After": str(math.ceil(wait))})
            said = check_token(request.query.get("token", ""), self.token)
            if said is not None:
                self.throttle.failed(address)
        if said is not None:
            raise _REFUSALS[said[0]](text=f"rhbl console: {said[1]}\n")

    async def index(self, request: web.Request) -> web.StreamResponse:
        self._authorised(request)
        return web.Response(text=self.assets.page(self.token), content_type="text/html",
                            headers={"Cache-Control": "no-store"})

    async def static(self, request: web.Request) -> web.StreamResponse:
        self._authorised(request)
        found = self.assets.get(request.match_info["name"])
        if found is None:
            raise web.HTTPNotFound(text="rhbl console: no such file\n")
        data, kind = found
        return web.Response(body=data, content_type=kind, headers={"Cache-Control": "no-store"})

    async def websocket(self, request: web.Request) -> web.StreamResponse:
        self._authorised(request)
        said = check_origin(request.headers.get("Origin"),
                            f"{request.scheme}://{request.headers['Host']}")
        if said is not None:
            raise web.HTTPForbidden(text=f"rhbl console: {said[1]}\n")
        ws = web.WebSocketResponse(heartbeat=HEARTBEAT, max_msg_size=MAX_MESSAGE)
        await ws.prepare(request)
        sock = request.transport.get_extra_info("socket") if request.transport else None
        if sock is not None:  # what waits in the kernel for a page, bounded: a page that reads
            with contextlib.suppress(OSError):  # nothing is found out within SEND_TIMEOUT s
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, PAGE_SEND_BUFFER)
        if len(self.pages) >= self.max_pages:
            return await self._refuse_page(ws, request)
        page = _Page(self._next_page, ws, self.default_robot, request)
        self._next_page += 1
        self.pages[page.id] = page
        log.info("page #%d connected from %s", page.id, request.remote)
        page.push("hello", json.dumps({
            "t": "hello", "page": page.id, "robot": page.robot, "view_only": self.view_only,
            "modes": list(MODES), "actions": list(DEFAULT_ACTIONS.names), "stale": STALE,
            "robots": self.robot_names(),
            "behaviour": None if self.behaviour is None else to_page(self.behaviour)}))
        self._send_robot(page)
        sender = asyncio.create_task(self._sender(page))
        try:
            async for msg in ws:
                if msg.type == WSMsgType.TEXT:
                    try:
                        self.handle(page, msg.data)
                    except Exception as exc:  # noqa: BLE001 - a page never kills the console
                        log.warning("page #%d: message not handled: %s: %s", page.id,
                                    type(exc).__name__, exc)
                        page.push("error", error_message(f"message not handled: {exc}"))
                elif msg.type == WSMsgType.BINARY:
                    page.push("error", error_message("binary messages are not understood"))
                else:
                    break
                # messages already read return without a pause: yield, so that a page that
                # floods messages cannot starve the senders, the watchdog and the other pages
                await asyncio.sleep(0)
        finally:
            # the page closed, reloaded or lost its connection: its commands end now
            if isinstance(ws.exception(), TimeoutError):  # no answer to the heartbeat's ping
                self._close_unread(page, f"no answer to a ping within {HEARTBEAT / 2:g} s")
            self.pages.pop(page.id, None)
            for r in self.robots.values():
                if r.holder is page:
                    self._unhold(r, f"page #{page.id} disconnected")
            sender.cancel()
            log.info("page #%d disconnected", page.id)
        return ws

    async def _refuse_page(self, ws: web.WebSocketResponse,
                           request: web.Request) -> web.WebSocketResponse:
        """A page over ``--max-pages``: told why (an ``error``, then the close code 1013, try
        again later, with the reason), counted, closed."""
        self.stats["pages_refused"] += 1
        why = (f"this console serves at most {self.max_pages} pages at once (--max-pages): "
               f"close another page, then reload")
        self.refusals.say(f"a page from {request.remote}: {why}")
        with contextlib.suppress(Exception):  # a page gone meanwhile
            await asyncio.wait_for(ws.send_str(error_message(why)), SEND_TIMEOUT)
            await asyncio.wait_for(ws.close(code=PAGES_FULL, message=why[:120].encode()),
                                   SEND_TIMEOUT)
        return ws

    async def _sender(self, page: _Page) -> None:
        with contextlib.suppress(asyncio.CancelledError, ConnectionError, RuntimeError):
            while not page.ws.closed:
                await page.wake.wait()
                page.wake.clear()
                for text in page.take():
                    try:
                        await asyncio.wait_for(page.ws.send_str(text), SEND_TIMEOUT)
                    except TimeoutError:
                        self._close_unread(page, f"a send waited {SEND_TIMEOUT:g} s")
                        return

    def _close_unread(self, page: _Page, why: str) -> None:
        """A page that reads nothing (a send waited ``SEND_TIMEOUT`` s, or it left a ping
        unanswered): closed, its commands end; a page reading again reconnects."""
        if page.unread:
            return  # found out both ways: said once
        page.unread = True
        self.stats["closed_unread"] += 1
        log.warning("page #%d reads nothing (%s): closing its connection", page.id, why)
        transport = page.request.transport if page.request is not None else None
        if transport is not None:
            transport.abort()  # its unread bytes go; the receive loop ends, the robot stops

    def counters(self) -> dict:
        """What the console did (``--stats``): pages served, robots seen, labels per robot."""
        return {"pages": self._next_page - 1, "robots": self.robot_names(),
                "labelled": {n: r.pubs.published for n, r in self.robots.items()
                             if r.pubs is not None},
                **self.stats, "refused": self.refusals.total,
                "throttled": self.throttle.throttled,
                "dropped": dict(self.decoder.counts)}

    def close(self) -> None:
        end = time.monotonic() + DRAIN  # one wait for every robot's last acknowledgements
        for r in self.robots.values():
            self._unhold(r, "the console stops")
            if r.hold is not None:  # held or not: no token outlives the console
                r.hold.release()
            if r.pubs is not None:
                r.pubs.drain(max(0.0, end - time.monotonic()))  # the person's last labels
                r.pubs.close()
            if r.client is not None:
                r.client.close()
            if r.learners is not None:
                with contextlib.suppress(Exception):
                    r.learners.sub.undeclare()
        for sub in self.subs:
            with contextlib.suppress(Exception):
                sub.undeclare()


def _ssl_context(args) -> ssl.SSLContext | None:
    if not (args.tls_cert or args.tls_key):
        return None
    if not (args.tls_cert and args.tls_key):
        raise ProcessError("console: --tls-cert and --tls-key go together", EXIT_USAGE)
    ctx = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    try:
        ctx.load_cert_chain(args.tls_cert, args.tls_key)
    except (OSError, ssl.SSLError) as exc:
        raise ProcessError(f"console: cannot load the TLS certificate/key: {exc}",
                           EXIT_USAGE) from exc
    return ctx


def body(ctx: Context) -> int:
    args = ctx.args
    try:
        host, port = parse_http(args.http)
    except ValueError as exc:
        raise ProcessError(f"console: {exc}", EXIT_USAGE) from exc
    token = access_token(host, args.token)
    tls = _ssl_context(args)
    if not is_loopback(host) and tls is None:
        log.warning("console: listening on %s without TLS: the token and the page travel in "
                    "clear text (give --tls-cert/--tls-key, or use an SSH tunnel)", host)
    if not args.view_only:
        ctx.declare_token()  # rhbl/alive/console/<robot>-<pid>: who is up, like every process
    return asyncio.run(_serve(ctx, host, port, token, tls))


async def _serve(ctx: Context, host: str, port: int, token: str | None,
                 tls: ssl.SSLContext | None) -> int:
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    console = Console(ctx, loop, token)
    ctx.report(console.counters)
    app = web.Application(middlewares=[guard(console.refusals, log)])
    app.router.add_get("/", console.index)
    app.router.add_get("/ws", console.websocket)
    app.router.add_get("/static/{name}", console.static)
    header_timeout = getattr(ctx.args, "header_timeout", HEADER_TIMEOUT)
    runner = web.AppRunner(app, access_log=None, handle_signals=False,
                           keepalive_timeout=header_timeout,
                           logger=ServerLog(log, console.refusals))
    await runner.setup()
    try:
        site = web.TCPSite(runner, host, port, ssl_context=tls)
        try:
            await site.start()
        except OSError as exc:
            raise ProcessError(f"console: cannot listen on {host}:{port}: {exc}",
                               EXIT_USAGE) from exc
        bound = site._server.sockets[0].getsockname()[1] if port == 0 else port
        shown = f"[{host}]" if ":" in host else host
        url = f"{'https' if tls else 'http'}://{shown}:{bound}/"
        if token:
            url += f"?token={token}"
        print(f"console: {url}", flush=True)
        log.info("serving the console for robot %s%s", ctx.robot,
                 " (view-only)" if console.view_only else "")
        dog = asyncio.create_task(console.watchdog())
        await stop.wait()
        dog.cancel()
    finally:
        console.close()
        for page in list(console.pages.values()):
            with contextlib.suppress(Exception):
                await page.ws.close()
        await runner.cleanup()
    return 0
