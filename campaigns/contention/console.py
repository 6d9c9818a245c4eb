"""Contention probes: the console (see campaigns/contention/__init__.py and docs/reliability.md,
"Contention: the console").

- ``console-robot-names``: stand-still commands for ``N`` robot names no server serves, on
  ``rhbl/fake<i>/position2d/0/cmd/vel/x`` from one session (the shipped router lets the
  controller's and ROS 2's credentials publish there for any name). Measured: the console's
  resident memory before and after (``/proc/PID/status``), the robot lists a real page was
  sent, the page's scans per second while it lasts, whether its WebSocket stayed open. Holds
  when the console grew less than ``MAX_GROWTH_MB``, the page kept ``MIN_SCANS`` scans/s and
  stayed open.
- ``console-pages``: ``N`` idle pages (WebSockets that read what comes and say nothing) beside
  a real page opened first. Measured: the real page's scans/s before and with them, how many
  were refused and how. Holds when the real page kept ``MIN_SCANS`` scans/s and the pages over
  the console's limit were refused with a reason.
- ``console-tokens``: ``rhbl console --token=a`` (refused: exit 2 and one line?), then ``N``
  wrong tokens from one address against a console with a strong token. Measured: how many
  were checked (401) and how many throttled (429), and whether the right token from another
  loopback address (127.0.0.2) still gets the page meanwhile. Holds when the weak token is
  refused, at most the burst plus one a second were checked, and the other address is served.
"""

from __future__ import annotations

import asyncio
import json
import subprocess
import sys
import time
from pathlib import Path

from campaigns.contention import Outcome, Probe, ProbeFunction
from lab.children import Child, free_port, rhbl_argv, rss_kib

__all__ = ["PROBES"]

ROOT = Path(__file__).resolve().parents[2]
MAX_GROWTH_MB = 60.0  # the console's growth under the robot-name flood
MIN_SCANS = 9.0  # scans/s a real page keeps (the server scans at 10 Hz)
STRONG = "probe-Token-7f3c9a1e5b2d"  # a token that passes the console's rule


# ---- processes ---------------------------------------------------------------------------
def _server(probe: Probe) -> tuple[Child, str]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    srv = Child("rhbl server", rhbl_argv("server", "--world", "room", "--listen", endpoint),
                probe.workdir, cwd=ROOT).start()
    if not srv.wait_for_line("listening on", 60):
        srv.stop()
        raise RuntimeError(f"rhbl server did not start:\n{srv.tail()}")
    return srv, endpoint


def _console(probe: Probe, endpoint: str, *extra: str) -> tuple[Child, str]:
    con = Child("rhbl console", rhbl_argv("console", "--connect", endpoint, "--http",
                                          "127.0.0.1:0", *extra), probe.workdir, cwd=ROOT).start()
    if not con.wait_for_line("console: http", 60):
        con.stop()
        raise RuntimeError(f"rhbl console did not print its URL:\n{con.tail()}")
    url = next(ln.split(" ", 1)[1] for ln in con.output().splitlines()
               if ln.startswith("console: "))
    return con, url


def _ws_url(url: str) -> str:
    base, _, query = url.partition("?")
    return base.replace("http://", "ws://", 1) + "ws" + (f"?{query}" if query else "")


def _mb(kib: int) -> float:
    return round(kib / 1024, 1)


class _Page:
    """A real page's view over a WebSocket: the scans of ``robot`` it was sent (times), the
    ``robots`` lists (count, largest), whether its connection closed."""

    def __init__(self, robot: str = "r0"):
        self.robot = robot
        self.scans: list[float] = []
        self.lists = 0
        self.list_bytes = 0
        self.most_listed = 0  # the most robot names a list held
        self.closed: str | None = None
        self.refused: str | None = None
        self.hello = asyncio.Event()

    async def run(self, session, url: str) -> None:
        try:
            async with session.ws_connect(url, heartbeat=None, max_msg_size=0) as ws:
                async for msg in ws:
                    if msg.type != 1:  # aiohttp.WSMsgType.TEXT
                        break
                    m = json.loads(msg.data)
                    t = m.get("t")
                    if t == "hello":
                        self.hello.set()
                        self.most_listed = max(self.most_listed, len(m.get("robots", ())))
                    elif t == "scan" and m.get("robot") == self.robot:
                        self.scans.append(time.monotonic())
                    elif t == "robots":
                        self.lists += 1
                        self.list_bytes = max(self.list_bytes, len(msg.data))
                        self.most_listed = max(self.most_listed, len(m.get("robots", ())))
                    elif t == "error" and not self.hello.is_set():
                        self.refused = m.get("error")
                self.closed = f"closed (code {ws.close_code})"
                if ws.close_code is not None and ws.close_code != 1000 and self.refused is None:
                    self.refused = f"closed with code {ws.close_code}"
        except Exception as exc:  # noqa: BLE001 - a refusal or a drop is what is measured
            self.closed = f"{type(exc).__name__}: {exc}"
            if self.refused is None:
                self.refused = self.closed

    def rate(self, start: float, end: float) -> tuple[float, float]:
        """(scans per second within [start, end], the longest gap between two scans there)."""
        got = [t for t in self.scans if start <= t <= end]
        edges = [start, *got, end]
        gap = max(b - a for a, b in zip(edges, edges[1:], strict=False))
        return round(len(got) / max(end - start, 1e-9), 1), round(gap, 2)


async def _wait_scans(page: _Page, n: int, timeout: float) -> None:
    end = time.monotonic() + timeout
    while len(page.scans) < n:
        if time.monotonic() > end or page.closed:
            raise RuntimeError(f"the page got {len(page.scans)} scans, not {n}, within "
                               f"{timeout:g} s ({page.closed or 'open'})")
        await asyncio.sleep(0.05)


# ---- robot names -------------------------------------------------------------------------
def _flood_names(endpoint: str, n: int) -> float:
    """``n`` stand-still commands, one per robot name ``fake<i>``; the seconds it took."""
    import zenoh

    from process.session import make_config
    from protocol.messages import VelCmd

    payload = VelCmd(vx=0.0, va=0.0, state=True, source="x").encode()
    with zenoh.open(make_config(mode="client", connect=[endpoint])) as s:
        t0 = time.monotonic()
        for i in range(n):
            s.put(f"rhbl/fake{i}/position2d/0/cmd/vel/x", payload)
        took = time.monotonic() - t0
        time.sleep(0.5)  # let the session flush before it closes
    return took


def robot_names(probe: Probe) -> Outcome:
    import aiohttp

    n = 20_000 if probe.full else 2_000
    watch = 30.0 if probe.full else 10.0  # s the page is watched after the flood starts
    srv, endpoint = _server(probe)
    con = None
    try:
        con, url = _console(probe, endpoint)

        async def run() -> dict:
            page = _Page()
            async with aiohttp.ClientSession() as http:
                reader = asyncio.create_task(page.run(http, _ws_url(url)))
                await _wait_scans(page, 20, 60)
                before = rss_kib(con.pid)
                lists0 = page.lists
                t0 = time.monotonic()
                took = await asyncio.get_running_loop().run_in_executor(
                    None, _flood_names, endpoint, n)
                await asyncio.sleep(max(0.0, watch - (time.monotonic() - t0)))
                rate, gap = page.rate(t0, time.monotonic())
                after = rss_kib(con.pid)
                closed = page.closed
                reader.cancel()
            return {"names": n, "flood_s": round(took, 2), "rss_before_mb": _mb(before),
                    "rss_after_mb": _mb(after), "growth_mb": _mb(after - before),
                    "lists": page.lists - lists0, "most_listed": page.most_listed,
                    "largest_list_kb": round(page.list_bytes / 1024, 1),
                    "scans_per_s": rate, "longest_gap_s": gap, "page": closed or "open"}

        f = asyncio.run(run())
    finally:
        if con is not None:
            con.stop()
        srv.stop()
    ok = (f["growth_mb"] < MAX_GROWTH_MB and f["scans_per_s"] >= MIN_SCANS
          and f["page"] == "open" and f["most_listed"] <= 1)  # r0, the only robot served
    said = (f"{n} robot names: the console grew {f['growth_mb']} MB, the page got "
            f"{f['scans_per_s']} scans/s (longest gap {f['longest_gap_s']} s) and "
            f"{f['lists']} robot lists (up to {f['most_listed']} names); its WebSocket "
            f"{f['page']}")
    return Outcome(ok, said, f)


# ---- pages -------------------------------------------------------------------------------
def pages(probe: Probe) -> Outcome:
    import aiohttp

    n = 1_500 if probe.full else 150
    window = 10.0 if probe.full else 5.0
    srv, endpoint = _server(probe)
    con = None
    try:
        con, url = _console(probe, endpoint)

        async def run() -> dict:
            page = _Page()
            connector = aiohttp.TCPConnector(limit=0)
            async with aiohttp.ClientSession(connector=connector) as http:
                reader = asyncio.create_task(page.run(http, _ws_url(url)))
                await _wait_scans(page, 20, 60)
                t0 = time.monotonic()
                await asyncio.sleep(window)
                alone, _ = page.rate(t0, time.monotonic())
                idle = [_Page("none") for _ in range(n)]
                tasks = []
                for i, p in enumerate(idle):
                    tasks.append(asyncio.create_task(p.run(http, _ws_url(url))))
                    if i % 50 == 49:
                        await asyncio.sleep(0)  # the connections opened a few at a time
                await asyncio.sleep(3.0)  # the idle pages connected (or refused)
                t1 = time.monotonic()
                await asyncio.sleep(window)
                crowded, gap = page.rate(t1, time.monotonic())
                refused = [p.refused for p in idle if p.refused]
                served = sum(1 for p in idle if p.hello.is_set() and not p.refused)
                for t in (*tasks, reader):
                    t.cancel()
                await asyncio.gather(*tasks, reader, return_exceptions=True)
            return {"idle_pages": n, "served": served, "refused": len(refused),
                    "scans_per_s_alone": alone, "scans_per_s_with_idle": crowded,
                    "longest_gap_s": gap, "page": page.closed or "open",
                    "refusal": (refused[0][:100] if refused else "")}

        f = asyncio.run(run())
        rss = rss_kib(con.pid)
        f["console_rss_mb"] = _mb(rss)
    finally:
        if con is not None:
            con.stop()
        srv.stop()
    limited = f["refused"] > 0 and "pages" in f["refusal"]
    ok = limited and f["scans_per_s_with_idle"] >= MIN_SCANS and f["page"] == "open"
    said = (f"{n} idle pages: {f['served']} served, {f['refused']} refused"
            f"{' (' + repr(f['refusal']) + ')' if f['refusal'] else ''}; the real page "
            f"{f['scans_per_s_alone']} -> {f['scans_per_s_with_idle']} scans/s")
    return Outcome(ok, said, f)


# ---- tokens ------------------------------------------------------------------------------
def _weak_token_refused(endpoint: str) -> tuple[bool, str, int | None]:
    """``rhbl console --token=a``: (refused with exit 2 and one line, that line, its exit
    status; None when it ran with the token until stopped)."""
    argv = rhbl_argv("console", "--connect", endpoint, "--http", "127.0.0.1:0", "--token=a")
    proc = subprocess.Popen(argv, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        out, err = proc.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        proc.terminate()  # it runs with the weak token: not refused
        try:
            out, err = proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            out, err = proc.communicate()
        said = [ln for ln in (out + err).splitlines() if ln.startswith("console: ")]
        return False, f"it served with the token: {said[0] if said else '?'}", None
    lines = [ln for ln in err.strip().splitlines() if ln]
    return proc.returncode == 2 and len(lines) == 1, (lines[0] if lines else ""), proc.returncode


def tokens(probe: Probe) -> Outcome:
    import aiohttp

    n = 1_000 if probe.full else 100
    srv, endpoint = _server(probe)
    con = None
    try:
        weak_ok, line, rc = _weak_token_refused(endpoint)
        con, url = _console(probe, endpoint, f"--token={STRONG}")
        base = url.split("?", 1)[0]

        async def run() -> dict:
            codes: dict[int, int] = {}
            said = ""
            async with aiohttp.ClientSession() as http:
                t0 = time.monotonic()
                for i in range(n):
                    async with http.get(f"{base}?token=wrong{i}") as r:
                        codes[r.status] = codes.get(r.status, 0) + 1
                        if r.status == 429 and not said:
                            said = (await r.text()).strip()
                took = time.monotonic() - t0
            # the right token from another loopback address, while this one is throttled
            other = aiohttp.TCPConnector(local_addr=("127.0.0.2", 0))
            async with aiohttp.ClientSession(connector=other) as http2, \
                    http2.get(f"{base}?token={STRONG}") as r:
                other_status = r.status
            return {"tries": n, "seconds": round(took, 2), "checked_401": codes.get(401, 0),
                    "throttled_429": codes.get(429, 0), "other_address": other_status,
                    "throttle_said": said[:100]}

        f = asyncio.run(run())
    finally:
        if con is not None:
            con.stop()
        srv.stop()
    f.update({"weak_token_exit": rc, "weak_token_line": line[:120]})
    burst_allowed = 10 + f["seconds"] + 1
    ok = (weak_ok and f["checked_401"] <= burst_allowed and f["throttled_429"] > 0
          and f["other_address"] == 200)
    said = (f"--token=a: {'refused (exit 2): ' + line[:80] if weak_ok else f'not refused (exit {rc})'}; "
            f"{n} wrong tokens from one address: {f['checked_401']} checked, "
            f"{f['throttled_429']} throttled; the right one from 127.0.0.2: {f['other_address']}")
    return Outcome(ok, said, f)


PROBES: dict[str, ProbeFunction] = {
    "console-robot-names": robot_names,
    "console-pages": pages,
    "console-tokens": tokens,
}

if __name__ == "__main__":  # pragma: no cover - python -m campaigns.contention --only ...
    sys.exit("run: python -m campaigns.contention --only console-robot-names,...")
