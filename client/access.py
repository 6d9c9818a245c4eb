"""Who may open a page or a WebSocket this machine serves: the access rules the console
(``client.roles.console.app``) and the Foxglove bridge's gate (``client.recording.gate``)
share. Pure (no web framework): each check says why a request is refused, or nothing.

- Without a token (the default on a loopback address) a request must name a loopback host
  (``Host: 127.0.0.1:8080``, ``localhost``, ``[::1]``): a site whose name an attacker points
  at 127.0.0.1 (DNS rebinding) is refused.
- With a token (``--token``, or a random one on any other address, printed in the URL) the
  request's ``?token=`` must carry it (compared in constant time).
- A request with an ``Origin`` (a web page's script) is refused unless it is the server's own.
- A token a person gives must be strong (``check_strength``: at least ``MIN_TOKEN``
  characters, ``MIN_DIFFERENT`` of them different; a random one of ``access_token`` is 24); a
  wrong one costs its address a try (``Throttle``: ``BURST`` at once, then one a second), so a
  token cannot be guessed at the speed of the network.
"""

from __future__ import annotations

import hmac
import ipaddress
import secrets
import time
from collections import OrderedDict

__all__ = ["BURST", "MIN_DIFFERENT", "MIN_TOKEN", "Throttle", "access_token", "check_host",
           "check_origin", "check_strength", "check_token", "host_name", "is_loopback"]

MIN_TOKEN = 16  # characters of a token given by a person, at least
MIN_DIFFERENT = 8  # different characters in it, at least (not "aaaaaaaaaaaaaaaa")
BURST = 10  # wrong tokens an address may give at once; then one a second
RATE = 1.0  # wrong tokens an address may give per second, after the burst
ADDRESSES = 4096  # addresses the throttle remembers (the longest unseen forgotten first)


def is_loopback(host: str) -> bool:
    """``localhost`` or a loopback address (``127.0.0.1``, ``::1``)."""
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


def check_host(host: str | None) -> tuple[int, str] | None:
    """Without a token: (400, why) without a Host header, (403, why) for a Host that is no
    loopback name (DNS rebinding), else None."""
    if not host:
        return 400, "a Host header is required"
    if not is_loopback(host_name(host)):
        return 403, f"Host {host[:80]!r} refused: open it as http://127.0.0.1:<port>/"
    return None


def check_token(given: str, token: str) -> tuple[int, str] | None:
    """(401, why) when ``given`` (the request's ``?token=``) is not ``token``, else None."""
    if not hmac.compare_digest(given.encode(), token.encode()):
        return 401, "a valid ?token= is required (printed in the console's URL)"
    return None


def check_origin(origin: str | None, own: str) -> tuple[int, str] | None:
    """(403, why) for an ``Origin`` other than the server's own (``own``: ``scheme://host``);
    a request without one (not a web page's script) passes."""
    if origin is not None and origin != own:
        return 403, f"foreign origin {origin[:80]} refused"
    return None


def check_strength(token: str) -> None:
    """ValueError when ``token`` (given by a person: ``--token``) is weak: under ``MIN_TOKEN``
    characters or under ``MIN_DIFFERENT`` different ones. The message names the rule, not the
    token."""
    if len(token) < MIN_TOKEN or len(set(token)) < MIN_DIFFERENT:
        raise ValueError(
            f"--token is weak ({len(token)} characters, {len(set(token))} different): give at "
            f"least {MIN_TOKEN} characters, {MIN_DIFFERENT} of them different (e.g. the output "
            f"of `openssl rand -hex 16`), or none for a random one")


class Throttle:
    """Wrong tokens per client address: ``BURST`` at once, then ``RATE`` a second (a token
    bucket per address). ``wait(address)``: the seconds that address must wait before its
    next try is checked (0: now); ``failed(address)``: it gave a wrong token. At most
    ``ADDRESSES`` addresses are remembered."""

    def __init__(self, burst: int = BURST, rate: float = RATE, clock=time.monotonic):
        self.burst, self.rate, self._clock = float(burst), float(rate), clock
        self._tries: OrderedDict[str, tuple[float, float]] = OrderedDict()  # addr -> (left, at)
        self.throttled = 0  # requests refused for waiting

    def _left(self, address: str) -> float:
        left, at = self._tries.get(address, (self.burst, 0.0))
        return min(self.burst, left + (self._clock() - at) * self.rate)

    def wait(self, address: str) -> float:
        left = self._left(address)
        if left >= 1.0:
            return 0.0
        self.throttled += 1
        return (1.0 - left) / self.rate

    def failed(self, address: str) -> None:
        self._tries[address] = (self._left(address) - 1.0, self._clock())
        self._tries.move_to_end(address)
        while len(self._tries) > ADDRESSES:
            self._tries.popitem(last=False)
