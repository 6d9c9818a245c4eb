"""The console's HTTP edge: who may fetch what, and refusals that cost one log line.

- ``Refusals``: one log line per refused request (a wrong token, a foreign Host, an unknown
  path, a malformed request), at most ``burst`` lines per ``per`` seconds, then one line saying
  how many more were refused: a flood of bad requests never floods the log.
- ``ServerLog``: the logger given to aiohttp's request handler, so the requests aiohttp itself
  refuses (no Host header, a header line too long, not HTTP at all) are one line through
  ``Refusals`` instead of a traceback each.
- ``guard``: the middleware every request passes: its refusal said once, an exception of a
  handler a clean 500 of one line (never a traceback per request).
- ``Assets``: the page's files, a fixed list read once from the package (``static/``): a
  path outside the list is a 404 without touching the file system (a 5,000-character path is
  just an unknown name); ``page(token)``: the HTML with its assets' URLs carrying the token,
  so the page, its assets and its WebSocket all answer to the same access check.
- ``read_message``: a page's WebSocket message as a JSON object (nested at most ``MAX_DEPTH``
  levels; ``ValueError`` naming what was wrong); ``error_message``: the one the page is sent
  when something it asked for is refused.

The header timeout is aiohttp's keep-alive timeout (``--header-timeout``): a connection whose
request headers have not all arrived within it (or that sits idle that long between requests)
is closed.
"""

from __future__ import annotations

import json
import logging
import time
import urllib.parse
from pathlib import Path

from aiohttp import web

__all__ = ["HEADER_TIMEOUT", "MAX_DEPTH", "Assets", "Refusals", "ServerLog", "error_message",
           "guard", "read_message"]

HEADER_TIMEOUT = 10.0  # s for a request's headers to arrive (and for an idle connection)
MAX_DEPTH = 8  # levels of nesting in a page's message (they are flat objects)
_TYPES = {".js": "text/javascript", ".css": "text/css", ".html": "text/html"}


class Refusals:
    """Says each refused request in one line, at most ``burst`` lines per ``per`` seconds; the
    rest are counted and summed up in one line when the next window opens."""

    def __init__(self, log: logging.Logger, burst: int = 10, per: float = 10.0,
                 clock=time.monotonic):
        self.log, self.burst, self.per, self._clock = log, int(burst), float(per), clock
        self._window = -float("inf")
        self._said = 0
        self._quiet = 0
        self.total = 0

    def say(self, text: str) -> None:
        self.total += 1
        now = self._clock()
        if now - self._window >= self.per:
            if self._quiet:
                self.log.warning("%d more requests refused in %.0f s (not each said)",
                                 self._quiet, self.per)
            self._window, self._said, self._quiet = now, 0, 0
        if self._said < self.burst:
            self._said += 1
            self.log.warning("refused %s", _clip(text, 300))
        else:
            self._quiet += 1


def _clip(text: str, n: int) -> str:
    text = text.replace("\n", " ").replace("\r", " ")
    return text if len(text) <= n else f"{text[:n - 25]}... ({len(text)} characters)"


def describe(request: web.BaseRequest) -> str:
    """``GET /path from 127.0.0.1`` (the path clipped)."""
    try:
        what = f"{request.method} {_clip(request.rel_url.path, 80)}"
    except Exception:  # noqa: BLE001 - a request aiohttp could not parse
        what = "a request"
    return f"{what} from {request.remote or '?'}"


class ServerLog(logging.LoggerAdapter):
    """aiohttp's request handler logs a refused or failed request with a traceback; here each is
    one line (the exception's message) through ``Refusals``; debug lines go to the console's
    log at debug level."""

    def __init__(self, log: logging.Logger, refusals: Refusals):
        super().__init__(log, {})
        self.refusals = refusals

    def log(self, level, msg, *args, exc_info=None, **kw) -> None:  # noqa: A003
        if level <= logging.DEBUG:
            self.logger.log(level, msg, *args)  # without the traceback
            return
        exc = exc_info if isinstance(exc_info, BaseException) else None
        text = msg % args if args else str(msg)
        reason = str(getattr(exc, "message", "") or exc or "").strip()
        self.refusals.say(f"{text}: {reason}" if reason else text)


def guard(refusals: Refusals, log: logging.Logger):
    """The middleware: a refusal (any HTTP error a handler raises) said in one line; a handler
    that fails says one line and answers 500."""

    @web.middleware
    async def middleware(request: web.Request, handler):
        try:
            return await handler(request)
        except web.HTTPException as exc:
            if exc.status >= 400:
                refusals.say(f"{describe(request)}: {exc.status} {_clip(exc.text or '', 120)}")
            raise
        except Exception as exc:  # noqa: BLE001 - one line, never a traceback per request
            refusals.say(f"{describe(request)}: 500 {type(exc).__name__}: {exc}")
            log.debug("request failed", exc_info=exc)
            raise web.HTTPInternalServerError(text="rhbl console: internal error\n") from None

    return middleware


class Assets:
    """The page's files (``folder``), read once: ``page(token)`` the HTML, ``get(name)`` an
    asset's bytes and type, or None for a name not in the list."""

    def __init__(self, folder: Path, page: str = "index.html"):
        self._files: dict[str, tuple[bytes, str]] = {}
        for path in sorted(folder.iterdir()):
            if path.is_file() and path.suffix in _TYPES and path.name != page:
                self._files[path.name] = (path.read_bytes(), _TYPES[path.suffix])
        self._page = (folder / page).read_text(encoding="utf-8")

    def names(self) -> list[str]:
        return list(self._files)

    def get(self, name: str) -> tuple[bytes, str] | None:
        return self._files.get(name)

    def page(self, token: str | None) -> str:
        """The HTML; with a token, every asset URL (``static/NAME``) carries it."""
        if not token:
            return self._page
        q = urllib.parse.quote(token, safe="")
        html = self._page
        for name in self._files:
            html = html.replace(f'"static/{name}"', f'"static/{name}?token={q}"')
        return html


def read_message(raw: str) -> dict:
    """A page's message: a JSON object nested at most ``MAX_DEPTH`` levels (ValueError
    naming what is wrong; a message nested thousands of levels deep is refused before the
    parser recurses)."""
    depth = deepest = 0
    quoted = escaped = False
    for ch in raw:  # brackets outside strings
        if quoted:
            if escaped:
                escaped = False
            elif ch == "\\":
                escaped = True
            elif ch == '"':
                quoted = False
        elif ch == '"':
            quoted = True
        elif ch in "[{":
            depth += 1
            deepest = max(deepest, depth)
            if deepest > MAX_DEPTH:
                raise ValueError(f"nested more than {MAX_DEPTH} levels deep")
        elif ch in "]}":
            depth -= 1
    msg = json.loads(raw)
    if not isinstance(msg, dict):
        raise ValueError("expected a JSON object")
    return msg


def error_message(text: str) -> str:
    """The JSON text of an ``error`` message to a page: ``{"t": "error", "error": text}``."""
    return json.dumps({"t": "error", "error": text})
