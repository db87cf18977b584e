"""The web side: one page and one WebSocket, served by aiohttp in a thread of its own.

Read-only: the server answers GET for the page's three files and the WebSocket, nothing
else; what a page may send is "next frame please" (with the map it shows) and, for a bag,
which frame to show.  No parameter, file or topic can be changed from it.

The browser sets the pace, within a cap: a page asks for the next frame when it has drawn
the last one, and only then is a frame converted and encoded (in one worker thread, once per
frame for all pages); the server sends each page at most ``max_rate`` frames a second (0 =
no cap; changeable while serving), holding a request until the page's next send is due and
then sending the newest frame.  A page that stops asking costs nothing; one that asks and
does not read blocks only its own sender (one message in flight, dropped after
``send_timeout``), and the heartbeat closes a connection whose browser vanished.  Frames
that arrive in between are never queued: the page gets the newest one.
"""
from __future__ import annotations

import asyncio
import concurrent.futures
import json
import threading
from dataclasses import dataclass, field
from importlib import resources
from typing import Any, Protocol

from aiohttp import WSMsgType, web

from .assembly import FrameAssembler, FrameParts
from .packets import MAPS, PacketBuilder

STATIC_FILES = {"/": ("index.html", "text/html"), "/viewer.js": ("viewer.js", "text/javascript"),
                "/viewer.css": ("viewer.css", "text/css")}
SECURITY_HEADERS = {
    "Content-Security-Policy": "default-src 'self'; img-src 'self' blob: data:; "
                               "connect-src 'self'; frame-ancestors 'none'",
    "X-Content-Type-Options": "nosniff",
    "Cache-Control": "no-store",
    "Referrer-Policy": "no-referrer",
}


class FrameSource(Protocol):
    """What the server shows: live topics (the node) or a recorded bag."""

    assembler: FrameAssembler

    def hello(self) -> dict[str, Any]:
        """Sent once per page: mode ('live' / 'bag'), names, bag length."""

    def seek(self, index: int) -> None:
        """Show frame ``index`` of a bag (live sources ignore it)."""

    def extra(self) -> dict[str, Any]:
        """Added to every frame header (the bag's position)."""


@dataclass(eq=False)
class _Client:
    ws: web.WebSocketResponse
    want: asyncio.Event = field(default_factory=asyncio.Event)
    map_kind: str = "pressure"
    last_key: Any = None
    sent: int = 0
    last_send: float = float("-inf")     # loop time of the last send (the cap counts from it)


class ViewerServer:
    """aiohttp app on ``host:port`` in a daemon thread with its own event loop."""

    def __init__(self, source: FrameSource, builder: PacketBuilder, host: str = "127.0.0.1",
                 port: int = 8080, max_clients: int = 4, send_timeout: float = 10.0,
                 idle_s: float = 1.0, heartbeat_s: float = 10.0, max_rate: float = 0.0
                 ) -> None:
        self.source = source
        self.builder = builder
        self.host = host
        self.port = int(port)
        self.max_clients = int(max_clients)
        self.send_timeout = float(send_timeout)
        self.idle_s = float(idle_s)
        self.heartbeat_s = float(heartbeat_s)
        self.max_rate = float(max_rate)   # frames/s to each page, 0 = no cap (any thread)
        self._files = {path: (resources.files(__package__).joinpath("static", name)
                              .read_bytes(), kind)
                       for path, (name, kind) in STATIC_FILES.items()}
        self._clients: set[_Client] = set()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._started = threading.Event()
        self._error: BaseException | None = None
        self._stop: asyncio.Future[None] | None = None
        self._changed: asyncio.Event | None = None
        self._waiting = 0
        self._poke_pending = False
        self._pool = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="viewer-encode")
        self._cache: tuple[Any, bytes] | None = None
        self.frames_sent = 0
        source.assembler.on_change(self._poke)

    # ------------------------------------------------------------------ lifetime

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/"

    @property
    def clients(self) -> int:
        """Pages connected now (read from any thread)."""
        return len(self._clients)

    def start(self, timeout: float = 10.0) -> str:
        """Serve in the background; the URL. OSError if the address cannot be bound."""
        self._thread = threading.Thread(target=self._run, name="viewer-web", daemon=True)
        self._thread.start()
        if not self._started.wait(timeout):
            raise OSError(f"the web server did not start on {self.host}:{self.port}")
        if self._error is not None:
            raise OSError(f"cannot serve on {self.host}:{self.port}: {self._error}")
        return self.url

    def stop(self, timeout: float = 5.0) -> None:
        """Close every page's connection and the server; join the thread."""
        loop, done = self._loop, self._stop
        if loop is not None and done is not None and not loop.is_closed():
            def finish() -> None:
                if not done.done():
                    done.set_result(None)
            try:
                loop.call_soon_threadsafe(finish)
            except RuntimeError:     # the loop has already closed
                pass
        if self._thread is not None:
            self._thread.join(timeout)
        self._pool.shutdown(wait=True, cancel_futures=True)

    def _run(self) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        try:
            loop.run_until_complete(self._serve())
        except BaseException as exc:     # bind errors end up in start()
            self._error = exc
        finally:
            self._started.set()
            loop.close()

    async def _serve(self) -> None:
        app = web.Application(client_max_size=4096)
        for path in STATIC_FILES:
            app.router.add_get(path, self._file)
        app.router.add_get("/ws", self._websocket)
        app.on_response_prepare.append(self._headers)
        app.on_shutdown.append(self._close_clients)
        runner = web.AppRunner(app, access_log=None, handle_signals=False)
        await runner.setup()
        self._changed = asyncio.Event()
        self._stop = asyncio.get_running_loop().create_future()
        try:
            site = web.TCPSite(runner, self.host, self.port, reuse_address=True)
            await site.start()
            if self.port == 0:      # an ephemeral port: tell which one
                server = getattr(site, "_server", None)
                if server is not None and server.sockets:
                    self.port = int(server.sockets[0].getsockname()[1])
            self._started.set()
            await self._stop
        finally:
            await runner.cleanup()

    async def _close_clients(self, _app: web.Application) -> None:
        for client in list(self._clients):
            await client.ws.close(code=1001, message=b"viewer stopping")

    @staticmethod
    async def _headers(_request: web.Request, response: web.StreamResponse) -> None:
        response.headers.update(SECURITY_HEADERS)

    async def _file(self, request: web.Request) -> web.Response:
        body, kind = self._files[request.path]
        return web.Response(body=body, content_type=kind, charset="utf-8")

    # ------------------------------------------------------------------ frames to pages

    def _poke(self) -> None:
        """A message arrived (any thread): wake the pages waiting for one."""
        loop = self._loop
        if self._waiting and not self._poke_pending and loop is not None:
            self._poke_pending = True
            try:
                loop.call_soon_threadsafe(self._wake)
            except RuntimeError:    # loop closed while stopping
                pass

    def _wake(self) -> None:
        self._poke_pending = False
        if self._changed is not None:
            self._changed.set()
            self._changed = asyncio.Event()

    async def _websocket(self, request: web.Request) -> web.StreamResponse:
        origin = request.headers.get("Origin")
        if origin is not None and origin.split("://", 1)[-1] != request.host:
            raise web.HTTPForbidden(text="cross-origin WebSocket refused")
        if len(self._clients) >= self.max_clients:
            raise web.HTTPServiceUnavailable(text=f"at most {self.max_clients} pages at once")
        ws = web.WebSocketResponse(heartbeat=self.heartbeat_s, max_msg_size=4096,
                                   compress=False)
        await ws.prepare(request)
        client = _Client(ws)
        self._clients.add(client)
        sender = asyncio.create_task(self._send_loop(client))
        try:
            await ws.send_str(json.dumps({"type": "hello", **self.source.hello()}))
            async for msg in ws:
                if msg.type != WSMsgType.TEXT or not self._request(client, msg.data):
                    break
        finally:
            sender.cancel()
            self._clients.discard(client)
            await ws.close()
        return ws

    def _request(self, client: _Client, text: str) -> bool:
        """One request of a page; False ends its connection (it spoke out of turn)."""
        try:
            request = json.loads(text)
        except ValueError:
            return False
        if not isinstance(request, dict):
            return False
        kind = request.get("type")
        if kind == "next":
            if request.get("map") in MAPS:
                client.map_kind = str(request["map"])
            client.want.set()
            return True
        if kind == "seek" and isinstance(request.get("index"), int):
            self.source.seek(int(request["index"]))
            return True
        return False

    async def _send_loop(self, client: _Client) -> None:
        loop = asyncio.get_running_loop()
        try:
            while not client.ws.closed:
                await client.want.wait()
                client.want.clear()
                await self._pace(client)
                packet = await self._next_packet(client)
                client.last_send = loop.time()
                await asyncio.wait_for(client.ws.send_bytes(packet), self.send_timeout)
                client.sent += 1
                self.frames_sent += 1
        except (asyncio.TimeoutError, ConnectionError, RuntimeError):
            await client.ws.close(code=1008, message=b"page too slow to read")

    async def _pace(self, client: _Client) -> None:
        """Wait until this page's next send is due: at most ``max_rate`` a second.

        Frames that arrive meanwhile are not queued (the page then gets the newest); the
        wait is re-read every 0.25 s, so a live change of ``max_rate`` applies at once.
        """
        loop = asyncio.get_running_loop()
        while True:
            rate = self.max_rate
            if rate <= 0:
                return
            wait = client.last_send + 1.0 / rate - loop.time()
            if wait <= 0:
                return
            await asyncio.sleep(min(wait, 0.25))

    async def _next_packet(self, client: _Client) -> bytes:
        """The newest frame this page has not seen, or figures only after ``idle_s``."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + self.idle_s
        while True:
            frame = self.source.assembler.latest()
            key = (frame.key if frame is not None else None, client.map_kind)
            if key != client.last_key:
                break
            remaining = deadline - loop.time()
            if remaining <= 0:
                frame = None           # nothing new: the figures, the page keeps its frame
                break
            changed = self._changed
            assert changed is not None
            self._waiting += 1
            try:
                await asyncio.wait_for(changed.wait(), remaining)
            except asyncio.TimeoutError:
                pass
            finally:
                self._waiting -= 1
        if frame is not None:
            client.last_key = key
        cached = self._cache
        if frame is not None and cached is not None and cached[0] == key:
            return cached[1]
        packet = await loop.run_in_executor(self._pool, self._build, frame, client.map_kind)
        if frame is not None:
            self._cache = (key, packet)
        return packet

    def _build(self, frame: FrameParts | None, map_kind: str) -> bytes:
        assembler = self.source.assembler
        extra = {**self.source.extra(), "pages": len(self._clients)}
        return self.builder.build(frame, assembler.stats(), map_kind, assembler.diagnostics,
                                  extra)
