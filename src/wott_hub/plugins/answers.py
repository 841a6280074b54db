"""What a plugin's hook answered, checked against what the hook promises: the accepted part and, for
each thing refused, why (the registry records those against the plugin; no hook is called here)."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from .model import DeviceConfig, FamilyInfo, UsbMatch
from .settings import settings_schema

__all__ = ["checked_demo_devices", "checked_families", "checked_usb_matches"]


def checked_families(result: Any) -> tuple[list[tuple[FamilyInfo, type | None]], list[str]]:
    """(each family with its JSON Schema filled in and its settings model if it gave one, problems)."""
    from jsonschema import Draft202012Validator
    from jsonschema.exceptions import SchemaError

    if not isinstance(result, list | tuple):
        return [], [f"returned {type(result).__name__}, not a list of FamilyInfo"]
    accepted: list[tuple[FamilyInfo, type | None]] = []
    problems: list[str] = []
    for fam in result:
        if not isinstance(fam, FamilyInfo):
            problems.append(f"returned a {type(fam).__name__}, not a FamilyInfo")
            continue
        model = fam.schema if isinstance(fam.schema, type) else None
        if model is not None:  # a settings model: its JSON Schema for docs and the first check
            try:
                fam = replace(fam, schema=settings_schema(model))
            except Exception as e:
                problems.append(f"family {fam.name!r}: invalid settings model: {e}")
                continue
        try:
            Draft202012Validator.check_schema(fam.schema)  # type: ignore[arg-type]  # a dict by now
        except SchemaError as e:
            problems.append(f"family {fam.name!r}: invalid settings schema: {e.message}")
            continue
        accepted.append((fam, model))
    return accepted, problems


def checked_usb_matches(result: Any) -> tuple[list[UsbMatch], list[str]]:
    """(the matches that can match, problems)."""
    if not isinstance(result, list | tuple):
        return [], [f"returned {type(result).__name__}, not a list of UsbMatch"]
    accepted: list[UsbMatch] = []
    problems: list[str] = []
    for match in result:
        if not isinstance(match, UsbMatch):
            problems.append(f"returned a {type(match).__name__}, not a UsbMatch")
        elif (problem := match.problem()) is not None:
            problems.append(f"USB match for family {match.family!r}: {problem}")
        else:
            accepted.append(match)
    return accepted, problems


def checked_demo_devices(result: Any, plugin: str, families: dict[str, FamilyInfo],
                         taken: set[str]) -> tuple[list[DeviceConfig], list[str]]:
    """(the demo devices of ``plugin``'s own families whose ids are not ``taken``, problems)."""
    if not isinstance(result, list | tuple):
        return [], [f"returned {type(result).__name__}, not a list of DeviceConfig"]
    accepted: list[DeviceConfig] = []
    problems: list[str] = []
    for cfg in result:
        if not isinstance(cfg, DeviceConfig):
            problems.append(f"returned a {type(cfg).__name__}, not a DeviceConfig")
        elif cfg.family not in families or families[cfg.family].plugin != plugin:
            problems.append(f"demo device {cfg.id!r} names family {cfg.family!r}, "
                            "which this plugin does not provide")
        elif cfg.id in taken or any(c.id == cfg.id for c in accepted):
            problems.append(f"demo device id {cfg.id!r} is already taken")
        else:
            accepted.append(cfg)
    return accepted, problems
