"""The live map's web server (``operator web``): the page, the fleet picture as JSON and as a
stream of server-sent events, GeoJSON, optional local map tiles, and the operator's
``start`` and ``hold`` per vehicle, proved by the server with the operator keys it holds.

aiohttp, because one well-kept library gives what the page needs on the asyncio loop it
already runs: static files, streamed responses for server-sent events, cookies, TLS, and a
thread pool for the blocking zenoh queries; Starlette would need uvicorn beside it.
Server-sent events rather than WebSocket: the page only listens (its two commands are plain
POSTs), and EventSource reconnects by itself.

Login: a token (128 random bits, printed at start, or given) exchanged once for a session
cookie (HttpOnly, SameSite=Strict, Secure under TLS); every ``/api`` path refuses without it
(401), so a page without it reads nothing. A command also needs the header
``X-Requested-With: uavmec-live-map``, which a form on another site cannot send. Tools may
send ``Authorization: Bearer TOKEN`` instead of the cookie.
"""

from __future__ import annotations

import asyncio
import hmac
import json
import logging
import secrets
import ssl
import threading
import time
from pathlib import Path
from typing import Any, Awaitable, Callable

from aiohttp import web

from protocol import Keys, ProtocolError
from protocol.client import ClientError
from protocol.text import printable

from ..live.feed import LiveFeed
from ..live.geojson import NoOrigin, feature_collection

log = logging.getLogger(__name__)

STATIC = Path(__file__).with_name("static")
COOKIE = "uavmec_live"
CSRF_HEADER, CSRF_VALUE = "X-Requested-With", "uavmec-live-map"
SEND_EVERY_S = 0.5
"""Least time between two snapshots on one stream: 2 a second at most, an update still within 1 s of a
status (each redraw costs the page's computer; docs/PERFORMANCE.md, "With the live map open")."""
REFRESH_S = 1.0
"""A snapshot at least this often, changed or not: the ages and the staleness alerts move
with time even when nothing arrives."""
COMMAND_TIMEOUT_S = 5.0
MAX_SESSIONS = 1024


class LiveMapServer:
    """The web application over a ``LiveFeed`` (whose picture and lock it reads)."""

    def __init__(self, feed: LiveFeed, token: str | None = None, *, tiles: Path | None = None,
                 tiles_zoom: int = 17, secure: bool = False) -> None:
        self.feed = feed
        self.token = token or secrets.token_urlsafe(16)
        self.tiles, self.tiles_zoom = tiles, tiles_zoom
        self.secure = secure
        self._sessions: set[str] = set()
        self._changed: asyncio.Event | None = None
        self._loop: asyncio.AbstractEventLoop | None = None

    # -- the application ------------------------------------------------------------------------

    def app(self) -> web.Application:
        app = web.Application(middlewares=[self._guard])
        app.router.add_get("/", self._index)
        app.router.add_static("/static/", STATIC, show_index=False)
        app.router.add_get("/login", self._login)
        app.router.add_post("/login", self._login)
        app.router.add_post("/logout", self._logout)
        app.router.add_get("/api/picture", self._picture)
        app.router.add_get("/api/stream", self._stream)
        app.router.add_get("/api/geojson", self._geojson)
        app.router.add_post(r"/api/vehicles/{vehicle}/{command:start|hold}", self._command)
        app.router.add_get(r"/tiles/{z:\d{1,2}}/{x:\d{1,9}}/{y:\d{1,9}}.png", self._tile)
        app.on_startup.append(self._started)
        return app

    async def _started(self, app: web.Application) -> None:
        self._loop = asyncio.get_running_loop()
        self._changed = asyncio.Event()
        self.feed.on_change = self._notify

    def _notify(self) -> None:
        """From zenoh's threads: wake the streams (on the loop's thread)."""
        loop, changed = self._loop, self._changed
        if loop is not None and changed is not None and not loop.is_closed():
            loop.call_soon_threadsafe(changed.set)

    @web.middleware
    async def _guard(self, request: web.Request, handler: Callable[[web.Request], Awaitable[web.StreamResponse]]
                     ) -> web.StreamResponse:
        """Every /api and /tiles path needs a login; a command also the page's header."""
        private = request.path.startswith(("/api/", "/tiles/"))
        if private and not self._logged_in(request):
            return web.json_response({"error": "login required: open the address operator web printed, or "
                                               "send its token"}, status=401)
        if request.method == "POST" and request.path.startswith("/api/") and \
                request.headers.get(CSRF_HEADER) != CSRF_VALUE:
            return web.json_response({"error": f"a command needs the header {CSRF_HEADER}: {CSRF_VALUE}"},
                                     status=403)
        response = await handler(request)
        response.headers.setdefault("Cache-Control", "no-store")
        response.headers.setdefault("X-Content-Type-Options", "nosniff")
        response.headers.setdefault("Content-Security-Policy",
                                    "default-src 'self'; img-src 'self' data:; style-src 'self'; "
                                    "frame-ancestors 'none'")
        return response

    def _logged_in(self, request: web.Request) -> bool:
        cookie = request.cookies.get(COOKIE, "")
        if cookie and any(hmac.compare_digest(cookie, s) for s in self._sessions):
            return True
        bearer = request.headers.get("Authorization", "")
        return bearer.startswith("Bearer ") and hmac.compare_digest(bearer[7:].encode(), self.token.encode())

    async def _index(self, request: web.Request) -> web.StreamResponse:
        return web.FileResponse(STATIC / "index.html")

    async def _login(self, request: web.Request) -> web.StreamResponse:
        given = request.query.get("token", "")
        if request.method == "POST":
            given = str((await request.post()).get("token", ""))
        if not hmac.compare_digest(given.encode(), self.token.encode()):
            log.warning("live map: a login with a wrong token from %s", request.remote)
            return web.json_response({"error": "wrong token: use the one operator web printed"}, status=401)
        if len(self._sessions) >= MAX_SESSIONS:
            self._sessions.pop()
        session = secrets.token_urlsafe(32)
        self._sessions.add(session)
        response = web.HTTPSeeOther("/")  # the token leaves the address bar
        response.set_cookie(COOKIE, session, httponly=True, samesite="Strict", secure=self.secure, path="/")
        raise response

    async def _logout(self, request: web.Request) -> web.StreamResponse:
        self._sessions.discard(request.cookies.get(COOKIE, ""))
        response = web.HTTPSeeOther("/")
        response.del_cookie(COOKIE, path="/")
        raise response

    # -- the picture --------------------------------------------------------------------------------

    def snapshot(self) -> dict[str, Any]:
        with self.feed.lock:
            out = self.feed.picture.snapshot(time.monotonic(), time.time())
        out["tiles"] = {"zoom": self.tiles_zoom} if self.tiles is not None else None
        return out

    async def _picture(self, request: web.Request) -> web.StreamResponse:
        return web.json_response(self.snapshot())

    async def _geojson(self, request: web.Request) -> web.StreamResponse:
        try:
            return web.json_response(feature_collection(self.snapshot()), content_type="application/geo+json")
        except NoOrigin as err:
            return web.json_response({"error": str(err)}, status=409)

    async def _stream(self, request: web.Request) -> web.StreamResponse:
        """Server-sent events: a snapshot at every change (``SEND_EVERY_S`` apart at least) and
        every ``REFRESH_S`` regardless."""
        assert self._changed is not None
        response = web.StreamResponse(headers={"Content-Type": "text/event-stream", "Cache-Control": "no-store",
                                               "X-Accel-Buffering": "no"})
        await response.prepare(request)
        log.info("live map: a page follows the picture (%s)", request.remote)
        try:
            while True:
                self._changed.clear()
                data = json.dumps(self.snapshot(), separators=(",", ":"))
                await response.write(f"event: picture\ndata: {data}\n\n".encode())
                sent = time.monotonic()
                try:
                    await asyncio.wait_for(self._changed.wait(), REFRESH_S)
                except asyncio.TimeoutError:
                    pass
                await asyncio.sleep(max(SEND_EVERY_S - (time.monotonic() - sent), 0.0))
        except (ConnectionResetError, asyncio.CancelledError):
            pass
        return response

    # -- the operator's commands ------------------------------------------------------------------

    async def _command(self, request: web.Request) -> web.StreamResponse:
        vehicle, command = request.match_info["vehicle"], request.match_info["command"]
        try:
            Keys(self.feed.prefix, vehicle)
        except ProtocolError as err:
            return web.json_response({"error": f"vehicle: {err.message}"}, status=400)
        try:
            body = await request.json() if request.can_read_body else {}
        except json.JSONDecodeError:
            return web.json_response({"error": "the body is not JSON"}, status=400)
        reason = body.get("reason", "") if isinstance(body, dict) else ""
        if not isinstance(reason, str) or len(reason) > 256:
            return web.json_response({"error": "reason: a text of at most 256 characters"}, status=400)
        key = self.feed.operator_key(vehicle)
        log.info("live map: %s %s asked from %s", command, vehicle, request.remote)

        def ask() -> Any:
            return self.feed.client(vehicle).operator(command, reason or "from the live map", COMMAND_TIMEOUT_S,
                                                      key=key)
        try:
            reply = await asyncio.get_running_loop().run_in_executor(None, ask)
        except ClientError as err:
            hint = " (the server holds no operator key for this vehicle: --operator-key)" if key is None else ""
            return web.json_response({"error": printable(f"{err.field}: {err.message}{hint}", 400)}, status=502)
        return web.json_response({"accepted": reply.accepted, "message": reply.message, "authority": reply.authority,
                                  "phase": reply.phase})

    async def _tile(self, request: web.Request) -> web.StreamResponse:
        if self.tiles is None:
            raise web.HTTPNotFound()
        m = request.match_info
        path = self.tiles / str(int(m["z"])) / str(int(m["x"])) / f"{int(m['y'])}.png"
        if not path.is_file():
            raise web.HTTPNotFound()
        return web.FileResponse(path, headers={"Cache-Control": "max-age=3600"})


class RunningServer:
    """A ``LiveMapServer`` served on its own thread and event loop (the demo's, the tests'):
    ``url`` once started, ``close`` to stop."""

    def __init__(self, server: LiveMapServer, host: str = "127.0.0.1", port: int = 0,
                 ssl_context: ssl.SSLContext | None = None) -> None:
        self.server = server
        self.host, self.port, self.ssl_context = host, port, ssl_context
        self._loop = asyncio.new_event_loop()
        self._runner: web.AppRunner | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="live-map", daemon=True)

    def start(self, timeout_s: float = 10.0) -> "RunningServer":
        self._thread.start()
        if not self._ready.wait(timeout_s):
            raise RuntimeError(f"the live map's server did not start within {timeout_s:g} s")
        if self._error is not None:
            raise self._error
        return self

    def _run(self) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._loop.run_until_complete(self._serve())
        except BaseException as err:  # reported by start()
            self._error = err
            self._ready.set()
            return
        self._ready.set()
        self._loop.run_forever()

    async def _serve(self) -> None:
        self._runner = web.AppRunner(self.server.app(), access_log=None, handle_signals=False, shutdown_timeout=0.5)
        await self._runner.setup()
        site = web.TCPSite(self._runner, self.host, self.port, ssl_context=self.ssl_context)
        await site.start()
        self.port = site._server.sockets[0].getsockname()[1]  # type: ignore[union-attr]

    @property
    def url(self) -> str:
        scheme = "https" if self.ssl_context is not None else "http"
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{scheme}://{host}:{self.port}/"

    @property
    def login_url(self) -> str:
        return f"{self.url}login?token={self.server.token}"

    def close(self) -> None:
        if not self._thread.is_alive():
            return

        async def stop() -> None:
            if self._runner is not None:
                await self._runner.cleanup()
        try:
            asyncio.run_coroutine_threadsafe(stop(), self._loop).result(timeout=5.0)
        except Exception as err:  # noqa: BLE001 - stopping: say it, go on
            log.warning("live map: stopping the server: %s", err)
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(timeout=5.0)
