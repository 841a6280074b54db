"""The Foxglove relay: a process of the hub's own that runs ``foxglove-sdk``'s server (issue 48, item 6).

Why a process: the SDK (0.30) fans a message out to its clients inside ``Channel.log``, on the
caller's thread and holding the GIL the whole time: it frames and copies the payload once per
subscribed client there (measured: a 250 kB image to 20 clients, 2.9 ms of the caller's CPU per call
and ~25 ms of wall time on the loaded 2-core machine; an 8 MB message to 20 clients held every other
Python thread still for 0.8-1.1 s). In the hub's process every device's pipeline waited for it, so
each viewer cost the sensors frames. Here the hub writes each message once to a socket (``live.py``:
encoded once by the mapping, sent once whatever the number of viewers) and this process, with its own
GIL, does the per-client work: the sockets, ``nagle.disable_nagle`` and ``guard.FoxgloveGuard`` (which
read this process's own sockets) live here.

The hub starts it (``python -m wott_hub.robotics.relay <down fd> <up fd>``) with one end of each of two
socket pairs (it reads the first, writes the second); frames are ``relay_wire``'s. Hub -> relay:
``INIT`` (the server's options), ``CHANNEL``/``CLOSE``, ``LOG``, ``STOP``. Relay -> hub: ``READY``
(the port, or why the server did not start), ``SUB`` (a client subscribed or unsubscribed a topic),
``HEALTH`` (the guard's counters, every ``TICK_S``), ``LOGREC`` (its log lines, written by the hub's
logging). The relay ends at ``STOP`` or when the hub's end closes (the hub died): it never outlives
the hub. Signals meant for the hub (a terminal's Ctrl-C to
the process group) are ignored: the hub stops it.

It runs ``NICE`` steps below the hub's priority (its threads, the SDK's, inherit it): on a busy
computer (a robot's is never idle) the kernel gives the CPU to the devices' pipelines first, and the
viewers are what waits (each client's queue then loses its oldest messages, counted by the SDK).
"""

from __future__ import annotations

import logging
import os
import signal
import socket
import sys
import threading
import time
from typing import Any

from . import relay_wire as W

log = logging.getLogger("wott_hub.foxglove")

NICE = 10
"""How many steps of ``nice`` below the hub: its CPU weight is ~1/10 of the hub's threads' under load."""


class _Forward(logging.Handler):
    """This process's log records, to the hub (which writes them as its own)."""

    def __init__(self, relay: Relay) -> None:
        super().__init__()
        self.relay = relay

    def emit(self, record: logging.LogRecord) -> None:
        try:
            text = record.getMessage()
            if record.exc_info:
                text += "\n" + logging.Formatter().formatException(record.exc_info)
            self.relay.tell(W.LOGREC, (record.levelno, record.name, text))
        except Exception:  # the hub is gone: nothing to tell
            pass


class Relay:
    def __init__(self, down: socket.socket, up: socket.socket) -> None:
        self.sock = down  # what the hub sends
        self.up = up  # what this process tells it
        self._lock = threading.Lock()  # one writer at a time: the main thread, the ticker, the SDK's
        self.channels: dict[int, Any] = {}  # id -> foxglove.Channel
        self.sent = 0
        self.bytes = 0
        self.stopped = threading.Event()

    def tell(self, kind: int, value: Any) -> None:
        frame = W.control(kind, value)
        with self._lock:
            W.send(self.up, frame)

    def run(self) -> int:
        first = W.recv(self.sock)
        if first is None or first[0] != W.INIT:
            return 2
        opts = first[1]
        logging.basicConfig(level=opts["level"], handlers=[_Forward(self)], force=True)
        import foxglove
        from foxglove.websocket import ChannelView, Client, ServerListener

        from .guard import TICK_S, FoxgloveGuard
        from .nagle import disable_nagle

        relay = self

        class Listener(ServerListener):
            def on_subscribe(self, client: Client, channel: ChannelView) -> None:
                relay.tell(W.SUB, (channel.topic, 1))

            def on_unsubscribe(self, client: Client, channel: ChannelView) -> None:
                relay.tell(W.SUB, (channel.topic, -1))

        context = foxglove.Context()
        cert, key = opts["tls"] if opts["tls"] is not None else (None, None)
        try:
            server = foxglove.start_server(
                name=opts["name"], host=opts["host"], port=opts["port"], context=context,
                server_listener=Listener(), capabilities=[], message_backlog_size=opts["backlog"],
                tls_cert=cert, tls_key=key)
        except RuntimeError as e:  # the SDK's FoxgloveError: a port in use, an address not here
            self.tell(W.READY, {"error": str(e).removeprefix("FoxgloveError: ")})
            return 1
        port = int(server.port)
        guard = FoxgloveGuard(port, lambda: self.bytes, lambda fn, *args: fn(*args))
        guard.install()
        self.tell(W.READY, {"port": port, "nagle": disable_nagle(port) > 0})

        def tick() -> None:
            while not self.stopped.wait(TICK_S):
                try:
                    guard.tick()
                    self.tell(W.HEALTH, {**guard.health(), "sent": self.sent, "bytes": self.bytes})
                except OSError:  # the hub is gone
                    return
                except Exception:  # the guard's failure must not end the endpoint
                    log.exception("Foxglove: watching the clients failed")

        ticker = threading.Thread(target=tick, name="foxglove-guard", daemon=True)
        ticker.start()
        try:
            self._serve(context)
        finally:
            self.stopped.set()
            guard.uninstall()
            server.stop()
            for ch in self.channels.values():
                ch.close()
        return 0

    def _serve(self, context: Any) -> None:
        import foxglove

        channels = self.channels
        while True:
            try:
                frame = W.recv(self.sock)
            except OSError:
                return
            if frame is None or frame[0] == W.STOP:
                return
            kind, body = frame
            if kind == W.LOG:
                cid, t_ns, payload = body
                ch = channels.get(cid)
                if ch is not None:
                    ch.base.log(payload, t_ns, None)  # the fan-out: this process's GIL, not the hub's
                    self.sent += 1
                    self.bytes += len(payload)
            elif kind == W.CHANNEL:
                cid, topic, schema_name, schema_encoding, schema, encoding, metadata = body
                channels[cid] = foxglove.Channel(
                    topic, schema=foxglove.Schema(name=schema_name, encoding=schema_encoding, data=schema),
                    message_encoding=encoding, context=context, metadata=metadata)
            elif kind == W.CLOSE:
                ch = channels.pop(body, None)
                if ch is not None:
                    ch.close()


def main() -> int:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the hub's signals: the hub stops this process
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    try:
        os.nice(NICE)  # before any thread starts: the SDK's threads inherit it
    except OSError:  # not allowed (a hub already at the lowest priority): served as it is
        pass
    down, up = (socket.socket(fileno=int(fd)) for fd in sys.argv[1:3])
    started = time.monotonic()
    try:
        return Relay(down, up).run()
    except Exception as e:  # said to the hub's log if it still listens, else to stderr
        print(f"wott-hub Foxglove relay failed after {time.monotonic() - started:.1f} s: {e!r}",
              file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
