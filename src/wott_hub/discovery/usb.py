"""USB devices the plugins know, found through udev: those present now, and those plugged in and out.

The plugins say which devices are theirs (``wott_hub_usb_devices``: ``UsbMatch`` rules on udev
properties); this module applies the rules to what udev knows. ``identify`` is the rule (no I/O,
properties in, a ``UsbDevice`` out); ``scan`` lists the devices present (``wott-hub discover
--usb``); ``UsbMonitor`` follows udev's events (a pyudev ``MonitorObserver``: its own thread, each
event handed to the asyncio loop with ``call_soon_threadsafe``), which the hub's ``[usb] adopt``
(``wott_hub.hub.usb``) acts on.

Which node: a camera exposes a capture node and a metadata node (``ID_V4L_CAPABILITIES``
``:capture:`` on the first only): only a capture node is a device. Which id: the device's Thing
id is ``<prefix>-<ID_SERIAL_SHORT>`` (a DIGIT ``digit-D20001``): the same board gets the same
Thing, whatever port it is in; a device without a serial number is named after its node
(``anyskin-ttyACM0``), which holds only while it stays in the same port. Which family, when
several plugins claim one device (an FTDI bridge is a 3D-ViTac board's or an slcan adapter's): the
first match whose family is adopted, else the first one; the others are listed beside it.

pyudev (and libudev under it) is imported only here, when asked: no udev (not Linux, a container
without /sys or /run/udev) is a ``UdevUnavailable`` with one line saying so, never a traceback.
"""

from __future__ import annotations

import asyncio
import logging
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from wott_hub.errors import DriverError
from wott_hub.plugins.model import DeviceConfig, UsbMatch, device_id_from

__all__ = ["UdevUnavailable", "UsbDevice", "UsbEvent", "UsbMonitor", "identify", "scan", "udev_context"]

log = logging.getLogger("wott_hub.discovery")


class UdevUnavailable(DriverError):
    """udev cannot be read here (pyudev or libudev missing, no /sys): USB devices cannot be found."""


@dataclass(frozen=True)
class UsbDevice:
    """One device node a plugin's ``UsbMatch`` claims (``match``; ``others``: further claims)."""

    match: UsbMatch
    sys_path: str
    node: str
    vendor_id: str
    product_id: str
    serial: str
    others: tuple[UsbMatch, ...] = ()

    @property
    def family(self) -> str:
        return self.match.family

    @property
    def thing_id(self) -> str:
        """``<prefix>-<serial>``, or ``<prefix>-<node name>`` without a serial (module docstring)."""
        prefix = self.match.id_prefix or self.match.family
        return device_id_from(f"{prefix}-{self.serial or os.path.basename(self.node)}", prefix)

    @property
    def adoptable(self) -> bool:
        return self.match.adoptable

    def config(self) -> DeviceConfig:
        """The device config it is adopted with: the match's settings, its node as the match's setting."""
        setting = self.match.setting
        assert setting is not None, "a listed-only match is never adopted"
        return DeviceConfig(self.thing_id, self.family, {**self.match.settings, setting: self.node})

    def to_dict(self, adopted: bool = False) -> dict[str, Any]:
        return {"family": self.family, "label": self.match.label,
                "usb": f"{self.vendor_id}:{self.product_id}",
                "serial": self.serial, "node": self.node, "id": self.thing_id, "adopted": adopted,
                "adoptable": self.adoptable, "also": [m.family for m in self.others],
                "sys_path": self.sys_path}


@dataclass(frozen=True)
class UsbEvent:
    """A udev event on a device node: ``action`` is ``add`` or ``remove``; ``device`` the node's match
    (None: no plugin claims it)."""

    action: str
    sys_path: str
    device: UsbDevice | None = field(default=None)


def _serial(subsystem: str, props: Mapping[str, str]) -> str:
    serial = props.get("ID_SERIAL_SHORT", "")
    if not serial and subsystem == "video4linux":
        # A Mini has no USB serial: it is the last word of its product string, which the V4L2 name
        # (uvcvideo: "<product>: <product>", cut to 31 characters) begins with.
        words = props.get("ID_V4L_PRODUCT", "").split(":")[0].split()
        serial = words[-1] if len(words) > 2 else ""
    return serial


def identify(subsystem: str, sys_path: str, properties: Mapping[str, str], matches: Sequence[UsbMatch],
             adopt: Iterable[str] = ()) -> UsbDevice | None:
    """The ``UsbDevice`` of a udev device node (its ``subsystem``, sysfs path and properties), or None
    when no match claims it or it is not a device of its own (a camera's metadata node)."""
    node = properties.get("DEVNAME", "")
    if not node:
        return None
    if subsystem == "video4linux" and "ID_V4L_CAPABILITIES" in properties \
            and ":capture:" not in properties["ID_V4L_CAPABILITIES"]:
        return None
    claims = [m for m in matches if m.matches(subsystem, properties)]
    if not claims:
        return None
    wanted = set(adopt)
    chosen = next((m for m in claims if m.family in wanted and m.adoptable), claims[0])
    others = tuple(dict.fromkeys(m.family for m in claims if m.family != chosen.family))
    return UsbDevice(chosen, sys_path, node, properties.get("ID_VENDOR_ID", "").lower(),
                     properties.get("ID_MODEL_ID", "").lower(), _serial(subsystem, properties),
                     tuple(next(m for m in claims if m.family == f) for f in others))


def udev_context() -> Any:
    """A pyudev ``Context``; ``UdevUnavailable`` (one line) when udev cannot be read here."""
    try:
        import pyudev
    except ImportError as e:  # not Linux (the dependency is Linux-only), or libudev is missing
        raise UdevUnavailable(f"udev is unavailable: {e}; USB devices can be listed on Linux only") from None
    if not os.path.isdir("/sys/class"):  # a container without sysfs: libudev would list nothing, silently
        raise UdevUnavailable("udev is unavailable: /sys is not mounted here, so no USB device can be seen")
    try:
        return pyudev.Context()
    except Exception as e:  # libudev not loadable (ImportError inside pyudev's ctypes) or refusing
        raise UdevUnavailable(f"udev is unavailable: {type(e).__name__}: {e}") from None


def _props(device: Any) -> dict[str, str]:
    return {str(k): str(v) for k, v in device.properties.items()}


def _devices_of(context: Any) -> Iterable[tuple[str, str, dict[str, str]]]:
    for subsystem in ("video4linux", "tty"):
        for device in context.list_devices(subsystem=subsystem):
            yield subsystem, str(device.sys_path), _props(device)


def scan(matches: Sequence[UsbMatch], adopt: Iterable[str] = (), context: Any = None) -> list[UsbDevice]:
    """The devices present now that a match claims, one per Thing id (a camera's first capture node),
    by family then node."""
    context = context if context is not None else udev_context()
    adopt = tuple(adopt)
    try:
        found = [identify(sub, path, props, matches, adopt) for sub, path, props in _devices_of(context)]
    except OSError as e:
        raise UdevUnavailable(f"udev is unavailable: cannot list devices: {e}") from None
    out: dict[str, UsbDevice] = {}
    for dev in sorted((d for d in found if d is not None), key=lambda d: (d.family, _node_order(d.node))):
        out.setdefault(dev.thing_id, dev)
    return list(out.values())


def _node_order(node: str) -> tuple[str, int]:
    """/dev/video2 before /dev/video10."""
    head = node.rstrip("0123456789")
    tail = node[len(head):]
    return head, int(tail) if tail else -1


class UsbMonitor:
    """udev's add and remove events on video4linux and tty nodes, handed to ``on_event`` on ``loop``.

    pyudev's ``MonitorObserver`` reads the netlink socket in its own thread; each event is turned
    into a ``UsbEvent`` there (``identify``: no I/O) and passed to the loop with
    ``call_soon_threadsafe``, so ``on_event`` runs on the loop's thread only. ``start`` before
    ``scan``: a device plugged in between the two is then seen twice, never missed.
    """

    def __init__(self, matches: Sequence[UsbMatch], adopt: Iterable[str], loop: asyncio.AbstractEventLoop,
                 on_event: Callable[[UsbEvent], None], context: Any = None) -> None:
        self.matches = list(matches)
        self.adopt = tuple(adopt)
        self.loop = loop
        self.on_event = on_event
        self.context = context
        self._observer: Any = None

    def start(self) -> None:
        import pyudev

        context = self.context if self.context is not None else udev_context()
        self.context = context
        try:
            monitor = pyudev.Monitor.from_netlink(context)
            monitor.filter_by("video4linux")
            monitor.filter_by("tty")
            monitor.start()
        except OSError as e:
            raise UdevUnavailable(f"udev is unavailable: cannot follow its events: {e}") from None
        self._observer = pyudev.MonitorObserver(monitor, callback=self._seen, name="usb-monitor")
        self._observer.daemon = True
        self._observer.start()

    def _seen(self, device: Any) -> None:
        """On the observer's thread: one udev event."""
        action = str(device.action or "")
        if action not in ("add", "remove"):
            return
        subsystem, path = str(device.subsystem or ""), str(device.sys_path)
        try:
            found = identify(subsystem, path, _props(device), self.matches, self.adopt)
        except Exception:  # a property udev sends oddly must not end the observer's thread
            log.exception("USB event on %s not understood", path)
            return
        event = UsbEvent(action, path, found)
        try:
            self.loop.call_soon_threadsafe(self.on_event, event)
        except RuntimeError:  # the loop is closed: the hub is stopping
            pass

    def stop(self) -> None:
        observer, self._observer = self._observer, None
        if observer is not None:
            observer.send_stop()
            observer.join(timeout=5)
