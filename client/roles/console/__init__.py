"""``rhbl console``: the teacher's console, a web page to see the robot, teach it and correct it.

A zenoh client like the other processes (the same ``--connect/--listen/--mode/--zenoh-config``
and ``--robot`` flags; behind the secured router it uses the teacher's credentials) that serves
one page and its WebSocket on ``--http HOST:PORT`` (default ``127.0.0.1:8080``) and prints one
line ``console: <URL>`` with the URL to open. The page (``client/roles/console/static/``: plain HTML,
JS and a canvas, no network access beyond this process) shows the world, the robot, its trail and
laser, who drives and with which action, the learner's tree and the controller's decision; the
person drives with the arrow keys/WASD, on-screen buttons or a gamepad. Commands go on the bus
exactly as ``rhbl teacher`` sends them (``client.player.PlayerClient``,
``client.labels.LabelPublisher``): the velocity on ``.../cmd/vel/teacher`` and the label for
the scan the page displayed on ``.../teacher/action``,
kept and resent until a learner acknowledges it (once a learner of the robot was seen).

    rhbl console                                   # http://127.0.0.1:8080/
    rhbl console --http 0.0.0.0:8443 --tls-cert c.pem --tls-key k.pem   # token in the URL
    rhbl console --view-only                       # watch: publishes nothing at all
    rhbl console --behaviour left-wall             # the page shows what to teach and its rule

docs/console.md describes the page; ``client.roles.console.app`` the server side (the
teaching session: ``client.roles.console.tutor``; who may open the page: ``client.access``).
"""

from __future__ import annotations

import argparse
import sys

from client.behaviour.given import behaviour_arg
from client.roles.common import add_process_arguments, run_role
from process import arguments

HEADER_TIMEOUT = arguments.Number(float, 0, 3600, low_open=True, name="seconds")
MAX_PAGES = arguments.Number(int, 1, 10_000, name="pages")

__all__ = ["add_arguments", "main"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_process_arguments(parser)
    for action in parser._actions:  # the console never waits for the server: its page does
        if action.dest == "wait_server":
            action.help = argparse.SUPPRESS
    parser.add_argument("--http", default="127.0.0.1:8080", metavar="HOST:PORT",
                        type=arguments.address,
                        help="where the page is served (default 127.0.0.1:8080; port 0 = any "
                             "free port). Any address but loopback requires an access token")
    parser.add_argument("--token", default=None, type=arguments.token,
                        help="access token the URL must carry (default: none on loopback, a "
                             "random one on any other address; printed in the URL): at least 16 "
                             "characters, 8 of them different. A token beginning with '-' is "
                             "given as --token=VALUE")
    parser.add_argument("--tls-cert", metavar="PEM", type=arguments.input_file,
                        help="serve HTTPS/WSS with this certificate")
    parser.add_argument("--tls-key", metavar="PEM", type=arguments.input_file,
                        help="the certificate's private key")
    parser.add_argument("--view-only", action="store_true",
                        help="watch only: no commands, no labels, no liveliness token")
    parser.add_argument("--max-pages", type=MAX_PAGES, default=32, metavar="N",
                        help="pages served at once (default 32); one more is refused with the "
                             "reason on the page (close code 1013)")
    parser.add_argument("--header-timeout", type=HEADER_TIMEOUT, default=10.0, metavar="SECONDS",
                        help="close a connection whose request headers have not all arrived "
                             "within this (or that is idle this long between requests; "
                             "default 10)")
    parser.add_argument("--behaviour", default=None, type=behaviour_arg, metavar="NAME|FILE",
                        help="the behaviour taught: the page shows its instructions and its "
                             "success rule (a shipped behaviour's name or a behaviour file; "
                             "default: the world's behaviour when one shipped behaviour is "
                             "the world's, else none)")


def main(args: argparse.Namespace) -> int:
    from client.access import check_strength
    from client.roles.console.app import body, parse_http

    # bad flags are said before any session is opened (exit status 2, like argparse)
    try:
        parse_http(args.http)
        if args.token:
            check_strength(args.token)
        if bool(args.tls_cert) != bool(args.tls_key):
            raise ValueError("--tls-cert and --tls-key go together")
    except ValueError as exc:
        print(f"rhbl console: error: {exc}", file=sys.stderr)
        return 2
    return run_role("console", args, body, early_token=False)
