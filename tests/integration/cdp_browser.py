"""Headless Chromium driven over the Chrome DevTools Protocol, for the web view's tests.

:class:`HeadlessChromium` starts ``chromium`` with WebGL on SwiftShader (no GPU needed) and a
DevTools port of its own choosing (``--remote-debugging-port=0``: the port is read from the
"DevTools listening on ws://..." line it prints), opens one page target and talks to it over one
WebSocket (the ``websockets`` sync client) with flattened sessions. Every event is kept, so a test
can read what the page logged: :meth:`HeadlessChromium.console_errors` gathers console errors
(``Runtime.consoleAPICalled`` of type error or assert), uncaught exceptions
(``Runtime.exceptionThrown``) and browser log errors (``Log.entryAdded`` of level error: failed
requests, a missing favicon, WebGL errors).
"""

from __future__ import annotations

import base64
import contextlib
import json
import re
import shutil
import subprocess
import tempfile
import threading
import time
from typing import Any

CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--enable-unsafe-swiftshader", "--use-angle=swiftshader",
                  "--no-first-run", "--no-default-browser-check", "--disable-extensions",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--mute-audio", "--hide-scrollbars")


def find_chromium() -> str | None:
    """The path of an installed Chromium (or Chrome), or None."""
    for name in CHROMIUM_NAMES:
        path = shutil.which(name)
        if path:
            return path
    return None


class CdpError(RuntimeError):
    """A DevTools command failed, or the browser did not answer in time."""


class HeadlessChromium:
    """One headless browser with one page; use as a context manager (the browser is killed on exit)."""

    def __init__(self, width: int = 1280, height: int = 800, start_timeout_s: float = 30.0) -> None:
        exe = find_chromium()
        if exe is None:
            raise CdpError("chromium is not installed")
        self._profile = tempfile.mkdtemp(prefix="unetyemu-chromium-")
        self.proc = subprocess.Popen([exe, *CHROMIUM_FLAGS, f"--window-size={width},{height}",
                                      f"--user-data-dir={self._profile}", "--remote-debugging-port=0", "about:blank"],
                                     stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        self.stderr_lines: list[str] = []
        url = self._devtools_url(start_timeout_s)
        from websockets.sync.client import connect

        self._stack = contextlib.ExitStack()
        self._ws = self._stack.enter_context(connect(url, max_size=None, open_timeout=start_timeout_s))
        self._next_id = 0
        self.events: list[dict[str, Any]] = []
        target = self.call("Target.createTarget", {"url": "about:blank"})["targetId"]
        self.session = self.call("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        for domain in ("Runtime", "Log", "Page"):
            self.call(f"{domain}.enable", session=True)

    def _devtools_url(self, timeout_s: float) -> str:
        found: list[str] = []
        done = threading.Event()

        def read() -> None:
            assert self.proc.stderr is not None
            for raw in self.proc.stderr:
                line = raw.decode(errors="replace").rstrip()
                self.stderr_lines.append(line)
                m = re.search(r"DevTools listening on (ws://\S+)", line)
                if m and not found:
                    found.append(m.group(1))
                    done.set()
            done.set()

        threading.Thread(target=read, name="chromium-stderr", daemon=True).start()
        if not done.wait(timeout_s) or not found:
            self.close()
            raise CdpError("chromium did not print its DevTools address:\n" + "\n".join(self.stderr_lines[-20:]))
        return found[0]

    # -- the protocol ------------------------------------------------------------------------------
    def call(self, method: str, params: dict[str, Any] | None = None, session: bool = False,
             timeout_s: float = 30.0) -> dict[str, Any]:
        """Send a command, keep the events that arrive meanwhile, return its result."""
        self._next_id += 1
        msg: dict[str, Any] = {"id": self._next_id, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = self.session
        self._ws.send(json.dumps(msg))
        deadline = time.monotonic() + timeout_s
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise CdpError(f"{method}: no answer within {timeout_s:g} s")
            reply = json.loads(self._ws.recv(timeout=left))
            if reply.get("id") == self._next_id:
                if "error" in reply:
                    raise CdpError(f"{method}: {reply['error']}")
                return reply.get("result", {})
            if "method" in reply:
                self.events.append(reply)

    def evaluate(self, expression: str) -> Any:
        """The value of a JavaScript expression in the page (JSON-serialisable values)."""
        result = self.call("Runtime.evaluate", {"expression": expression, "returnByValue": True, "awaitPromise": True},
                           session=True)
        if "exceptionDetails" in result:
            raise CdpError(f"{expression}: {result['exceptionDetails']}")
        return result["result"].get("value")

    def navigate(self, url: str) -> None:
        self.call("Page.navigate", {"url": url}, session=True)

    def wait_for(self, expression: str, timeout_s: float, poll_s: float = 0.2) -> Any:
        """Poll a JavaScript expression until it is truthy; its value (CdpError on timeout)."""
        deadline = time.monotonic() + timeout_s
        while True:
            value = self.evaluate(expression)
            if value:
                return value
            if time.monotonic() > deadline:
                raise CdpError(f"still false after {timeout_s:g} s: {expression}")
            time.sleep(poll_s)

    def screenshot(self) -> bytes:
        """A PNG of the page as it is drawn now."""
        return base64.b64decode(self.call("Page.captureScreenshot", {"format": "png"}, session=True)["data"])

    def console_errors(self) -> list[str]:
        """Everything the page reported as an error so far, as text."""
        out = []
        for ev in self.events:
            method, params = ev.get("method"), ev.get("params", {})
            if method == "Runtime.consoleAPICalled" and params.get("type") in ("error", "assert"):
                out.append("console: " + " ".join(str(a.get("value", a.get("description", ""))) for a in params.get("args", [])))
            elif method == "Runtime.exceptionThrown":
                d = params.get("exceptionDetails", {})
                out.append(f"exception: {d.get('text')} {d.get('exception', {}).get('description', '')}")
            elif method == "Log.entryAdded" and params.get("entry", {}).get("level") == "error":
                e = params["entry"]
                out.append(f"log ({e.get('source')}): {e.get('text')} {e.get('url', '')}")
        return out

    # -- life cycle ----------------------------------------------------------------------------
    def close(self) -> None:
        stack = getattr(self, "_stack", None)
        if stack is not None:
            try:
                stack.close()
            except Exception:
                pass
            self._stack = None
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10)
        shutil.rmtree(self._profile, ignore_errors=True)

    def __enter__(self) -> HeadlessChromium:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


__all__ = ["CdpError", "HeadlessChromium", "find_chromium"]
