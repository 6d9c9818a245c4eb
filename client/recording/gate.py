"""The Foxglove bridge's front door: the console's rules (``client.access``) for who may open its
WebSocket.

foxglove-sdk's WebSocket server checks only the subprotocol of an upgrade (it has no hook for
the request's Origin, Host or a token), so ``rhbl foxglove`` runs it on a free loopback port
and serves the address the person names with this gate, which reads each request's header
(at most ``MAX_HEADER`` bytes within ``HEADER_TIMEOUT`` s), decides, and then either answers
with an HTTP error or relays the connection, bytes unchanged, to the SDK's server:

- without a token (the default on a loopback address) the request must name a loopback host
  (``Host: 127.0.0.1:8765``, ``localhost``, ``[::1]``): a site whose name an attacker points at
  127.0.0.1 (DNS rebinding) is refused;
- with a token (``--token``, or a random one on any other address, printed in the URL) the
  request's ``?token=`` must carry it; a weak ``--token`` is refused as the console refuses it
  (``client.access.check_strength``), and an address that gave too many wrong tokens waits
  (``client.access.Throttle``: 429 with Retry-After, counted ``throttled``);
- a request with an ``Origin`` (one a web page's script makes) is refused unless that origin
  is one the person allowed (``--allow-origin https://app.foxglove.dev``); apps and programs
  that send none (the desktop apps, ``websockets``) are not asked for one;
- an address other than loopback needs TLS (``--tls-cert``/``--tls-key``): the token and the
  live data would travel in clear text.

Each refusal is one log line (at most one a second, with the count of those not logged).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import ssl
import threading
import time
from urllib.parse import parse_qs, urlsplit

from client.access import Throttle, access_token, check_token, host_name, is_loopback
from process.arguments import Checked

__all__ = ["HEADER_TIMEOUT", "MAX_HEADER", "Gate", "access_token", "is_loopback", "origin"]

log = logging.getLogger(__name__)

MAX_HEADER = 8192  # bytes of one request's header
HEADER_TIMEOUT = 10.0  # s to send it


def _origin(text: str) -> str:
    parts = urlsplit(text)
    if parts.scheme not in ("http", "https") or not parts.hostname or parts.path not in \
            ("", "/") or parts.query or parts.fragment or parts.username:
        raise ValueError(f"must be an origin SCHEME://HOST[:PORT] (e.g. "
                         f"https://app.foxglove.dev), got {text!r}")
    return text.rstrip("/")


origin = Checked("origin", _origin)  # ``--allow-origin``
origin.kind, origin.example = "origin", "https://app.foxglove.dev"


class Gate:
    """Serves ``host:port`` (TLS with ``tls``), relays each allowed request to
    ``127.0.0.1:inner_port``. ``start()`` binds (OSError when it cannot) and returns the port;
    ``stop()`` closes everything. Counters: ``allowed``, ``refused``."""

    def __init__(self, host: str, port: int, inner_port: int, token: str | None,
                 origins: list[str], tls: ssl.SSLContext | None = None):
        self.host, self.port, self.inner_port = host, port, inner_port
        self.token, self.origins, self.tls = token, set(origins), tls
        self.allowed = self.refused = 0
        self.throttle = Throttle()  # wrong tokens per address: a few at once, then one a second
        self._unlogged = 0
        self._last_log = 0.0
        self._loop = asyncio.new_event_loop()
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="foxglove-gate", daemon=True)
        self._stop: asyncio.Event | None = None

    # -- the decision --
    def verdict(self, head: bytes, address: str = "?") -> tuple[int, str] | None:
        """None to relay a request with this header from ``address``, else (HTTP status, why).
        A wrong token costs ``address`` a try (``client.access.Throttle``); one that must wait
        is answered 429 before its token is looked at."""
        try:
            text = head.decode("latin-1")
            line, *rest = text.split("\r\n")
            method, target, _version = line.split(" ")
        except ValueError:
            return 400, "not an HTTP request"
        fields: dict[str, list[str]] = {}
        for h in rest:
            if h:
                name, sep, value = h.partition(":")
                if not sep:
                    return 400, "a malformed header line"
                fields.setdefault(name.strip().lower(), []).append(value.strip())
        if method != "GET" or "websocket" not in ",".join(fields.get("upgrade", [])).lower():
            return 400, "only a Foxglove WebSocket is served here"
        if len(fields.get("host", [])) > 1 or len(fields.get("origin", [])) > 1:
            return 400, "a repeated Host or Origin header"
        if self.token is None:
            hosts = fields.get("host", [])
            if not hosts or not is_loopback(host_name(hosts[0])):
                return 403, (f"Host {hosts[0] if hosts else None!r} refused: open it as "
                             f"ws://127.0.0.1:<port>")
        else:
            wait = math.ceil(self.throttle.wait(address))
            if wait > 0:
                return 429, f"too many wrong tokens from {address}: try again in {wait} s"
            given = parse_qs(urlsplit(target).query).get("token", [""])[0]
            if check_token(given, self.token) is not None:
                self.throttle.failed(address)
                return 401, "a valid ?token= is required (printed in the bridge's URL)"
        origins = fields.get("origin", [])
        if origins and origins[0].rstrip("/") not in self.origins:
            return 403, (f"Origin {origins[0]!r} refused (allow an app with --allow-origin "
                         f"{origins[0]})")
        return None

    def _refuse_log(self, peer, status: int, why: str) -> None:
        self.refused += 1
        now = time.monotonic()
        if now - self._last_log < 1.0:
            self._unlogged += 1
            return
        more = f" ({self._unlogged} more refused since)" if self._unlogged else ""
        self._last_log, self._unlogged = now, 0
        log.warning("foxglove: refused a request from %s: %d %s%s", peer, status, why, more)

    # -- serving --
    async def _handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter):
        peer = writer.get_extra_info("peername")
        try:
            try:
                head = await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), HEADER_TIMEOUT)
            except asyncio.LimitOverrunError:
                return await self._answer(writer, peer, 431, "a header over "
                                                             f"{MAX_HEADER} bytes")
            except TimeoutError:
                return await self._answer(writer, peer, 408, f"no complete header within "
                                                             f"{HEADER_TIMEOUT:g} s")
            except (asyncio.IncompleteReadError, ConnectionError, ssl.SSLError):
                return None
            said = self.verdict(head, peer[0] if isinstance(peer, tuple) else "?")
            if said is not None:
                return await self._answer(writer, peer, *said)
            self.allowed += 1
            inner_r, inner_w = await asyncio.open_connection("127.0.0.1", self.inner_port)
            inner_w.write(head)
            await asyncio.gather(_pipe(reader, inner_w), _pipe(inner_r, writer))
        except (ConnectionError, OSError, ssl.SSLError):
            pass
        finally:
            writer.close()

    async def _answer(self, writer, peer, status: int, why: str) -> None:
        self._refuse_log(peer, status, why)
        body = f"rhbl foxglove: {why}\n".encode()
        reason = {400: "Bad Request", 401: "Unauthorized", 403: "Forbidden",
                  408: "Request Timeout", 429: "Too Many Requests",
                  431: "Request Header Fields Too Large"}[status]
        # a 429's seconds are the last number of its reason (verdict says "try again in N s")
        retry = f"Retry-After: {why.split()[-2]}\r\n" if status == 429 else ""
        writer.write(f"HTTP/1.1 {status} {reason}\r\nContent-Type: text/plain\r\n{retry}"
                     f"Content-Length: {len(body)}\r\nConnection: close\r\n\r\n".encode()
                     + body)
        with contextlib.suppress(asyncio.TimeoutError, ConnectionError, OSError):
            await asyncio.wait_for(writer.drain(), 5)

    async def _serve(self) -> None:
        self._stop = asyncio.Event()
        try:
            server = await asyncio.start_server(self._handle, self.host, self.port,
                                                ssl=self.tls, limit=MAX_HEADER)
        except BaseException as exc:  # noqa: BLE001 - handed to start()
            self._error = exc
            self._ready.set()
            return
        self.port = server.sockets[0].getsockname()[1]
        self._ready.set()
        async with server:
            await self._stop.wait()

    def _run(self) -> None:
        asyncio.set_event_loop(self._loop)
        self._loop.run_until_complete(self._serve())

    def start(self) -> int:
        self._thread.start()
        self._ready.wait()
        if self._error is not None:
            raise self._error
        return self.port

    def stop(self) -> None:
        if self._stop is not None and self._thread.is_alive():
            self._loop.call_soon_threadsafe(self._stop.set)
            self._thread.join(5)


async def _pipe(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
    try:
        while data := await reader.read(65536):
            writer.write(data)
            await writer.drain()
    except (ConnectionError, OSError, ssl.SSLError):
        pass
    finally:
        writer.close()
