"""The gate of ``servodesk serve``: who may open the page and a session, and how many at once.

As jupyter_server guards its server (``check_host``, ``check_origin`` and its token, in
``jupyter_server/base/handlers.py``), every request is checked before textual-serve sees it:

- **Host**: the header names this machine as serve listens on it (``localhost``, a loopback
  address, ``--host``). A foreign site whose name its owner points at 127.0.0.1 (DNS
  rebinding) sends its own name, and is refused.
- **Token**: the page needs serve's token (``/?token=…``, printed at start, new each start),
  compared in constant time; the page gives its websocket the token in the path
  (``/ws/TOKEN``: textual.js appends ``?width=…`` to the URL it is given).
- **Origin**: a websocket must come from serve's own page: its Origin is the scheme, host and
  port the browser reached (the Host header, as an SSH forward may change the port). A script
  on another site's page sends that site's Origin; a client that sends none is refused too.
- **Sessions**: at most ``max_sessions`` at once, each a TUI process (about 85 MB) competing
  for the CPU with the controller service; a closed session frees its slot.

Each refusal is answered before a session's process starts: 403 with the reason in one line,
503 when every session is in use.
"""

from __future__ import annotations

import asyncio
import hmac
import ipaddress
import logging
import secrets
import socket
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NoReturn
from urllib.parse import urlsplit

import aiohttp_jinja2
from aiohttp import hdrs, web
from textual_serve.server import Server, to_int

log = logging.getLogger("servodesk.serve")

WILDCARDS = frozenset({"", "0.0.0.0", "::"})  # --host values that listen on every address


def url_host(host: str) -> str:
    """``host`` as it stands in a URL: an IPv6 address in brackets."""
    return f"[{host}]" if ":" in host else host


@dataclass(frozen=True)
class Gate:
    """What a request must show: a Host among ``names`` (any IP address of this machine too,
    if serve listens on all of them: ``any_address``), the ``token``, and for a websocket an
    Origin that is the Host it reached."""

    names: frozenset[str]
    any_address: bool = False
    token: str = field(default_factory=lambda: secrets.token_urlsafe(32), repr=False)

    @classmethod
    def listening_on(cls, host: str) -> Gate:
        """The gate of a server listening on ``host`` (``--host``), with a new token."""
        names = {"localhost", host.lower()}
        if host in WILDCARDS:
            names |= {socket.gethostname().lower(), socket.getfqdn().lower()}
        return cls(frozenset(names - {""}), any_address=host in WILDCARDS)

    def page_url(self, host: str, port: int) -> str:
        """The address to open: serve's page with the token."""
        shown = "127.0.0.1" if host in WILDCARDS else url_host(host)
        return f"http://{shown}:{port}/?token={self.token}"

    def host_problem(self, host: str | None) -> str:
        """Why a request with this Host header is refused; "" if it names this machine."""
        if not host:
            return "no Host header: open the address servodesk serve printed at start"
        name = _host_name(host)
        if name in self.names or _this_machine(name, self.any_address):
            return ""
        return (f"Host {host!r} is not a name of this server (a foreign name pointed here is "
                "refused): open the address servodesk serve printed at start")

    def origin_problem(self, origin: str | None, host: str) -> str:
        """Why a websocket from ``origin`` to ``host`` is refused; "" if it is serve's page."""
        if not origin:
            return ("a session's websocket must come from servodesk serve's page, and this one "
                    "names no Origin: open the address serve printed at start")
        parts = urlsplit(origin.lower())
        if parts.scheme in ("http", "https") and parts.netloc == host.lower():
            return ""
        return (f"a session's websocket from the page of {origin} is refused: only servodesk "
                f"serve's own page (at {host}) opens sessions")

    def token_problem(self, given: str | None) -> str:
        """Why a request with the token ``given`` is refused; "" if it is serve's."""
        if not given:
            return ("this page needs servodesk serve's token: open the address it printed at "
                    "start (http://…/?token=…)")
        if not hmac.compare_digest(given.encode(), self.token.encode()):
            return ("wrong token: open the address servodesk serve printed at start (the token "
                    "is new each time serve starts)")
        return ""


def _host_name(host: str) -> str:
    """The name in a Host header, lower case; "" where it is no name[:port]."""
    try:
        parts = urlsplit(f"//{host}")
        _ = parts.port  # raises for a port that is no number
    except ValueError:
        return ""
    return parts.hostname or ""


def _this_machine(name: str, any_address: bool) -> bool:
    """``name`` is an IP address serve answers on: a loopback one, or any when it listens on
    all (an address cannot be re-pointed as a name can)."""
    try:
        address = ipaddress.ip_address(name)
    except ValueError:
        return False
    return address.is_loopback or any_address


class GatedServer(Server):
    """textual-serve's ``Server`` behind the ``Gate``, with at most ``max_sessions`` sessions."""

    def __init__(self, command: str, *, host: str, port: int, title: str,
                 templates_path: Path, gate: Gate, max_sessions: int) -> None:
        super().__init__(command, host=host, port=port, title=title,
                         templates_path=templates_path)
        self.gate = gate
        self.max_sessions = max_sessions
        self.sessions = 0  # open now; counted on the event loop's one thread
        self._handlers: set[asyncio.Task[Any]] = set()  # the open sessions' websocket handlers
        self.ended = 0  # sessions still open when serve stopped, ended by it

    async def _make_app(self) -> web.Application:
        app = await super()._make_app()
        app.router.add_get("/ws/{token}", self.handle_websocket, name="session")
        app.middlewares.append(self._check_host)  # every route: the page, static files, /ws
        return app

    async def on_startup(self, app: web.Application) -> None:
        """Nothing: serve prints its address, with the token, itself."""

    async def on_shutdown(self, app: web.Application) -> None:
        """End every session now: its TUI is told to quit and its websocket closes. Left open,
        aiohttp waits for the browser to go (23 s with one session open)."""
        self.ended = len(self._handlers)
        for handler in self._handlers:
            handler.cancel()
        await asyncio.gather(*self._handlers, return_exceptions=True)

    def initialize_logging(self) -> None:
        super().initialize_logging()
        logging.getLogger("aiohttp.access").addFilter(_Scrub(self.gate.token))

    @web.middleware
    async def _check_host(self, request: web.Request, handler: Any) -> web.StreamResponse:
        if problem := self.gate.host_problem(request.headers.get(hdrs.HOST)):
            _refuse(request, problem)
        return await handler(request)

    async def handle_index(self, request: web.Request) -> web.Response:
        if problem := self.gate.token_problem(request.query.get("token")):
            _refuse(request, problem)
        self._check_room(request)
        return aiohttp_jinja2.render_template("app_index.html", request, {
            "font_size": to_int(request.query.get("fontsize", "16"), 16),
            "application": {"name": self.title},
            "websocket_path": f"/ws/{self.gate.token}",
        })

    async def handle_websocket(self, request: web.Request) -> web.WebSocketResponse:
        if problem := (self.gate.origin_problem(request.headers.get(hdrs.ORIGIN),
                                                request.headers[hdrs.HOST])
                       or self.gate.token_problem(request.match_info.get("token"))):
            _refuse(request, problem)
        self._check_room(request)
        self.sessions += 1
        handler = asyncio.current_task()
        assert handler is not None  # aiohttp runs each request as a task
        self._handlers.add(handler)
        try:
            return await super().handle_websocket(request)  # until its TUI has ended
        finally:
            self._handlers.discard(handler)
            self.sessions -= 1

    def _check_room(self, request: web.Request) -> None:
        if self.sessions >= self.max_sessions:
            _refuse(request, f"all {self.max_sessions} sessions are in use (--max-sessions "
                             f"{self.max_sessions}): close a browser tab of servodesk serve, or "
                             "restart serve with a larger --max-sessions",
                    web.HTTPServiceUnavailable)


class _Scrub(logging.Filter):
    """Keeps the token out of the access log (the page's and the websocket's URLs carry it),
    as jupyter_server scrubs its own."""

    def __init__(self, token: str) -> None:
        super().__init__()
        self.token = token

    def filter(self, record: logging.LogRecord) -> bool:
        record.msg = str(record.msg).replace(self.token, "…")
        return True


def _refuse(request: web.Request, problem: str,
            answer: type[web.HTTPError] = web.HTTPForbidden) -> NoReturn:
    """Answer ``problem`` in one line (403 unless told); logged on serve's stderr, the path
    without its token."""
    path = "/ws/…" if request.path.startswith("/ws/") else request.path
    log.warning("refused %s %s: %s", request.method, path, problem)
    raise answer(text=f"servodesk serve: {problem}\n")
