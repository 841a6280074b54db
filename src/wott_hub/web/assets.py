"""Tornado routes serving the twin's static files and the vendored three.js.

Files are read through ``importlib.resources`` (so an installed wheel works as
well as the checkout), once, and kept in memory with their ETag and, for the
larger ones, a gzip copy made on first request: three.module.min.js (the device
page's renderer) is 0.7 MB, 0.17 MB compressed. Nothing
here is ever fetched from the network.
"""

from __future__ import annotations

import asyncio
import gzip
import hashlib
import mimetypes
from dataclasses import dataclass
from importlib import resources
from typing import Any

import tornado.web

__all__ = ["PREFIX", "Asset", "routes"]

PREFIX = "/twin"
_GZIP_MIN = 2048
_TYPES = {".js": "text/javascript; charset=utf-8", ".css": "text/css; charset=utf-8",
          ".html": "text/html; charset=utf-8", ".svg": "image/svg+xml", ".png": "image/png",
          ".LICENSE": "text/plain; charset=utf-8"}


@dataclass
class Asset:
    """One file served from memory; ``load`` says where its bytes come from."""

    package: str
    path: str
    body: bytes | None = None
    gz: bytes | None = None
    etag: str = ""
    content_type: str = "application/octet-stream"

    def load(self) -> bytes:
        if self.body is not None:
            return self.body
        node = resources.files(self.package)
        for part in self.path.split("/"):
            node = node / part
        self.body = body = node.read_bytes()
        self.etag = '"' + hashlib.blake2b(body, digest_size=12).hexdigest() + '"'
        ext = "." + self.path.rsplit(".", 1)[-1]
        self.content_type = _TYPES.get(ext) or mimetypes.guess_type(self.path)[0] or self.content_type
        return body

    def gzipped(self) -> bytes:
        if self.gz is None:
            self.gz = gzip.compress(self.load(), compresslevel=6, mtime=0)
        return self.gz


def _static(name: str) -> Asset:
    return Asset(__package__, f"static/{name}")


class AssetHandler(tornado.web.RequestHandler):
    """Serves one ``Asset`` (or one of ``assets`` by the name in the URL) with ETag revalidation."""

    def initialize(self, asset: Asset | None = None, assets: dict[str, Asset] | None = None) -> None:
        self.asset = asset
        self.assets = assets or {}

    async def get(self, name: str | None = None) -> None:
        asset = self.asset if name is None else self.assets.get(name)
        if asset is None:
            raise tornado.web.HTTPError(404)
        body = asset.body
        if body is None:
            body = await asyncio.to_thread(asset.load)
        # no-cache: the browser keeps the copy and revalidates it (a 304 costs nothing), so a
        # new version of the page is picked up at once
        self.set_header("Cache-Control", "no-cache")
        self.set_header("ETag", asset.etag)
        self.set_header("Content-Type", asset.content_type)
        self.set_header("X-Content-Type-Options", "nosniff")
        if self.request.headers.get("If-None-Match") == asset.etag:
            self.set_status(304)
            self.finish()
            return
        if len(body) >= _GZIP_MIN and "gzip" in self.request.headers.get("Accept-Encoding", ""):
            gz = asset.gz
            if gz is None:
                gz = await asyncio.to_thread(asset.gzipped)
            body = gz
            self.set_header("Content-Encoding", "gzip")
            self.set_header("Vary", "Accept-Encoding")
        self.finish(body)

    def compute_etag(self) -> None:  # ours is computed once per file
        return None


_PAGES = ("index.html", "device.html", "twin.css", "wot.js", "skin.js", "fleet.js", "device.js", "replay.js",
          "render3d.js")
# three.js and its orbit controls, vendored with their licence (docs/dependencies.md)
_VENDOR = ("three.module.min.js", "OrbitControls.js", "three.LICENSE")


def routes() -> list[tuple[str, type, dict[str, Any]]]:
    """``/`` (the fleet page), ``/twin/<file>`` and ``/twin/vendor/<file>`` (three.js)."""
    assets = {name: _static(name) for name in _PAGES}
    vendor = {name: _static(f"vendor/{name}") for name in _VENDOR}
    return [
        (r"/", AssetHandler, {"asset": assets["index.html"]}),
        (rf"{PREFIX}/?", tornado.web.RedirectHandler, {"url": "/"}),
        (rf"{PREFIX}/vendor/([A-Za-z0-9_.-]+)", AssetHandler, {"assets": vendor}),
        (rf"{PREFIX}/([A-Za-z0-9_.-]+)", AssetHandler, {"assets": assets}),
    ]
