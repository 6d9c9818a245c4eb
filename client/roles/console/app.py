"""The server side of ``rhbl console``: zenoh subscriptions -> JSON over a WebSocket, and the
person's commands -> the teacher's keys.

Threads: zenoh delivers samples in its own threads; each callback decodes and validates the
message (``protocol.messages``), turns it into one JSON text and hands it to the asyncio loop
(``call_soon_threadsafe``), which keeps only the latest text of each kind per robot and page:
a slow page skips frames, it never builds a backlog and never slows the bus down.

The page's messages (JSON objects, at most 4 KiB; anything else is answered with an ``error``
and the connection stays up):

    {"t": "view", "robot": "r1"}                 watch another robot of the server
    {"t": "mode", "mode": "demonstrate"|"watch"|"correct"}
    {"t": "drive", "action": "fwd", "scan_id": 812}   the key held now, for the scan displayed
    {"t": "release"}                              keys up / page hidden: stop commanding now
    {"t": "take"}                                 take the robot over from another page

One page at a time drives a robot: the first page that drives holds it until it leaves, switches
to watch or another page takes over explicitly. The robot never moves on a stale key: a release,
the page's WebSocket closing or no ``drive`` for ``STALE`` seconds end the person's commands at
once (a last zero command, then the teacher's hold token is withdrawn, so the server hands the
robot to the controller, or stops it, on the next tick).

Messages to the page: ``hello``, ``world``, ``state``, ``scan``, ``cmd`` (the action being
executed), ``notice``, ``decision``, ``control`` (who holds each robot), ``robots``, ``error``.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import ipaddress
import json
import logging
import math
import os
import secrets
import signal
import ssl
import time
from collections import OrderedDict
from pathlib import Path

from aiohttp import WSMsgType, web

from client.behaviour.actions import DEFAULT_ACTIONS
from client.labels import DRAIN, Hold, LabelPublisher
from client.player import PlayerClient
from protocol import keys
from protocol.decoding import Decoder
from protocol.messages import Decision, Scan, State, TreeNotice, VelCmd, WorldInfo
from protocol.runtime import EXIT_USAGE, Context, ProcessError

__all__ = ["STALE", "Console", "access_token", "body", "host_name", "parse_http"]

log = logging.getLogger(__name__)

STATIC = Path(__file__).with_name("static")
STALE = 0.5  # s of wall time without a ``drive`` from the page: its key is stale, stop
MAX_MESSAGE = 4096  # bytes of a page's message
MODES = ("demonstrate", "watch", "correct")
SCAN_MEMORY = 128  # scan ids remembered per robot (a page's label must name one of these)


def parse_http(value: str) -> tuple[str, int]:
    """``HOST:PORT`` (``[v6]:PORT`` too) -> (host, port); ValueError with a clear message."""
    host, sep, port = value.rpartition(":")
    host = host.strip("[]")
    if not sep or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise ValueError(f"--http must be HOST:PORT (e.g. 127.0.0.1:8080), got {value!r}")
    return host, int(port)


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def host_name(host: str) -> str:
    """The name in a Host header: ``[::1]:8080`` -> ``::1``, ``localhost:80`` -> ``localhost``."""
    if host.startswith("["):
        return host[1:].split("]", 1)[0]
    return host.rsplit(":", 1)[0] if host.count(":") == 1 else host


def access_token(host: str, token: str | None) -> str | None:
    """The token the page's URL must carry: the given one, else a random one on any address
    other than loopback, else none."""
    if token:
        return token
    return None if is_loopback(host) else secrets.token_urlsafe(18)


def _action_of(vx: float, va: float) -> str:
    for name, (ax, aa) in DEFAULT_ACTIONS.items():
        if math.isclose(vx, ax, abs_tol=1e-6) and math.isclose(va, aa, abs_tol=1e-6):
            return name
    return "stop" if vx == 0 and va == 0 else f"vx {vx:.2f} va {va:.2f}"


class _Page:
    def __init__(self, ident: int, ws: web.WebSocketResponse, robot: str):
        self.id, self.ws, self.robot = ident, ws, robot
        self.mode = "demonstrate"
        self.pending: dict[str, str] = {}  # kind -> latest JSON text
        self.errors = 0
        self.wake = asyncio.Event()

    def push(self, kind: str, text: str) -> None:
        if kind == "error":  # every error is said, the other kinds keep only their latest
            self.errors += 1
            kind = f"error-{self.errors}"
        self.pending[kind] = text
        self.wake.set()


class _Robot:
    def __init__(self, name: str):
        self.name = name
        self.world: str | None = None  # JSON of the WorldInfo
        self.world_asked = 0.0
        self.latest: dict[str, str] = {}  # kind -> JSON (for a page that starts watching)
        self.scans: OrderedDict[int, Scan] = OrderedDict()  # id -> the scan (labels carry it)
        self.last_scan: Scan | None = None
        self.holder: _Page | None = None
        self.action: str | None = None  # what the person commands now
        self.last_drive = 0.0
        self.labelled = -1  # the last scan id labelled
        self.client: PlayerClient | None = None  # the person's commands, as the teacher's
        self.pubs: LabelPublisher | None = None
        self.hold: Hold | None = None


class Console:
    def __init__(self, ctx: Context, loop: asyncio.AbstractEventLoop, token: str | None):
        self.ctx, self.session, self.loop = ctx, ctx.session, loop
        self.view_only = bool(ctx.args.view_only)
        self.token = token
        self.robots: dict[str, _Robot] = {}
        self.pages: dict[int, _Page] = {}
        self._next_page = 1
        self._tasks: set[asyncio.Task] = set()  # kept referenced until done
        self.default_robot = ctx.robot
        self._robot(self.default_robot)
        self.subs = []
        # a malformed message never stops the console: dropped, counted
        self.decoder = Decoder(log, level=logging.DEBUG)
        s = self.session
        for key_of, fn in ((keys.state_key, self._on_state), (keys.scan_key, self._on_scan),
                           (keys.learner_notice_key, self._on_notice),
                           (keys.controller_decision_key, self._on_decision),
                           (keys.cmd_vel_subscription, self._on_cmd)):
            self.subs.append(s.declare_subscriber(key_of(keys.EVERY), fn))

    def _decode(self, cls, sample):
        """(the message, its robot) of a sample, or (None, robot): dropped, counted."""
        return (self.decoder.decode(cls, sample.payload.to_bytes()),
                keys.parse(sample.key_expr).robot)

    # ---- zenoh side (zenoh threads): decode, make JSON, hand over to the loop ----------------
    def _hand(self, robot: str, kind: str, text: str, scan=None) -> None:
        with contextlib.suppress(RuntimeError):  # the loop is closing
            self.loop.call_soon_threadsafe(self._deliver, robot, kind, text, scan)

    def _on_state(self, sample) -> None:
        st, robot = self._decode(State, sample)
        if st is None:
            return
        pose = st.truth if st.truth is not None else st.pos
        self._hand(robot, "state", json.dumps({
            "t": "state", "robot": robot, "ts": st.ts, "seq": st.seq,
            "pose": [round(x, 4) for x in pose], "vel": [round(x, 4) for x in st.vel],
            "stall": st.stall, "driver": st.driver}))

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

    def _on_notice(self, sample) -> None:
        n, robot = self._decode(TreeNotice, sample)
        if n is None:
            return
        self._hand(robot, "notice", json.dumps({
            "t": "notice", "robot": robot, "seq": n.seq, "nodes": n.nodes, "height": n.height,
            "vectors": n.vectors, "snapshot_id": n.snapshot_id, "ts": n.ts}))

    def _on_decision(self, sample) -> None:
        d, robot = self._decode(Decision, sample)
        if d is None:
            return
        path = [{"index": i, "depth": dp, "label": lab,
                 "radius": round(r, 4) if math.isfinite(r) else None}
                for i, dp, r, lab in d.path]
        self._hand(robot, "decision", json.dumps({
            "t": "decision", "robot": robot, "scan_id": d.scan_id, "ts": d.ts,
            "action": d.action, "snapshot_id": d.snapshot_id, "nodes": d.nodes, "path": path}))

    def _on_cmd(self, sample) -> None:
        c, robot = self._decode(VelCmd, sample)
        if c is None:
            return
        source = keys.source_of_cmd_key(str(sample.key_expr)) or c.source
        action = _action_of(c.vx, c.va) if c.state else "motors off"
        self._hand(robot, f"cmd-{source}", json.dumps({
            "t": "cmd", "robot": robot, "source": source, "action": action,
            "scan_id": c.scan_id}))

    # ---- loop side ------------------------------------------------------------------------
    def _robot(self, name: str) -> _Robot:
        r = self.robots.get(name)
        if r is None:
            r = self.robots[name] = _Robot(name)
            self._ask_world(r)
            self._broadcast(json.dumps({"t": "robots", "robots": sorted(self.robots)}))
        return r

    def _ask_world(self, r: _Robot) -> None:
        now = time.monotonic()
        if r.world is not None or now - r.world_asked < 5.0:
            return
        r.world_asked = now

        def fetch() -> str | None:
            try:
                for reply in self.session.get(keys.sim_request_key(r.name, "get_world"),
                                              timeout=2.0):
                    if reply.ok is not None:
                        w = WorldInfo.decode(reply.ok.payload.to_bytes())
                        return json.dumps({
                            "t": "world", "robot": r.name, "name": w.name, "task": w.task,
                            "walls": w.walls, "goal": w.goal, "starts": w.starts})
            except Exception as exc:  # noqa: BLE001 - a real robot has no world to give
                log.info("no world for robot %s: %s", r.name, exc)
            return None

        async def get() -> None:
            text = await self.loop.run_in_executor(None, fetch)
            if text is not None:
                r.world = text
                for p in self.pages.values():
                    if p.robot == r.name:
                        p.push("world", text)

        task = self.loop.create_task(get())
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    def _deliver(self, robot: str, kind: str, text: str, scan) -> None:
        r = self._robot(robot)
        if r.world is None:  # the server came up after the console (asked at most every 5 s)
            self._ask_world(r)
        if scan is not None:
            r.scans[scan.id] = scan
            r.last_scan = scan
            while len(r.scans) > SCAN_MEMORY:
                r.scans.popitem(last=False)
        r.latest[kind] = text
        for p in self.pages.values():
            if p.robot == robot:
                p.push(kind, text)

    def _broadcast(self, text: str, kind: str = "robots") -> None:
        for p in self.pages.values():
            p.push(kind, text)

    def _control_text(self, r: _Robot) -> str:
        h = r.holder
        return json.dumps({"t": "control", "robot": r.name, "holder": h.id if h else None,
                           "holder_mode": h.mode if h else None, "action": r.action})

    def _announce(self, r: _Robot) -> None:
        text = self._control_text(r)
        for p in self.pages.values():
            if p.robot == r.name:
                p.push("control", text)

    # -- the person's commands --
    def _drive(self, page: _Page, action, scan_id) -> str | None:
        """Publish the page's command and label; an error text when refused."""
        if self.view_only:
            return "this console is view-only (--view-only): it publishes nothing"
        if page.mode == "watch":
            return "watch mode: switch to demonstrate or correct to drive"
        if action not in DEFAULT_ACTIONS.names:
            return f"unknown action {action!r}; one of {', '.join(DEFAULT_ACTIONS.names)}"
        if isinstance(scan_id, bool) or not isinstance(scan_id, int):
            return f"'scan_id' must be the integer id of the scan displayed, got {scan_id!r}"
        r = self.robots[page.robot]
        if r.holder is not None and r.holder is not page:
            return (f"page #{r.holder.id} holds robot {r.name}: watch, or take over "
                    f"explicitly")
        scan = r.scans.get(scan_id)
        if scan is None:
            return (f"scan {scan_id} is not among the last {SCAN_MEMORY} scans of robot "
                    f"{r.name}: the page is behind, not driving on a stale view")
        if r.pubs is None:
            r.client = PlayerClient(session=self.session, robot=r.name, source="teacher",
                                    express=True, block=True)
            r.pubs = LabelPublisher(self.session, r.name)
            # the teacher's hold token, one per robot driven (its ident names that robot)
            r.hold = Hold(self.session, f"{r.name}-{os.getpid()}")
        box = r.pubs.outbox
        if box is not None and box.full:
            return (f"{len(box)} labels wait for a learner's acknowledgement (at most "
                    f"{box.cap}): not driving until one acknowledges them (they are resent "
                    f"while a learner is up)")
        changed = r.holder is not page or r.action != action
        r.holder = page
        vx, va = DEFAULT_ACTIONS[action]
        r.hold.acquire()  # before the command: the server may release the teacher at once
        r.client.answer(scan, vx, va)
        if scan_id > r.labelled:  # one label per scan (the learner learns it like any other)
            r.pubs.label(scan, action, action)
            r.labelled = scan_id
        r.action, r.last_drive = action, time.monotonic()
        if changed:
            log.info("page #%d drives robot %s: %s (%s)", page.id, r.name, action, page.mode)
            self._announce(r)
        return None

    def _stop(self, r: _Robot, why: str) -> None:
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

    def _unhold(self, r: _Robot, why: str) -> None:
        self._stop(r, why)
        if r.holder is not None:
            r.holder = None
            self._announce(r)

    async def watchdog(self) -> None:
        while True:
            await asyncio.sleep(0.05)
            now = time.monotonic()
            for r in self.robots.values():
                if r.action is not None and now - r.last_drive > STALE:
                    self._stop(r, f"no key from the page for {STALE:g} s")

    def handle(self, page: _Page, raw) -> None:
        """One message of a page (a bad one is answered with an error, never raised)."""
        err = None
        try:
            msg = json.loads(raw)
            if not isinstance(msg, dict):
                raise ValueError("expected a JSON object")
        except ValueError as exc:
            page.push("error", json.dumps({"t": "error", "error": f"bad message: {exc}"}))
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
            if not isinstance(name, str) or name not in self.robots:
                err = f"unknown robot {name!r}; known: {', '.join(sorted(self.robots))}"
            else:
                if r is not None and r.holder is page:
                    self._unhold(r, "the page watches another robot")
                page.robot = name
                self._send_robot(page)
        else:
            err = f"unknown message type {t!r}"
        if err:
            page.push("error", json.dumps({"t": "error", "error": err}))

    def _send_robot(self, page: _Page) -> None:
        r = self._robot(page.robot)
        self._ask_world(r)
        if r.world is not None:
            page.push("world", r.world)
        for kind, text in r.latest.items():
            page.push(kind, text)
        page.push("control", self._control_text(r))

    # ---- HTTP ------------------------------------------------------------------------------
    def _authorised(self, request: web.Request) -> bool:
        if self.token is None:
            # no token (loopback only): the page must be asked for by a loopback name, so a
            # site whose name an attacker points at 127.0.0.1 (DNS rebinding) gets nothing
            if not is_loopback(host_name(request.host or "")):
                raise web.HTTPForbidden(text=f"rhbl console: Host {request.host!r} refused: "
                                             f"open it as http://127.0.0.1:<port>/\n")
            return True
        given = request.query.get("token", "")
        return hmac.compare_digest(given.encode(), self.token.encode())

    async def index(self, request: web.Request) -> web.StreamResponse:
        if not self._authorised(request):
            raise web.HTTPUnauthorized(text="rhbl console: a valid ?token= is required "
                                            "(printed in the console's URL)\n")
        return web.FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-store"})

    async def websocket(self, request: web.Request) -> web.StreamResponse:
        if not self._authorised(request):
            raise web.HTTPUnauthorized(text="rhbl console: a valid ?token= is required\n")
        origin = request.headers.get("Origin")
        own = f"{request.scheme}://{request.host}"
        if origin is not None and origin != own:
            log.warning("refused a WebSocket from origin %s (expected %s)", origin, own)
            raise web.HTTPForbidden(text=f"rhbl console: foreign origin {origin} refused\n")
        ws = web.WebSocketResponse(heartbeat=5.0, max_msg_size=MAX_MESSAGE)
        await ws.prepare(request)
        page = _Page(self._next_page, ws, self.default_robot)
        self._next_page += 1
        self.pages[page.id] = page
        log.info("page #%d connected from %s", page.id, request.remote)
        page.push("hello", json.dumps({
            "t": "hello", "page": page.id, "robot": page.robot, "view_only": self.view_only,
            "modes": list(MODES), "actions": list(DEFAULT_ACTIONS.names), "stale": STALE,
            "robots": sorted(self.robots)}))
        self._send_robot(page)
        sender = asyncio.create_task(self._sender(page))
        try:
            async for msg in ws:
                if msg.type == WSMsgType.TEXT:
                    try:
                        self.handle(page, msg.data)
                    except Exception as exc:  # noqa: BLE001 - a page never kills the console
                        log.exception("page #%d: message not handled", page.id)
                        page.push("error", json.dumps({"t": "error", "error": str(exc)}))
                elif msg.type == WSMsgType.BINARY:
                    page.push("error", json.dumps({"t": "error",
                                                   "error": "binary messages are not understood"}))
                else:
                    break
        finally:
            # the page closed, reloaded or lost its connection: its commands end now
            self.pages.pop(page.id, None)
            for r in self.robots.values():
                if r.holder is page:
                    self._unhold(r, f"page #{page.id} disconnected")
            sender.cancel()
            log.info("page #%d disconnected", page.id)
        return ws

    async def _sender(self, page: _Page) -> None:
        with contextlib.suppress(asyncio.CancelledError, ConnectionError, RuntimeError):
            while not page.ws.closed:
                await page.wake.wait()
                page.wake.clear()
                batch, page.pending = page.pending, {}
                for text in batch.values():
                    await page.ws.send_str(text)

    def counters(self) -> dict:
        """What the console did (``--stats``): pages served, robots seen, labels per robot."""
        return {"pages": self._next_page - 1, "robots": sorted(self.robots),
                "labelled": {n: r.pubs.published for n, r in self.robots.items()
                             if r.pubs is not None},
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
    app = web.Application()
    app.router.add_get("/", console.index)
    app.router.add_get("/ws", console.websocket)
    app.router.add_static("/static/", STATIC, show_index=False)
    runner = web.AppRunner(app, access_log=None, handle_signals=False)
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
