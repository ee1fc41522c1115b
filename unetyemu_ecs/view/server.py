"""The web view's server: the page's static files and its WebSocket on one port of 127.0.0.1.

One asyncio event loop on a thread of its own runs a ``websockets`` server. Plain HTTP GETs are
answered from ``static/`` by the ``process_request`` hook (a fixed list of files read at start, so no
path can leave that folder); ``/ws`` upgrades to the WebSocket of :mod:`.wire`. Requests must name
this server by ``Host`` (``127.0.0.1:PORT`` or ``localhost:PORT``) and WebSocket ``Origin`` must be
this server or absent, so other web pages open in the same browser cannot read the stream.

What is sent comes from a :class:`ViewSource` (live snapshots, a recording) that the server polls
``STATE_HZ`` times a second of wall time while a page is ready for more. Each page has a mailbox
of one slot per channel (``state``, ``image``, ``lidar:<vehicle>``) emptied by its own sender task:
a newer frame replaces one still waiting (counted as dropped), so a slow page gets fewer frames and
never more memory. A page that has not taken its last state (stalled, or busy) is not polled for
at all: with only stalled pages nothing is computed. Frames are built once for all pages, and only
when a page wants them (its selected vehicle's camera and LiDAR, or every LiDAR).
"""

from __future__ import annotations

import asyncio
import email.utils
import logging
import mimetypes
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from . import wire
from .frames import LazyFrame

STATIC_DIR = Path(__file__).resolve().parent / "static"
HOST = "127.0.0.1"
CLOSE_TIMEOUT_S = 1.0             # a page that does not answer the closing handshake is cut off after this
STOP_WAIT_S = 1.5
STALL_S = 1.0                     # [s, wall] a page that took no state for this long is stalled (demand)
MAX_ERRORS_KEPT = 10
_CONTENT_TYPES = {".html": "text/html; charset=utf-8", ".js": "text/javascript; charset=utf-8",
                  ".mjs": "text/javascript; charset=utf-8", ".css": "text/css; charset=utf-8",
                  ".svg": "image/svg+xml", ".json": "application/json", ".png": "image/png"}

log = logging.getLogger("unetyemu_ecs.view")


class ServerError(RuntimeError):
    """The server could not start (the port in use, no permission); the message says which and why."""


@dataclass
class Update:
    """What a source has for the pages now: the ``state`` text message, and the newest LiDAR cloud and
    camera image of each vehicle (built only when a page wants them)."""

    state: str
    lidar: Mapping[str, LazyFrame] = field(default_factory=dict)
    images: Mapping[str, LazyFrame] = field(default_factory=dict)


class ViewSource(Protocol):
    """Where the frames come from. Every method is called on the server's thread."""

    def hello(self) -> list[str | bytes]:
        """The messages a page gets first, once: the ``scene`` text message and the ``mesh``."""
        ...

    def poll(self, now_s: float) -> Update | None:
        """The newest state (``now_s``: ``time.monotonic()``); None when there is nothing yet."""
        ...

    def control(self, msg: dict[str, Any]) -> None:
        """A player command from a page (``play``, ``pause``, ``seek``, ``speed``); a live source ignores them."""
        ...


class _Page:
    """One connected page: its mailbox, what it asked for, and what it was last sent."""

    def __init__(self, ws: Any) -> None:
        self.ws = ws
        self.slots: dict[str, str | bytes] = {}       # channel -> message waiting for the sender
        self.wake = asyncio.Event()
        self.selected: str | None = None
        self.lidar_mode = "selected"
        self.seen: dict[str, int] = {}                 # channel -> seq of the last frame put in its slot
        self.greeted = False                           # the scene and the mesh are sent
        self.state_sent_s = 0.0                        # [s, monotonic] when it last took a state

    @property
    def ready(self) -> bool:
        """It has taken the last state: it is keeping up (a page still busy with the scene is not)."""
        return self.greeted and "state" not in self.slots

    def watching(self, now_s: float) -> bool:
        """It took a state within the last STALL_S seconds (or has taken the last one): not stalled."""
        return self.greeted and ("state" not in self.slots or now_s - self.state_sent_s < STALL_S)

    def put(self, channel: str, message: str | bytes) -> bool:
        """Put ``message`` in the channel's slot; True when it replaced one never sent (a drop)."""
        replaced = channel in self.slots
        self.slots[channel] = message
        self.wake.set()
        return replaced


def _static_files(root: Path) -> dict[str, tuple[bytes, str]]:
    """URL path -> (body, content type) of every file under ``root`` (``/`` is ``index.html``)."""
    files: dict[str, tuple[bytes, str]] = {}
    for path in sorted(root.rglob("*")):
        if path.is_file() and not path.name.startswith("."):
            kind = _CONTENT_TYPES.get(path.suffix) or mimetypes.guess_type(path.name)[0] or "text/plain; charset=utf-8"
            files["/" + path.relative_to(root).as_posix()] = (path.read_bytes(), kind)
    if "/index.html" in files:
        files["/"] = files["/index.html"]
    if "/favicon.svg" in files:
        files["/favicon.ico"] = files["/favicon.svg"]
    return files


class ViewServer:
    """HTTP + WebSocket server of the view on ``127.0.0.1:port`` (0: any free port), on its own thread."""

    def __init__(self, source: ViewSource, port: int = 0, name: str = "view", state_hz: float = wire.STATE_HZ,
                 static_dir: Path = STATIC_DIR) -> None:
        self.source = source
        self.requested_port = int(port)
        self.port: int | None = None
        self.name = name
        self.period_s = 1.0 / state_hz
        self._files = _static_files(static_dir)
        self._pages: set[_Page] = set()
        self._allowed_hosts: frozenset[str] = frozenset()
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._joined: asyncio.Event | None = None      # set when a page connects (wakes the ticker)
        self._ready = threading.Event()
        self._start_error: BaseException | None = None
        # called on the server's thread when what the pages want may have changed (pages came or went,
        # chose another vehicle or LiDAR setting, or stalled): see :meth:`demand`
        self.on_change: Callable[[], None] | None = None
        # counters (written on the server's thread)
        self.pages_total = 0
        self.frames_sent = 0
        self.frames_dropped = 0
        self.bytes_sent = 0
        self.http_requests = 0
        self.bad_messages = 0
        self.polls = 0
        self._cpu_s = 0.0
        self.error_count = 0
        self.errors: list[str] = []

    # -- life cycle (the caller's thread) --------------------------------------------------------
    @property
    def url(self) -> str:
        return f"http://{HOST}:{self.port}/" if self.port is not None else ""

    def start(self, timeout_s: float = 10.0) -> None:
        """Bind and serve; raises :class:`ServerError` naming the port when it cannot."""
        self._thread = threading.Thread(target=self._run, name=f"unetyemu-{self.name}-server", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout_s):
            self.stop()
            raise ServerError(f"{self.name}: the server on {HOST}:{self.requested_port} did not start "
                              f"within {timeout_s:g} s")
        if self._start_error is not None:
            exc = self._start_error
            self._thread.join(1.0)
            self._thread = None
            why = getattr(exc, "strerror", None) or str(exc)
            hint = ("the port is in use (another program, or another view): choose another port, or 0 for any "
                    "free port") if getattr(exc, "errno", None) in (98, 48, 10048) else why
            raise ServerError(f"{self.name}: cannot serve on {HOST}:{self.requested_port}: {hint}") from exc

    def stop(self, timeout_s: float = 2.0) -> None:
        """Close every page's connection and the listening socket, end the thread; idempotent."""
        loop, stop = self._loop, self._stop
        if loop is not None and stop is not None and not loop.is_closed():
            try:
                loop.call_soon_threadsafe(stop.set)
            except RuntimeError:          # the loop closed meanwhile
                pass
        if self._thread is not None:
            self._thread.join(timeout_s)
            self._thread = None

    @property
    def pages(self) -> int:
        return len(self._pages)

    def has_ready_pages(self) -> bool:
        return any(p.ready for p in list(self._pages))

    def demand(self) -> tuple[bool, frozenset[str], bool, frozenset[str]]:
        """What the pages that are watching (not stalled) want now (any thread): (any watching, the
        vehicles whose images they show, whether one shows every LiDAR, the vehicles whose LiDAR they show)."""
        now_s = time.monotonic()
        pages = [p for p in list(self._pages) if p.watching(now_s)]
        selected = frozenset(p.selected for p in pages if p.selected is not None)
        lidar_all = any(p.lidar_mode == "all" for p in pages)
        lidar_of = frozenset(p.selected for p in pages if p.lidar_mode == "selected" and p.selected is not None)
        return bool(pages), selected, lidar_all, lidar_of

    def _changed(self) -> None:
        if self.on_change is not None:
            try:
                self.on_change()
            except Exception as exc:
                self._error("reporting what the pages want", exc)

    def thread_cpu_s(self) -> float | None:
        """CPU time the server's thread has used so far [s] (None once it ended, or where unsupported)."""
        thread = self._thread
        try:
            return time.clock_gettime(time.pthread_getcpuclockid(thread.ident))  # type: ignore[union-attr,arg-type]
        except (AttributeError, OSError, TypeError):
            return None

    def counters(self) -> dict[str, Any]:
        cpu_s = self.thread_cpu_s()
        if cpu_s is not None:
            self._cpu_s = cpu_s
        pages = list(self._pages)
        return {"url": self.url, "clients": len(pages), "clients_total": self.pages_total,
                "clients_watching": sum(p.watching(time.monotonic()) for p in pages),
                "messages_waiting": sum(len(p.slots) for p in pages),
                "frames_sent": self.frames_sent, "frames_dropped": self.frames_dropped, "bytes_sent": self.bytes_sent,
                "http_requests": self.http_requests, "bad_messages": self.bad_messages,
                "thread_cpu_s": round(self._cpu_s, 3), "error_count": self.error_count, "errors": list(self.errors)}

    def _error(self, what: str, exc: BaseException) -> None:
        """Count a failure (the server goes on); the first few are kept and logged, not every one."""
        self.error_count += 1
        if len(self.errors) < MAX_ERRORS_KEPT:
            self.errors.append(f"{what}: {type(exc).__name__}: {exc}")
            log.warning("%s: %s: %s", self.name, what, exc, exc_info=exc)

    # -- the server's thread ---------------------------------------------------------------------
    def _run(self) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        try:
            loop.run_until_complete(self._main())
        except BaseException as exc:      # never seen: keep the reason for the caller
            if not self._ready.is_set():
                self._start_error = exc
        finally:
            self._ready.set()
            try:
                self._cpu_s = time.thread_time()
                # what is left (a sender stuck on a page that does not read, a handler): cancel it quietly
                pending = [task for task in asyncio.all_tasks(loop) if not task.done()]
                for task in pending:
                    task.cancel()
                if pending:
                    loop.run_until_complete(asyncio.wait(pending, timeout=STOP_WAIT_S))
                loop.run_until_complete(loop.shutdown_asyncgens())
            finally:
                loop.close()

    async def _main(self) -> None:
        from websockets.asyncio.server import serve

        self._stop = asyncio.Event()
        self._joined = asyncio.Event()
        try:
            server = await serve(self._handler, HOST, self.requested_port, process_request=self._process_request,
                                 compression=None, max_size=wire.MAX_CLIENT_MESSAGE_BYTES, max_queue=8,
                                 close_timeout=CLOSE_TIMEOUT_S, logger=log)
        except OSError as exc:
            self._start_error = exc
            self._ready.set()
            return
        self.port = int(server.sockets[0].getsockname()[1])
        self._allowed_hosts = frozenset({f"{HOST}:{self.port}", f"localhost:{self.port}"})
        self._ready.set()
        ticker = asyncio.create_task(self._ticker())
        try:
            await self._stop.wait()
        finally:
            ticker.cancel()
            server.close()
            try:
                await asyncio.wait_for(server.wait_closed(), STOP_WAIT_S)
            except (TimeoutError, asyncio.TimeoutError):
                for page in list(self._pages):      # a page that does not read: cut it off
                    page.ws.transport.abort()
                try:
                    await asyncio.wait_for(server.wait_closed(), STOP_WAIT_S)
                except (TimeoutError, asyncio.TimeoutError):
                    pass

    def _process_request(self, connection: Any, request: Any) -> Any:
        """Answer a plain HTTP GET with a static file; let ``/ws`` through to the WebSocket handshake."""
        from websockets.datastructures import Headers
        from websockets.http11 import Response

        self.http_requests += 1
        try:
            host = request.headers.get("Host")
            origin = request.headers.get("Origin")
        except Exception:           # a header given twice
            return connection.respond(400, "Bad request\n")
        if host not in self._allowed_hosts:
            return connection.respond(421, f"This server answers as {HOST}:{self.port} only\n")
        path = request.path.split("?", 1)[0].split("#", 1)[0]
        if path == wire.WS_PATH:
            if origin is not None and origin not in {f"http://{h}" for h in self._allowed_hosts}:
                return connection.respond(403, "WebSocket connections from other web pages are refused\n")
            return None                       # go on with the WebSocket handshake
        found = self._files.get(path)
        if found is None:
            return connection.respond(404, f"Not found: {path}\n")
        body, kind = found
        headers = Headers([("Date", email.utils.formatdate(usegmt=True)), ("Connection", "close"),
                           ("Content-Length", str(len(body))), ("Content-Type", kind), ("Cache-Control", "no-cache"),
                           ("X-Content-Type-Options", "nosniff")])
        return Response(200, "OK", headers, body)

    async def _handler(self, ws: Any) -> None:
        from websockets.exceptions import ConnectionClosed

        page = _Page(ws)
        self._pages.add(page)
        self._joined.set()
        self.pages_total += 1
        sender = asyncio.create_task(self._sender(page))
        try:
            async for message in ws:
                self._on_message(page, message)
        except ConnectionClosed:
            pass
        finally:
            self._pages.discard(page)
            sender.cancel()
            self._changed()

    async def _sender(self, page: _Page) -> None:
        from websockets.exceptions import ConnectionClosed

        try:
            for message in self.source.hello():
                await page.ws.send(message)
                self._count_sent(message)
            page.greeted = True
            while True:
                await page.wake.wait()
                page.wake.clear()
                while page.slots:
                    channel = next(iter(page.slots))
                    message = page.slots.pop(channel)
                    await page.ws.send(message)
                    self._count_sent(message)
                    if channel == "state":
                        page.state_sent_s = time.monotonic()
        except (ConnectionClosed, asyncio.CancelledError):
            pass
        except Exception as exc:
            self._error("sending", exc)

    def _count_sent(self, message: str | bytes) -> None:
        self.frames_sent += 1
        self.bytes_sent += len(message)

    def _on_message(self, page: _Page, message: str | bytes) -> None:
        msg = wire.parse_client_message(message)
        if msg is None:
            self.bad_messages += 1
            return
        kind = msg["type"]
        if kind == "select":
            page.selected = msg["vehicle"]
            page.seen.pop("image", None)               # the new vehicle's newest image goes out next
        elif kind == "lidar":
            page.lidar_mode = msg["mode"]
        if kind in ("select", "lidar"):
            self._changed()
        else:
            try:
                self.source.control(msg)
            except Exception as exc:
                self._error(f"control {kind}", exc)

    async def _ticker(self) -> None:
        loop = asyncio.get_running_loop()
        next_s = loop.time()
        while True:
            if not self._pages:                          # nobody watching: sleep until a page connects
                self._joined.clear()
                await self._joined.wait()
                next_s = loop.time()
            next_s += self.period_s
            delay = next_s - loop.time()
            if delay < -self.period_s:                   # fell behind (a slow build): do not catch up
                next_s = loop.time()
                delay = 0.0
            await asyncio.sleep(max(0.0, delay))
            if self._pages:
                try:
                    self._tick()
                except Exception as exc:
                    self._error("building a frame", exc)

    def _tick(self) -> None:
        """Poll the source for the pages ready for more, fill their mailboxes (server's thread)."""
        self._changed()
        ready = [p for p in self._pages if p.ready]
        self.frames_dropped += len(self._pages) - len(ready)       # the busy ones miss this state
        if not ready:
            return
        update = self.source.poll(time.monotonic())
        self.polls += 1
        if update is None:
            return
        for page in ready:
            page.put("state", update.state)
            if page.selected is not None:
                frame = update.images.get(page.selected)
                if frame is not None:
                    self._offer(page, "image", frame)
            if page.lidar_mode == "all":
                for vehicle, frame in update.lidar.items():
                    self._offer(page, f"lidar:{vehicle}", frame)
            elif page.lidar_mode == "selected" and page.selected is not None:
                frame = update.lidar.get(page.selected)
                if frame is not None:
                    self._offer(page, f"lidar:{page.selected}", frame)

    def _offer(self, page: _Page, channel: str, frame: LazyFrame) -> None:
        """Put ``frame`` in the page's ``channel`` slot unless the page already had it (``seq`` is
        unique across a source's frames, so a new selection's frame is never mistaken for the old one)."""
        if page.seen.get(channel) == frame.seq:
            return
        page.seen[channel] = frame.seq
        message = frame.get()
        if message is not None and page.put(channel, message):
            self.frames_dropped += 1

__all__ = ["HOST", "STATIC_DIR", "ServerError", "Update", "ViewServer", "ViewSource"]
