"""Who may open a page or a WebSocket this machine serves: the access rules the console
(``client.roles.console.app``) and the Foxglove bridge's gate (``client.recording.gate``)
share. Pure (no web framework): each check says why a request is refused, or nothing.

- Without a token (the default on a loopback address) a request must name a loopback host
  (``Host: 127.0.0.1:8080``, ``localhost``, ``[::1]``): a site whose name an attacker points
  at 127.0.0.1 (DNS rebinding) is refused.
- With a token (``--token``, or a random one on any other address, printed in the URL) the
  request's ``?token=`` must carry it (compared in constant time).
- A request with an ``Origin`` (a web page's script) is refused unless it is the server's own.
"""

from __future__ import annotations

import hmac
import ipaddress
import secrets

__all__ = ["access_token", "check_host", "check_origin", "check_token", "host_name",
           "is_loopback"]


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
