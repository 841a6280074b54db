"""The one way the hub calls into plugin code: a failure stays with its owner.

Plugin code is anything a third party wrote: a hook (``wott_hub_*``) or a
driver's ``open``/``prepare``/``frames``/``health``/``close``. Whatever it
raises (``Exception``, and ``SystemExit``, which a careless plugin may call),
the caller gets a ``Fault`` instead of the exception, so the failure cannot
reach the hub Thing's properties, the fleet's routes or a watcher task. What
a fault marks is the caller's choice: the plugin's record for a hook, the one
device for a driver call.

``attempt``/``attempt_async`` run one call and return an ``Outcome``.
``Guard`` adds what a long-lived owner (a device, a watcher) needs: the
traceback is logged once per distinct failure, a failure repeated every
second (``health()`` read by the watcher) is not logged again except as a
one-line reminder every ``remind_s``, and the current faults are kept to
report (``Guard.faults``). ``KeyboardInterrupt`` and ``asyncio.CancelledError``
pass: they are the hub stopping, not the plugin failing.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

from .loader import describe_exception

__all__ = ["Fault", "Guard", "Outcome", "attempt", "attempt_async"]

T = TypeVar("T")

log = logging.getLogger("wott_hub.plugins")

CAUGHT = (Exception, SystemExit)
"""What plugin code may raise and the hub survives (``SystemExit``: a plugin calling ``sys.exit``)."""


@dataclass(frozen=True)
class Fault:
    """One failed call: ``reason`` is ``"<what> raised <Type>: <message>"``, the text a device's
    health shows; ``detail`` adds the plugin's file and line (``loader.describe_exception``)."""

    what: str
    reason: str
    detail: str
    error: BaseException

    @classmethod
    def of(cls, what: str, error: BaseException) -> Fault:
        if isinstance(error, TimeoutError) and not str(error):
            return cls(what, f"{what} did not return in time", f"{what} did not return in time", error)
        text = f"{type(error).__name__}: {error}".rstrip(": ")
        return cls(what, f"{what} raised {text}", describe_exception(error), error)


@dataclass(frozen=True)
class Outcome(Generic[T]):
    """What a call returned (``value``), or why it did not (``fault``)."""

    value: T | None = None
    fault: Fault | None = None

    @property
    def ok(self) -> bool:
        return self.fault is None


def attempt(what: str, fn: Callable[..., T], *args: Any, **kwargs: Any) -> Outcome[T]:
    """Call ``fn(*args, **kwargs)``, plugin code; a failure becomes the outcome's ``fault``."""
    try:
        return Outcome(fn(*args, **kwargs))
    except CAUGHT as e:
        return Outcome(fault=Fault.of(what, e))


async def attempt_async(what: str, fn: Callable[..., Awaitable[T]], *args: Any,
                        timeout_s: float | None = None, **kwargs: Any) -> Outcome[T]:
    """``attempt`` for a coroutine function; ``timeout_s``: a call that does not return in time
    (a ``close()`` that hangs) is a fault too, and is cancelled."""
    try:
        if timeout_s is None:
            return Outcome(await fn(*args, **kwargs))
        return Outcome(await asyncio.wait_for(fn(*args, **kwargs), timeout_s))
    except asyncio.CancelledError:
        raise
    except CAUGHT as e:
        return Outcome(fault=Fault.of(what, e))


class Guard:
    """The calls into plugin code made for one owner (a device, a watcher), with their faults.

    ``faults``: what is failing now, by ``what`` (``"health()"`` -> its ``Fault``),
    cleared by the next call of the same ``what`` that succeeds.
    """

    def __init__(self, owner: str, *, logger: logging.Logger | None = None, remind_s: float = 60.0) -> None:
        self.owner = owner
        self.faults: dict[str, Fault] = {}
        self._log = logger or log
        self._remind_s = remind_s
        self._logged: dict[str, tuple[str, float, int]] = {}  # what -> (reason, when logged, repeats since)

    def call(self, what: str, fn: Callable[..., T], *args: Any, **kwargs: Any) -> Outcome[T]:
        out = attempt(what, fn, *args, **kwargs)
        self._settle(what, out)
        return out

    async def call_async(self, what: str, fn: Callable[..., Awaitable[T]], *args: Any,
                         timeout_s: float | None = None, **kwargs: Any) -> Outcome[T]:
        out = await attempt_async(what, fn, *args, timeout_s=timeout_s, **kwargs)
        self._settle(what, out)
        return out

    def failed(self, what: str, error: BaseException, *, retry_s: float | None = None) -> Fault:
        """Record a failure the caller caught itself (a ``frames()`` iteration raising)."""
        fault = Fault.of(what, error)
        self.faults[what] = fault
        self._report(fault, retry_s)
        return fault

    def succeeded(self, what: str) -> None:
        self.faults.pop(what, None)

    def _settle(self, what: str, out: Outcome[Any]) -> None:
        if out.fault is None:
            self.faults.pop(what, None)
        else:
            self.faults[what] = out.fault
            self._report(out.fault, None)

    def _report(self, fault: Fault, retry_s: float | None) -> None:
        """The traceback once per distinct failure; the same failure again only as a reminder."""
        now = time.monotonic()
        last = self._logged.get(fault.what)
        retry = f"; retrying in {retry_s:.1f} s" if retry_s is not None else ""
        if last is None or last[0] != fault.reason:
            self._logged[fault.what] = (fault.reason, now, 0)
            self._log.error("%s: %s%s", self.owner, fault.reason, retry,
                            exc_info=(type(fault.error), fault.error, fault.error.__traceback__))
            return
        reason, when, repeats = last
        if now - when >= self._remind_s:
            self._log.warning("%s: still failing, %d times since last logged: %s%s",
                              self.owner, repeats + 1, reason, retry)
            self._logged[fault.what] = (reason, now, 0)
        else:
            self._logged[fault.what] = (reason, when, repeats + 1)
