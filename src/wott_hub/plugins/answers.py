"""The registry's hooks whose answers are lists or claims, each answer checked before it is used.

A plugin's ``wott_hub_demo_devices``, ``wott_hub_claim_td`` and ``wott_hub_usb_devices`` may return
anything; what is not what the hook promises (a non-list, a ``DeviceConfig`` of a family it does
not provide, a ``UsbMatch`` that can never match) is recorded against that plugin and left out,
and the other plugins' answers stand. Called through ``Registry``'s methods of the same names,
with the registry's one-plugin-at-a-time calls (``call_each``), error record (``record_error``) and
plugin order (``plugin_names``); split from ``registry.py`` to keep each module to one job.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import Any, Protocol

from .model import DeviceConfig, FamilyInfo, UsbMatch


class Registry(Protocol):
    """What of ``registry.Registry`` these checks use (a protocol: no import of it, no cycle)."""

    def plugin_names(self) -> list[str]: ...

    def call_each(self, hook: str, copy_args: bool = False, **kwargs: Any) -> Iterator[tuple[str, Any]]: ...

    def record_error(self, plugin: str, hook: str, message: str) -> None: ...

    def families(self) -> dict[str, FamilyInfo]: ...

__all__ = ["claim", "demo_devices", "usb_matches"]


def demo_devices(reg: Registry) -> list[DeviceConfig]:
    """Each plugin's simulated demo devices, for ``wott-hub run`` without a config."""
    hook = "wott_hub_demo_devices"
    families = reg.families()
    out: list[DeviceConfig] = []
    ids: set[str] = set()
    for name, result in reg.call_each(hook):
        if not isinstance(result, list | tuple):
            reg.record_error(name, hook, f"returned {type(result).__name__}, not a list of DeviceConfig")
            continue
        for cfg in result:
            if not isinstance(cfg, DeviceConfig):
                reg.record_error(name, hook, f"returned a {type(cfg).__name__}, not a DeviceConfig")
            elif cfg.family not in families or families[cfg.family].plugin != name:
                reg.record_error(name, hook, f"demo device {cfg.id!r} names family {cfg.family!r}, "
                                              "which this plugin does not provide")
            elif cfg.id in ids:
                reg.record_error(name, hook, f"demo device id {cfg.id!r} is already taken")
            else:
                ids.add(cfg.id)
                out.append(cfg)
    return out


def claim(reg: Registry, td: Mapping[str, Any]) -> DeviceConfig | None:
    """The device config of the first plugin that adopts a foreign TD (``wott_hub_claim_td``), or None."""
    hook = "wott_hub_claim_td"
    families = reg.families()
    for name, result in reg.call_each(hook, copy_args=True, td=dict(td)):
        if result is None:
            continue
        if not isinstance(result, DeviceConfig):
            reg.record_error(name, hook, f"returned {type(result).__name__}, not a DeviceConfig")
        elif result.family not in families:
            reg.record_error(name, hook, f"claimed a device for unknown family {result.family!r}")
        else:
            return result
    return None


def usb_matches(reg: Registry) -> list[UsbMatch]:
    """Every plugin's USB matches (``wott_hub_usb_devices``), in registration order (built-ins first);
    a declaration that can never match is recorded against its plugin and left out, a repeated
    one kept once."""
    hook = "wott_hub_usb_devices"
    answers: dict[str, list[Any]] = {}
    for name, result in reg.call_each(hook):
        answers.setdefault(name, []).append(result)
    out: list[UsbMatch] = []
    for name in [n for n in reg.plugin_names() if n in answers]:
        for result in answers[name]:
            if not isinstance(result, list | tuple):
                reg.record_error(name, hook, f"returned {type(result).__name__}, not a list of UsbMatch")
                continue
            _accept_usb(reg, name, result, out)
    return out


def _accept_usb(reg: Registry, name: str, result: list[Any] | tuple[Any, ...], out: list[UsbMatch]) -> None:
    hook = "wott_hub_usb_devices"
    for match in result:
        if not isinstance(match, UsbMatch):
            reg.record_error(name, hook, f"returned a {type(match).__name__}, not a UsbMatch")
        elif (problem := match.problem()) is not None:
            reg.record_error(name, hook, f"USB match for family {match.family!r}: {problem}")
        elif match not in out:
            out.append(match)
