"""The dashboard's web server: NiceGUI (FastAPI and uvicorn underneath) serving the page at
``/``, the hub's summary as JSON at ``/api/status``, behind the token rule of
:mod:`utrf.dashboard.access`."""

from __future__ import annotations

import asyncio
import gc
import sys
from collections.abc import Callable
from dataclasses import dataclass

from nicegui import Client, app, background_tasks, ui

from utrf.dashboard.access import TokenGuard, needs_token
from utrf.dashboard.hub import DashboardHub
from utrf.dashboard.page import DashboardPage

#: how long NiceGUI keeps a page that lost its connection (or has not connected yet: a
#: browser on a loaded machine takes seconds to load three.js and ECharts), before dropping
#: it; the page in control gives up control only then (the fingers held at once)
RECONNECT_TIMEOUT_S = 15.0
#: the interpreter's thread switch interval in the dashboard's process (s; Python's is 5 ms):
#: the Hand's reader thread decodes the 1 kHz stream beside the event loop, and at each
#: socket write or select the loop lets go of the interpreter, then waited up to 5 ms for it,
#: several times an update (docs/dashboard.md)
GIL_SWITCH_S = 0.001


@dataclass(frozen=True)
class ServerOptions:
    host: str = "127.0.0.1"
    port: int = 8080
    token: str | None = None  # required when host is not a loopback name
    ui_hz: float = 30.0  # the live view: 3D hand, numbers, modes, faults
    plot_hz: float = 2.0  # each chart, one a frame at most (5 doubled the p99: docs/dashboard.md)
    window_s: float = 5.0  # the plots' span
    points_per_s: float = 25.0  # the plots' decimation for the eye

    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        query = f"/?token={self.token}" if self.token else "/"
        return f"http://{host}:{self.port}{query}"


def serve(hub: DashboardHub, options: ServerOptions, on_ready: Callable[[str], None]) -> None:
    """Serve until Ctrl-C or SIGTERM (blocks)."""
    if needs_token(options.host) and not options.token:
        raise ValueError(
            f"the dashboard listens on {options.host}, beyond 127.0.0.1: it needs a token"
        )
    if options.token:
        app.add_middleware(TokenGuard, token=options.token)
    sys.setswitchinterval(GIL_SWITCH_S)

    @ui.page("/")
    def index(client: Client) -> None:
        DashboardPage(
            hub,
            client,
            ui_hz=options.ui_hz,
            plot_hz=options.plot_hz,
            window_s=options.window_s,
            points_per_s=options.points_per_s,
        )
        # what the server and the page built lives on: out of the collector's way (a full
        # collection of NiceGUI's heap held the event loop 0.06-0.13 s, docs/dashboard.md)
        gc.freeze()

    @app.get("/api/status")
    def status() -> dict:
        return hub.status()

    async def announce() -> None:
        # uvicorn listens only after the app's startup: say "open" once it answers
        for _ in range(400):
            try:
                _, writer = await asyncio.open_connection(options.host, options.port)
            except OSError:
                await asyncio.sleep(0.05)
                continue
            writer.close()
            break
        on_ready(options.url())

    app.on_startup(lambda: background_tasks.create(announce(), name="utrf-announce"))
    ui.run(
        host=options.host,
        port=options.port,
        title="utrf dashboard",
        show=False,
        reload=False,
        show_welcome_message=False,
        reconnect_timeout=RECONNECT_TIMEOUT_S,
        # small messages many times a second on a local line: compressing each costs both
        # ends more CPU than it saves
        ws_per_message_deflate=False,
    )
