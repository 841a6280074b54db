"""``wott-directory``: run a Thing Description Directory on its own, for a fleet of hubs.

Hubs register their Things into it with a ttl (``Registrar``) and keep them
fresh; when a hub dies its Things expire. Writes need the bearer token from
``--token``, ``--token-file`` or ``WOTT_DIRECTORY_TOKEN``; ``--open`` lets
loopback clients write without one and is refused on any other address.
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import os
import signal
import sys
from pathlib import Path

from .directory import Directory
from .server import DirectoryServer
from .settings import ConfigError, DirectorySettings

__all__ = ["main"]


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="wott-directory", description=__doc__.split("\n\n")[0])
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=8090, help="port (0: any free port; default 8090)")
    p.add_argument("--db", default="sqlite:///wott-directory.db",
                   help="SQLAlchemy database URL (default sqlite:///wott-directory.db)")
    p.add_argument("--public-url", help="URL clients use to reach the API (default http://HOST:PORT/)")
    p.add_argument("--token", help="bearer token for writes (prefer --token-file or WOTT_DIRECTORY_TOKEN)")
    p.add_argument("--token-file", type=Path, help="file holding the bearer token")
    p.add_argument("--open", action="store_true", help="loopback clients may write without a token")
    p.add_argument("--protect-reads", action="store_true", help="reads need the token too")
    p.add_argument("--title", default=DirectorySettings.title)
    p.add_argument("--page-size", type=int, default=DirectorySettings.page_size)
    p.add_argument("--max-body", type=int, default=DirectorySettings.max_body_bytes,
                   help="largest accepted TD in bytes")
    p.add_argument("--max-store", type=int, default=DirectorySettings.max_store_bytes,
                   help="stored TDs in total, bytes of JSON (clients' writes beyond: 413)")
    p.add_argument("--max-events", type=int, default=DirectorySettings.max_event_bytes,
                   help="past events kept for Last-Event-ID replay, bytes of JSON")
    p.add_argument("--purge-interval", type=float, default=DirectorySettings.purge_interval)
    p.add_argument("--no-freeze-gc", action="store_true",
                   help="keep TDs under the cyclic GC (slower, long pauses with many TDs)")
    p.add_argument("--log-level", default="INFO")
    return p


def settings_from_args(args: argparse.Namespace) -> DirectorySettings:
    token = args.token or os.environ.get("WOTT_DIRECTORY_TOKEN") or None
    if args.token_file is not None:
        token = args.token_file.read_text().strip()
    return DirectorySettings(title=args.title, token=token, open_writes=args.open,
                             protect_reads=args.protect_reads, page_size=args.page_size,
                             max_body_bytes=args.max_body, purge_interval=args.purge_interval,
                             max_store_bytes=args.max_store, max_event_bytes=args.max_events,
                             freeze_gc=not args.no_freeze_gc)


async def _serve(args: argparse.Namespace) -> None:
    settings = settings_from_args(args)
    # DirectoryServer.start checks this too, but only after Directory() has built the engine,
    # which fails first on a --db whose driver is missing: refuse the unsafe binding before that
    settings.check_bind(args.host)
    server = DirectoryServer(Directory(settings, args.db), args.host, args.port, args.public_url)
    await server.start()
    mode = "open to loopback writes" if settings.open_writes else (
        "writes need the token" if settings.token else "read-only (no token configured)")
    print(f"wott-directory at {server.url} ({mode}); TD at {server.url.rstrip('/')}/.well-known/wot",
          flush=True)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    await stop.wait()
    await server.stop()


def main(argv: list[str] | None = None) -> None:
    args = _parser().parse_args(argv)
    logging.basicConfig(level=args.log_level.upper(),
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    try:
        asyncio.run(_serve(args))
    except ConfigError as e:
        print(f"wott-directory: {e}", file=sys.stderr)
        raise SystemExit(2) from None


if __name__ == "__main__":
    main()
