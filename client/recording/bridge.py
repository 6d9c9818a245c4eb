"""``rhbl foxglove``: serve the live bus to Foxglove or Lichtblick over the Foxglove WebSocket
protocol (``foxglove-sdk``'s server), on localhost.

    rhbl foxglove --connect tcp/127.0.0.1:7447           # then open ws://127.0.0.1:8765

It taps the bus like ``rhbl record`` (``client.recording.tap.BusTap``: every robot seen, or
``--robot``) and converts with ``client.recording.foxglove_schemas`` (the same viewer channels a
recording holds):
``/world`` (walls, goal, robots), ``/tf``, ``/<robot>/laser``, ``/<robot>/pose``,
``/<robot>/path``, ``/<robot>/status`` (who drives, the tree's size). The world scene is sent
again every few seconds, so a viewer that connects late draws the walls too.

Who may connect follows the console's rules (``client.recording.gate``: the SDK's server has no
hook for them, so a gate in front of it decides): loopback names only without a token, a token
(``--token``, or a random one printed in the URL) and TLS on any other address, a web page's
``Origin`` refused unless allowed with ``--allow-origin``.
"""

from __future__ import annotations

import argparse
import logging
import os
import ssl
import threading
import time

from client.access import check_strength
from client.recording import gate
from client.recording.foxglove_schemas import ViewerFeed, ViewerMessage
from client.recording.mcap_file import KINDS, classify
from client.recording.tap import BusTap
from process import arguments
from process.runtime import EXIT_USAGE, Context, ProcessError, add_report_arguments, run_process
from process.session import add_zenoh_arguments
from protocol.decoding import Decoder

__all__ = ["FoxgloveSink", "add_arguments", "main"]

log = logging.getLogger(__name__)

WORLD_REPEAT = 3.0  # s between repeats of the world scene
DRAWN = ("scan", "fiducial", "state", "driver", "notice", "world")  # kinds the viewer channels show


class FoxgloveSink:
    """A ``BusTap`` sink that logs the viewer messages on foxglove-sdk channels (whatever
    sinks their context has: a WebSocket server, an MCAP file)."""

    def __init__(self, context=None):
        self.context = context
        self.feed = ViewerFeed()
        self.channels: dict[str, object] = {}
        self.messages = 0
        self.counts: dict[str, int] = {}
        self._world: dict[str, ViewerMessage] = {}  # robot -> its latest /world scene
        self._world_at = 0.0
        self._lock = threading.Lock()
        self.decoder = Decoder(log, level=logging.DEBUG)  # a malformed message draws nothing

    def _channel(self, vm: ViewerMessage):
        import foxglove

        ch = self.channels.get(vm.topic)
        if ch is None:
            ch = self.channels[vm.topic] = foxglove.Channel(
                vm.topic, message_encoding=vm.encoding, context=self.context,
                schema=foxglove.Schema(name=vm.schema_name, encoding=vm.schema_encoding,
                                       data=vm.schema_data))
        return ch

    def _log(self, vm: ViewerMessage) -> None:
        self._channel(vm).log(vm.data, log_time=vm.time_ns)
        self.counts[vm.topic] = self.counts.get(vm.topic, 0) + 1

    def write(self, key: str, data: bytes, recv_ns: int, kind: str | None = None,
              robot: str | None = None, sim_time: float | None = None) -> None:
        if kind is None:
            kind, robot = classify(key)
        if kind not in DRAWN:
            return
        msg = self.decoder.decode(KINDS[kind], data, where=key)
        if msg is None:
            return
        with self._lock:
            for vm in self.feed.update(kind, robot, msg, recv_ns):
                if kind == "world" and vm.topic == "/world":
                    self._world[robot] = vm
                self._log(vm)
            self.messages += 1
        self.maybe_flush()

    def write_alive(self, key: str, alive: bool, recv_ns: int) -> None:
        pass

    def maybe_flush(self, now: float | None = None) -> None:
        """Repeat the world scenes every few seconds (late viewers)."""
        now = time.monotonic() if now is None else now
        if self._world and now - self._world_at >= WORLD_REPEAT:
            self._world_at = now
            with self._lock:
                for vm in self._world.values():
                    self._log(ViewerMessage(vm.topic, vm.schema_name, vm.schema_encoding,
                                            vm.schema_data, vm.encoding, vm.data,
                                            time.time_ns()))

    def close(self) -> None:
        pass


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_zenoh_arguments(parser)
    parser.add_argument("--robot", action="append", dest="robots", metavar="NAME",
                        type=arguments.key_chunk,
                        help="show this robot (repeatable; default: every robot seen)")
    parser.add_argument("--host", default="127.0.0.1", type=arguments.host,
                        help="address the WebSocket server binds (default 127.0.0.1: this "
                             "machine only)")
    parser.add_argument("--port", type=arguments.port, default=8765,
                        help="WebSocket port (default 8765, Foxglove's default; 0 = any free)")
    parser.add_argument("--duration", type=arguments.seconds, default=None, metavar="SECONDS",
                        help="stop after this many seconds (default: until stopped)")
    parser.add_argument("--token", default=None, type=arguments.token,
                        help="access token the WebSocket URL must carry (?token=...; default: "
                             "none on loopback, a random one on any other address; printed in "
                             "the URL). A token beginning with '-' is given as --token=VALUE")
    parser.add_argument("--tls-cert", metavar="PEM", type=arguments.input_file,
                        help="serve WSS with this certificate (required on an address other "
                             "than loopback)")
    parser.add_argument("--tls-key", metavar="PEM", type=arguments.input_file,
                        help="the certificate's private key")
    parser.add_argument("--allow-origin", action="append", default=[], type=gate.origin,
                        metavar="ORIGIN",
                        help="a web app allowed to connect, by its origin (repeatable; e.g. "
                             "https://app.foxglove.dev for Foxglove's web app, or the address "
                             "Lichtblick is served from). A page of any other origin is "
                             "refused; apps that send none (the desktop apps) are not asked")
    add_report_arguments(parser)


def check(args: argparse.Namespace) -> ssl.SSLContext | None:
    """The options together (ValueError: exit 2, before any connection); the TLS context."""
    if bool(args.tls_cert) != bool(args.tls_key):
        raise ValueError("--tls-cert and --tls-key go together")
    if args.token:
        check_strength(args.token)  # the console's rule: a weak token is refused
    if not gate.is_loopback(args.host) and not args.tls_cert:
        raise ValueError(f"--host {args.host} is not a loopback address: give --tls-cert and "
                         f"--tls-key (the token and the live data would travel in clear "
                         f"text), or serve 127.0.0.1 and use an SSH tunnel")
    if not args.tls_cert:
        return None
    tls = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    try:
        tls.load_cert_chain(args.tls_cert, args.tls_key)
    except (OSError, ssl.SSLError) as exc:
        raise ValueError(f"--tls-cert/--tls-key: cannot load them: {exc}") from None
    return tls


def main(args: argparse.Namespace) -> int:
    name = "all" if not args.robots else args.robots[0]  # in its liveliness token
    tls: list[ssl.SSLContext | None] = []
    return run_process("foxglove", args, lambda ctx: BridgeProcess(ctx, tls[0]).run(),
                       ident=f"{name}-{os.getpid()}", check=lambda: tls.append(check(args)))


class BridgeProcess:
    """A foxglove-sdk WebSocket server fed by the bus tap through a ``FoxgloveSink``."""

    def __init__(self, ctx: Context, tls: ssl.SSLContext | None = None):
        import foxglove

        self.args = args = ctx.args
        context = foxglove.Context()
        # the SDK's server on a free loopback port, reached only through the gate
        self.server = foxglove.start_server(name="rhbl", host="127.0.0.1", port=0,
                                            context=context)
        ctx.scope.callback(self.server.stop)
        self.token = gate.access_token(args.host, args.token)
        self.tls = tls
        self.gate = gate.Gate(args.host, args.port, self.server.port, self.token,
                              args.allow_origin, tls)
        try:
            self.port = self.gate.start()
        except OSError as exc:  # the port is taken, ...
            raise ProcessError(f"foxglove: cannot serve on {args.host}:{args.port}: "
                               f"{exc.strerror or exc}", EXIT_USAGE) from exc
        ctx.scope.callback(self.gate.stop)
        self.sink = FoxgloveSink(context)
        self.tap = BusTap(ctx.session, self.sink, robots=args.robots)
        self.closed = False
        ctx.scope.callback(self.close)  # on every path, after "stopping (signal)"
        ctx.report(self.counters)

    def run(self) -> int:
        # the line tests and people wait for
        host = f"[{self.args.host}]" if ":" in self.args.host else self.args.host
        url = (f"{'wss' if self.tls else 'ws'}://{host}:{self.port}"
               f"{'/?token=' + self.token if self.token else ''}")
        log.info("Foxglove WebSocket server listening on %s (open it in Foxglove or "
                 "Lichtblick: Open connection -> Foxglove WebSocket)", url)
        t0 = time.monotonic()
        while self.args.duration is None or time.monotonic() - t0 < self.args.duration:
            time.sleep(0.1)
        return 0

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self.tap.close()
            self.gate.stop()
            self.server.stop()
            log.info("foxglove bridge stopped: %d bus messages shown on %d topics",
                     self.sink.messages, len(self.sink.channels))

    def counters(self) -> dict:
        return {"messages": self.sink.messages, "topics": len(self.sink.channels),
                "dropped": dict(self.sink.decoder.counts), "connections": self.gate.allowed,
                "refused": self.gate.refused, "throttled": self.gate.throttle.throttled}
