"""``servodesk serve`` in a real headless Chromium (Debian's chromium and chromium-driver,
driven by selenium), and what the browser received, as text.

The page draws the terminal on a canvas (xterm.js), so the screen's text is in no DOM node.
What the browser received is: a wrapper around ``window.WebSocket``, injected before the
page loads (CDP ``Page.addScriptToEvaluateOnNewDocument``), keeps every binary message (the
TUI's output bytes); ``Browser.text`` decodes them and strips the escape sequences. Used by
tests/app/test_serve.py and ``benchmarks/ui.py --browser``.

``ScriptedSessions`` opens sessions without a browser, as the page does (aiohttp, which
textual-serve depends on): many at once, or with a foreign Origin or a wrong token.
"""

from __future__ import annotations

import asyncio
import base64
import codecs
import contextlib
import os
import re
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request
from collections.abc import Callable, Coroutine, Iterator
from pathlib import Path
from typing import Any, TypeVar

import aiohttp
from selenium import webdriver
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.by import By
from selenium.webdriver.common.keys import Keys

ROOT = Path(__file__).resolve().parents[2]
CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"
WINDOW = (1600, 1000)  # about 166 × 50 cells at the page's 16 px font
START_S = 60.0
T = TypeVar("T")

# Every binary message the page's websockets receive, base64 (the TUI's output bytes).
RECORDER = """
(() => {
  const Native = window.WebSocket;
  const received = (window.__servodeskReceived = []);
  window.WebSocket = class extends Native {
    constructor(...args) {
      super(...args);
      this.addEventListener("message", (event) => {
        if (!(event.data instanceof ArrayBuffer)) return;
        const bytes = new Uint8Array(event.data);
        let text = "";
        for (let i = 0; i < bytes.length; i += 0x8000) {
          text += String.fromCharCode.apply(null, bytes.subarray(i, i + 0x8000));
        }
        received.push(btoa(text));
      });
    }
  };
})();
"""
TAKE = "return window.__servodeskReceived ? window.__servodeskReceived.splice(0) : [];"
# a cursor move starts another place on the screen: a line break in the text; every other
# escape sequence (colours, modes, OSC) goes
CURSOR_MOVE = re.compile(r"\x1b\[[0-9;]*[Hf]")
ESCAPE = re.compile(r"\x1b\[[0-?]*[ -/]*[@-~]|\x1b\][^\x07\x1b]*(?:\x07|\x1b\\)|\x1b[@-Z\\-_]")
PAGE_URL = re.compile(r"servodesk serve: (http://127\.0\.0\.1:\d+/\?token=([\w-]+))")
SAME = "the page's"  # ScriptedSessions.open's Origin: serve's own page's


def screen_text(raw: str) -> str:
    """What a terminal's output bytes (decoded) show, as text."""
    return ESCAPE.sub("", CURSOR_MOVE.sub("\n", raw))


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


class Served:
    """``servodesk serve`` on a free port, in a private runtime directory (its controller's
    socket there); its output in ``log``; ``url``, the page's address with the token it
    printed."""

    def __init__(self, log: Path, *args: str, runtime: Path | None = None) -> None:
        self.port = free_port()
        self.origin = f"http://127.0.0.1:{self.port}"  # its own page's
        self.url = self.token = ""  # once serve has printed them
        self._own_runtime = runtime is None
        self.runtime = runtime or Path(tempfile.mkdtemp(prefix="sd-"))
        self.socket = self.runtime / "servodesk" / "controller.sock"
        self.log = log
        env = {**os.environ, "PYTHONPATH": str(ROOT), "XDG_RUNTIME_DIR": str(self.runtime)}
        with log.open("wb") as out:
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "app", "serve", "--http-port", str(self.port), *args],
                cwd=ROOT, env=env, stdin=subprocess.DEVNULL, stdout=out, stderr=out)
        wait_until(self._answers, START_S, f"servodesk serve at {self.url}", self._failed)

    def _answers(self) -> bool:
        if not self.token:
            if (printed := PAGE_URL.search(self.log.read_text(errors="replace"))) is None:
                return False
            self.url, self.token = printed.groups()
        try:
            with urllib.request.urlopen(self.url, timeout=2) as response:
                return response.status == 200
        except OSError:
            return False

    def websocket_url(self, token: str | None = None) -> str:
        """A session's websocket, as the page asks for it (``token``: serve's unless told; ""
        is textual-serve's own path, without one)."""
        token = self.token if token is None else token
        path = f"/ws/{token}" if token else "/ws"
        return f"ws://127.0.0.1:{self.port}{path}?width=120&height=40"

    def _failed(self) -> str:
        if self.proc.poll() is not None:
            return f"servodesk serve exited {self.proc.returncode}: {self.log.read_text()}"
        return ""

    def stop(self) -> int:
        """SIGTERM, as Ctrl+C; its exit code."""
        self.proc.terminate()
        try:
            return self.proc.wait(timeout=60)
        finally:
            self.kill()

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(timeout=30)
        if self._own_runtime:
            shutil.rmtree(self.runtime, ignore_errors=True)


class Browser:
    """Headless Chromium on a page of ``servodesk serve``."""

    def __init__(self) -> None:
        options = webdriver.ChromeOptions()
        options.binary_location = CHROMIUM
        for argument in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
                         "--disable-gpu", f"--window-size={WINDOW[0]},{WINDOW[1]}"):
            options.add_argument(argument)
        self.driver = webdriver.Chrome(options=options, service=Service(CHROMEDRIVER))
        self.driver.execute_cdp_cmd("Page.addScriptToEvaluateOnNewDocument",
                                    {"source": RECORDER})
        self._decoder = codecs.getincrementaldecoder("utf-8")("replace")
        self._raw = ""
        self.received = ""  # everything received so far, as text

    def open(self, url: str) -> None:
        self.driver.get(url)

    def text(self) -> str:
        """All the text received so far (what arrived since the last call added)."""
        for chunk in self.driver.execute_script(TAKE):
            self._raw += self._decoder.decode(base64.b64decode(chunk))
        self.received = screen_text(self._raw)
        return self.received

    def mark(self) -> int:
        """Where the text received so far ends: ``wait_for(..., after=mark)``."""
        return len(self.text())

    def wait_for(self, needle: str | re.Pattern[str], timeout_s: float = 30.0,
                 after: int = 0) -> re.Match[str] | str:
        """Wait until ``needle`` (a string or regex) is in the text received after ``after``;
        the match."""
        found: list[re.Match[str] | str] = []

        def seen() -> bool:
            text = self.text()[after:]
            if isinstance(needle, str):
                if needle in text:
                    found.append(needle)
            elif (match := needle.search(text)) is not None:
                found.append(match)
            return bool(found)

        wait_until(seen, timeout_s, f"{needle!r} in the browser")
        return found[0]

    def _focus_terminal(self) -> None:
        """Focus xterm's input by script: moving the pointer to it (``send_keys_to_element``)
        fails, "move target out of bounds", when xterm has put it at a cursor off the page."""
        terminal = self.driver.find_element(By.CSS_SELECTOR, ".xterm-helper-textarea")
        self.driver.execute_script("arguments[0].focus();", terminal)

    def press(self, *keys: str) -> None:
        """Type ``keys`` (selenium ``Keys`` or text) into the terminal."""
        self._focus_terminal()
        ActionChains(self.driver).send_keys(*keys).perform()

    def press_ctrl(self, key: str) -> None:
        """Ctrl and ``key`` together."""
        self._focus_terminal()
        ActionChains(self.driver).key_down(Keys.CONTROL).send_keys(key).key_up(Keys.CONTROL
                                                                              ).perform()

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.driver.quit()


class Session:
    """A session a script opened: what its TUI sent, as text."""

    def __init__(self, websocket: aiohttp.ClientWebSocketResponse) -> None:
        self.websocket = websocket
        self._chunks: list[bytes] = []  # appended on the sessions' event loop

    async def receive(self) -> None:
        async for message in self.websocket:
            if message.type == aiohttp.WSMsgType.BINARY:
                self._chunks.append(message.data)

    def text(self) -> str:
        return screen_text(b"".join(self._chunks[:]).decode(errors="replace"))

    def wait_for(self, needle: str, timeout_s: float) -> None:
        wait_until(lambda: needle in self.text(), timeout_s, f"{needle!r} in a scripted session")


class ScriptedSessions:
    """Sessions of ``servodesk serve`` opened by a script as its page opens them (aiohttp: a
    websocket with the page's Origin and the token in its path), on an event loop in a thread
    of their own; ``close`` ends them all."""

    def __init__(self, served: Served) -> None:
        self.served = served
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, daemon=True)
        self._thread.start()
        self._http: aiohttp.ClientSession = self._run(self._client())
        self._open: dict[Session, asyncio.Task[None]] = {}

    @staticmethod
    async def _client() -> aiohttp.ClientSession:
        return aiohttp.ClientSession()

    def _run(self, coroutine: Coroutine[Any, Any, T]) -> T:
        return asyncio.run_coroutine_threadsafe(coroutine, self._loop).result(START_S)

    def open(self, count: int = 1, origin: str | None = SAME, token: str | None = None
             ) -> list[Session | int]:
        """``count`` sessions asked for at once, with ``origin`` (None: no Origin header) and
        ``token`` (serve's unless told): each a ``Session``, or the HTTP status it was refused
        with."""
        sent = self.served.origin if origin == SAME else origin
        url = self.served.websocket_url(token)

        async def one() -> Session | int:
            try:
                websocket = await self._http.ws_connect(url, origin=sent)
            except aiohttp.WSServerHandshakeError as refused:
                return refused.status
            session = Session(websocket)
            self._open[session] = asyncio.get_running_loop().create_task(session.receive())
            return session

        async def all_at_once() -> list[Session | int]:
            return list(await asyncio.gather(*(one() for _ in range(count))))

        return self._run(all_at_once())

    def close_session(self, session: Session) -> None:
        """Close ``session``'s websocket, as a closed browser tab does."""
        receiving = self._open.pop(session)

        async def close() -> None:
            await session.websocket.close()
            await receiving

        self._run(close())

    def close(self) -> None:
        for session in list(self._open):
            self.close_session(session)
        self._run(self._http.close())
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(timeout=START_S)
        self._loop.close()


@contextlib.contextmanager
def scripted(served: Served) -> Iterator[ScriptedSessions]:
    sessions = ScriptedSessions(served)
    try:
        yield sessions
    finally:
        sessions.close()


@contextlib.contextmanager
def browser() -> Iterator[Browser]:
    opened = Browser()
    try:
        yield opened
    finally:
        opened.close()


def wait_until(condition: Callable[[], bool], timeout_s: float, what: str,
               failed: Callable[[], str] = lambda: "") -> None:
    """Poll ``condition`` until it holds; TimeoutError naming ``what`` (or ``failed()``'s
    reason, at once, when it gives one)."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        if reason := failed():
            raise RuntimeError(reason)
        if time.monotonic() > deadline:
            raise TimeoutError(f"{what}: not within {timeout_s:g} s")
        time.sleep(0.05)
