"""``serve``: run a hub until SIGINT/SIGTERM, for ``wott-hub run`` and embedding programs.

Signals are handled from ``serve``'s first instruction to its last (issue 33):

- The first SIGINT or SIGTERM, at any moment, stops the hub: during start-up it cancels the start
  (``Hub.stop`` then stops what had started), afterwards it ends the wait. The handlers stay in
  place during the stop: a signal then is never the interpreter's ``KeyboardInterrupt`` cutting
  the stop sequence short (it would skip clearing the MQTT retained state, writing history...).
- The same request arriving twice is one request: a signal within ``COALESCE_S`` of the last one
  counted is ignored. ``uv run`` forwards to the hub the signal it got from the process group,
  which the hub got too: through ``uv``, every Ctrl-C and every SIGTERM arrives twice.
- A second request during the stop hurries it (``Hub.hurry``: history stops waiting for the
  database and spools what it cannot write, exports are cancelled); the stop sequence runs on,
  in order, and has ``HURRY_S`` more to end. A third request ends the process at once
  (``os._exit``). Either way what could not be recorded is said, never dropped without a word.
- Every stop is bounded: past ``STOP_S`` ``serve`` hurries the stop itself, and past
  ``STOP_S + HURRY_S`` it stops waiting and says what is left.
- A process that a signal asked to stop ends: ``EXIT_S`` after ``serve`` returns, a daemon thread
  ends it (``os._exit``) if Python's own shutdown still waits for some thread (a plugin's, a
  library's) that does not end. An embedding program that must live on passes ``exit_s=None``.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

from wott_hub.config import HubConfig

from .collector import tune_for_hub
from .lifecycle import Hub

__all__ = ["COALESCE_S", "EXIT_S", "HURRY_S", "STOP_S", "serve"]

log = logging.getLogger("wott_hub.hub")

COALESCE_S = 1.0
"""A signal this soon after the last one counted is the same request (``uv run`` forwards each)."""
STOP_S = 30.0
"""A stop that takes longer is hurried (as by a second Ctrl-C)."""
HURRY_S = 5.0
"""A hurried stop gets this long more before ``serve`` stops waiting for it."""
EXIT_S = 5.0
"""After a stop a signal asked for, the process ends at most this long after ``serve`` returns."""

_SIGNALS = (signal.SIGINT, signal.SIGTERM)


async def serve(config: HubConfig, *, ready: Callable[[Hub], None] | None = None,
                stop: asyncio.Event | None = None, extra_handlers: Sequence[tuple[Any, ...]] = (),
                exit_s: float | None = EXIT_S) -> Hub:
    """Run a hub until SIGINT/SIGTERM (or ``stop``), then shut it down cleanly, within bounds.

    With ``demo`` and no devices configured, the demo fleet (``plugins.demo.demo_devices``).
    ``exit_s``: after a stop a signal asked for, end the process if it has not ended this long
    after ``serve`` returned (None: never; for a program that goes on after a signal).
    """
    signals = _Signals(asyncio.get_running_loop(), stop)  # the first instruction: no signal is lost
    hub: Hub | None = None
    try:
        if config.demo and not config.devices:
            from dataclasses import replace

            from wott_hub.plugins.demo import demo_devices

            config = replace(config, devices=tuple(demo_devices()))
        hub = Hub(config, extra_handlers=extra_handlers)
        signals.hub = hub
        if await signals.until_stop(hub.start()):
            tune_for_hub()
            if ready is not None:
                ready(hub)
            await signals.until_stop(None)
    finally:
        if hub is not None:
            await _stop(hub, signals)
        signals.remove(exit_s)
    return hub


async def _stop(hub: Hub, signals: _Signals) -> None:
    """``hub.stop()``, hurried after a second request or ``STOP_S``, given up after ``HURRY_S`` more."""
    task = asyncio.ensure_future(hub.stop())
    hurry = asyncio.ensure_future(signals.hurry.wait())
    try:
        await asyncio.wait({task, hurry}, timeout=STOP_S, return_when=asyncio.FIRST_COMPLETED)
        if not task.done():
            if not hurry.done():
                log.warning("the hub has not stopped within %.0f s: stopping without waiting for the "
                            "database", STOP_S)
            hub.hurry()
            await asyncio.wait({task}, timeout=HURRY_S)
        if not task.done():
            log.error("the hub did not stop within %.0f s more; %s", HURRY_S, _what_is_left(hub)[0])
            task.cancel()
            return
        error = task.exception()
        if error is not None:
            log.error("stopping the hub failed: %s: %s", type(error).__name__, error)
        report, notable = _what_is_left(hub)
        if signals.hurried or notable:
            log.warning("stopped; %s", report)
    finally:
        hurry.cancel()


def _what_is_left(hub: Hub) -> tuple[str, bool]:
    """What became of the records (written, waiting in the spool, not recorded), and whether any
    did not reach the database."""
    try:
        history = hub.health().get("history") or {}
    except Exception as e:  # a report must not fail the stop
        return f"history state unknown ({type(e).__name__}: {e})", True
    if not history.get("enabled"):
        return "history is off", False
    parts = [f"{history.get('written', 0)} records written to history"]
    spool = history.get("spool") or {}
    if spool.get("records"):
        parts.append(f"{spool['records']} wait in the spool {spool.get('path')} (written when the database "
                     "answers, at the next start)")
    lost = history.get("dropped", 0) + history.get("queued", 0)
    if lost:
        parts.append(f"{lost} not recorded")
    return "; ".join(parts), bool(spool.get("records") or lost)


class _Signals:
    """SIGINT/SIGTERM for the life of ``serve``: requests counted (repeats within ``COALESCE_S``
    are one), the first sets ``requested``, the second ``hurry``, the third ends the process."""

    def __init__(self, loop: asyncio.AbstractEventLoop, stop: asyncio.Event | None) -> None:
        self.loop = loop
        self.requested = stop or asyncio.Event()
        self.hurry = asyncio.Event()
        self.hub: Hub | None = None
        self.count = 0
        self.signum = 0
        self._last = -1e9
        self._installed: list[signal.Signals] = []
        for sig in _SIGNALS:
            with contextlib.suppress(NotImplementedError, RuntimeError, ValueError):  # not the main thread
                loop.add_signal_handler(sig, self._got, sig)
                self._installed.append(sig)

    @property
    def hurried(self) -> bool:
        return self.hurry.is_set()

    def _got(self, sig: signal.Signals) -> None:
        now = time.monotonic()
        if now - self._last < COALESCE_S:
            return  # the same request again (uv run forwards what the process group got)
        self._last = now
        self.count += 1
        self.signum = self.signum or int(sig)
        name = signal.Signals(sig).name
        if self.count == 1:
            log.info("%s: stopping (again to stop without waiting for the database)", name)
            self.requested.set()
        elif self.count == 2:
            log.warning("%s again: stopping without waiting for the database (again to exit at once)", name)
            self.requested.set()
            self.hurry.set()
        else:
            left = _what_is_left(self.hub)[0] if self.hub is not None else "nothing started"
            _exit_now(128 + int(sig), f"{name} a third time: exiting at once; {left}")

    async def until_stop(self, work: Any) -> bool:
        """Run ``work`` (a coroutine, or None: nothing) until a stop is requested; True if it ended
        first (its error raised), False if the request came first (``work`` cancelled)."""
        waiting = asyncio.ensure_future(self.requested.wait())
        task = asyncio.ensure_future(work) if work is not None else None
        try:
            await asyncio.wait({waiting} | ({task} if task is not None else set()),
                               return_when=asyncio.FIRST_COMPLETED)
            if task is not None and task.done():
                task.result()
                return True
            if task is not None:  # start-up interrupted: what it started, Hub.stop stops
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await task
            return False
        finally:
            waiting.cancel()
            if task is not None and not task.done():
                task.cancel()

    def remove(self, exit_s: float | None) -> None:
        """Put the handlers back; after a stop a signal asked for, the process must end: a later
        signal ends it at once, and a watchdog ends it ``exit_s`` from now if it is still there."""
        for sig in self._installed:
            with contextlib.suppress(RuntimeError, ValueError):
                self.loop.remove_signal_handler(sig)
        if not self.count or exit_s is None:
            return
        for sig in self._installed:
            with contextlib.suppress(ValueError):
                signal.signal(sig, _exit_on_signal)
        code = 128 + self.signum
        threading.Thread(target=_watchdog, args=(exit_s, code), name="wott-hub-exit", daemon=True).start()


def _exit_on_signal(signum: int, _frame: object) -> None:
    _exit_now(128 + signum, f"{signal.Signals(signum).name} while exiting: exiting at once")


def _watchdog(after_s: float, code: int) -> None:
    time.sleep(after_s)
    me = threading.current_thread()
    names = sorted(t.name for t in threading.enumerate() if t is not me and t.is_alive())
    _exit_now(code, f"the process had not ended {after_s:.0f} s after the hub stopped (threads still "
                    f"running: {', '.join(names) or 'none'}): exiting")


def _exit_now(code: int, message: str) -> None:
    """Say why, then end the process without waiting for anything."""
    with contextlib.suppress(Exception):
        log.error("%s", message)
        for stream in (sys.stdout, sys.stderr):
            stream.flush()
    os._exit(code)
