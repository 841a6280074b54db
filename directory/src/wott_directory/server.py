"""Run a directory on its own HTTP server (the standalone command, tests, benchmarks)."""

from __future__ import annotations

import socket
from typing import Any

from tornado.httpserver import HTTPServer
from tornado.netutil import bind_sockets

from .directory import Directory
from .handlers import make_app

__all__ = ["DirectoryServer"]


class DirectoryServer:
    """A started ``Directory`` behind a tornado HTTPServer on ``host:port`` (port 0: a free one).

    Without ``public_url`` the directory's base URL is ``http://host:port/``, known
    only once the socket is bound; that is why binding comes before ``Directory.start``.
    """

    def __init__(self, directory: Directory, host: str = "127.0.0.1", port: int = 0,
                 public_url: str | None = None, prefix: str = "", **app_settings: Any) -> None:
        self.directory = directory
        self.prefix = prefix.rstrip("/")
        self.host = host
        self.port = port
        self.public_url = public_url
        self.app_settings = app_settings
        self.server: HTTPServer | None = None

    @property
    def url(self) -> str:
        return self.directory.settings.base_url

    async def start(self) -> DirectoryServer:
        self.directory.settings.check_bind(self.host)
        sockets = bind_sockets(self.port, self.host, family=socket.AF_INET if ":" not in self.host
                               else socket.AF_UNSPEC)
        self.port = sockets[0].getsockname()[1]
        host = f"[{self.host}]" if ":" in self.host else self.host
        await self.directory.set_base_url(self.public_url or f"http://{host}:{self.port}{self.prefix}/")
        if not self.directory.started:
            await self.directory.start()
        # room above the directory's own limit so an oversized body gets a 413, not a reset
        max_body = max(self.directory.settings.max_body_bytes * 4, 100 * 1024 * 1024)
        app = make_app(self.directory, self.prefix, **self.app_settings)
        self.server = HTTPServer(app, max_body_size=max_body, idle_connection_timeout=300)
        self.server.add_sockets(sockets)
        return self

    async def stop(self) -> None:
        if self.server is not None:
            self.server.stop()
        await self.directory.stop()
        if self.server is not None:
            await self.server.close_all_connections()
            self.server = None
