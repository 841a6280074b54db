"""What ``wott-hub config check`` and ``wott-hub run`` check beyond the tables themselves: each
device's settings against its family, the database URL and the files ``[security]`` names, and
(``--open``) each device opened through its plugin, its first frame read, and closed, without
serving it.

Why here and not when the hub starts: a hub started with a device whose settings are wrong
marks that device failed and keeps serving the others (a plugin's failure marks its device,
never the hub), which is right for a device that is unplugged but wrong for a typo a person
can fix before starting. ``run`` refuses to start on any problem found here; ``config check``
reports them all without starting anything.

Every problem of every device is reported, one line each: the JSON Schema each family
declares (``FamilyInfo.schema``, derived from its settings model) is checked with every error
kept (``iter_errors``), not the best one; the registry's own check (``Registry.validate``,
the model's bounds: NaN) runs on settings that pass it. An unknown setting says which
declared one it is probably a typo of. Lines read
``hub.toml: device[0].simulte (device 'pad', family 'taxel-array'): unknown setting; did
you mean 'simulate'?``.
"""

from __future__ import annotations

import asyncio
import copy
import difflib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from wott_hub.configspec import suggest
from wott_hub.errors import ConfigError, DriverError, WottHubError

if TYPE_CHECKING:
    from wott_hub.config import HubConfig
    from wott_hub.plugins import DeviceConfig
    from wott_hub.plugins.registry import Registry

__all__ = ["FIRST_FRAME_S", "OPEN_TIMEOUT_S", "DeviceCheck", "check_devices", "check_files", "check_usb",
           "open_devices"]

OPEN_TIMEOUT_S = 60.0
"""A device that has not opened (and closed) by then is reported as not opening: a check ends."""

FIRST_FRAME_S = 10.0
"""How long an opened device has to give its first frame (a simulator, a camera, a serial board)."""

_KINDS = {"number": "a number", "integer": "a whole number", "string": "a string", "boolean": "true or false",
          "array": "a list", "object": "a table", "null": "nothing"}


@dataclass
class DeviceCheck:
    """One ``[[device]]`` table: its problems (config errors), and with ``--open`` what opening it said."""

    id: str
    family: str
    where: str
    errors: list[str] = field(default_factory=list)
    opened: str | None = None  # what was opened: nodes, and the driver's description
    open_error: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"id": self.id, "family": self.family, "where": self.where, "errors": self.errors,
                "opened": self.opened, "open_error": self.open_error}


def check_devices(cfg: HubConfig, registry: Registry | None = None) -> list[DeviceCheck]:
    """Each configured device with every problem of its family and settings."""
    if registry is None:
        from wott_hub.plugins import get_registry

        registry = get_registry()
    families = registry.families()
    out = []
    for i, dev in enumerate(cfg.devices):
        check = DeviceCheck(dev.id, dev.family, f"{cfg.source}: device[{i}]")
        info = families.get(dev.family)
        if info is None:
            known = ", ".join(sorted(families)) or "none"
            check.errors.append(f"{check.where}.family: unknown family {dev.family!r}"
                                f"{suggest(dev.family, families)} (installed: {known})")
        else:
            check.errors += _settings_problems(dev, info.schema, check.where)
            if not check.errors:
                try:
                    registry.validate(dev)
                except WottHubError as e:
                    check.errors.append(f"{check.where}: {e}")
        out.append(check)
    return out


def _settings_problems(dev: DeviceConfig, schema: Any, where: str) -> list[str]:
    """Every problem of the settings; a misspelt key with a likely meaning is reported once, and what
    follows only from it (``port`` missing because ``simulate`` is spelt ``simulte``) is not: the
    rest is checked as if each such key were spelt as suggested."""
    from jsonschema import Draft202012Validator

    validator = Draft202012Validator(schema)
    typos: list[str] = []
    fixed = copy.deepcopy(dict(dev.settings))
    for error in validator.iter_errors(dev.settings):
        if error.validator == "additionalProperties" and isinstance(error.instance, Mapping):
            known = list(error.schema.get("properties") or {})
            table = _at(fixed, list(error.absolute_path))
            for key in [k for k in error.instance if k not in known]:
                close = difflib.get_close_matches(str(key), known, n=1, cutoff=0.6)
                if close and isinstance(table, dict) and close[0] not in table:
                    table[close[0]] = table.pop(key)
                    typos += _explain(dev, error, where, only=key)
    lines: list[str] = []
    for error in sorted(validator.iter_errors(fixed), key=lambda e: [str(p) for p in e.absolute_path]):
        lines += _explain(dev, error, where)
    return list(dict.fromkeys([*typos, *lines]))


def _at(data: Any, path: list[Any]) -> Any:
    for step in path:
        try:
            data = data[step]
        except (KeyError, IndexError, TypeError):
            return None
    return data


def _explain(dev: DeviceConfig, error: Any, where: str, only: Any = None) -> list[str]:
    """One jsonschema error as lines naming the setting, worded as the hub's config errors are
    (``only``: of an unknown-key error, the line of that key alone)."""
    path = list(error.absolute_path)
    about = f"(device {dev.id!r}, family {dev.family!r})"

    def place(steps: Sequence[Any]) -> str:
        return where + "".join(f"[{s}]" if isinstance(s, int) else f".{s}" for s in steps)

    instance, schema, kind = error.instance, error.schema, error.validator
    if kind == "additionalProperties" and isinstance(instance, Mapping):
        known = list(schema.get("properties") or {})
        return [f"{place([*path, key])} {about}: unknown setting"
                f"{suggest(str(key), known) or ' (known: ' + ', '.join(known) + ')'}"
                for key in instance if key not in known and (only is None or key == only)]
    if kind == "required" and isinstance(instance, Mapping):
        return [f"{place([*path, key])} {about}: required, missing"
                for key in error.validator_value if key not in instance]
    if kind in ("oneOf", "anyOf") and isinstance(instance, Mapping):
        names = [b["required"][0] for b in error.validator_value
                 if isinstance(b, Mapping) and len(b.get("required") or ()) == 1]
        if names and len(names) == len(error.validator_value):
            given = [n for n in names if n in instance]
            listed = " or ".join(repr(n) for n in names)
            rule = f"give only one of {listed}" if given else f"needs one of {listed}"
            return [f"{place(path)} {about}: {rule}"]
    if kind == "type":
        types = error.validator_value if isinstance(error.validator_value, list) else [error.validator_value]
        expected = " or ".join(_KINDS.get(str(t), str(t)) for t in types)
        return [f"{place(path)} {about}: {expected}, got {instance!r}"]
    if kind in ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum"):
        return [f"{place(path)} {about}: got {instance!r}; must be {_bounds(schema)}"]
    if kind == "enum":
        return [f"{place(path)} {about}: {instance!r} is not one of "
                f"{', '.join(str(v) for v in error.validator_value)}"]
    return [f"{place(path)} {about}: {error.message}"]


def _bounds(prop: Mapping[str, Any]) -> str:
    """The range of a number's schema, worded as ``wott_configspec.range_text`` words a model's."""
    ge, gt, le, lt = (prop.get(k) for k in ("minimum", "exclusiveMinimum", "maximum", "exclusiveMaximum"))

    def num(x: float) -> str:
        return str(int(x)) if float(x).is_integer() and abs(x) < 1e15 else f"{x:g}"

    if ge is not None and le is not None:
        return f"from {num(ge)} to {num(le)}"
    low = f"at least {num(ge)}" if ge is not None else f"above {num(gt)}" if gt is not None else ""
    high = f"at most {num(le)}" if le is not None else f"below {num(lt)}" if lt is not None else ""
    return " and ".join(p for p in (low, high) if p)


def check_usb(cfg: HubConfig, registry: Registry | None = None) -> list[str]:
    """``[usb] adopt``: each a family an installed plugin provides, with USB devices it can adopt."""
    if not cfg.usb.adopt:
        return []
    if registry is None:
        from wott_hub.plugins import get_registry

        registry = get_registry()
    from wott_hub.discovery.usb_config import check_adopt

    adoptable = [m.family for m in registry.usb_matches() if m.adoptable]
    return check_adopt(cfg.usb, registry.families(), adoptable, cfg.source)


def check_files(cfg: HubConfig) -> list[str]:
    """The rules across tables the hub applies when it is built (``config_rules``), and what the config
    names outside itself, read as the hub will read it: the history database's URL (its scheme and
    driver; a file path needs nothing), the token file, the TLS pair."""
    from wott_hub.config_rules import startup_problems

    sec = cfg.security
    out = startup_problems(cfg)  # what the hub refuses when it is built: `run` and `config check` alike
    if cfg.history and "://" in cfg.database:
        from wott_hub.errors import HistoryError
        from wott_hub.history.db import create_engine, database_url

        try:
            create_engine(database_url(cfg.database)).dispose()  # no connection is made
        except HistoryError as e:
            out.append(f"{cfg.source}: [hub].database: {e}")
    if sec.tokens_file:
        from wott_hub.security.tokens import TokenFile

        try:
            TokenFile(sec.tokens_file).load()
        except ConfigError as e:
            out.append(f"{cfg.source}: [security].tokens_file: {e}")
    if sec.cert and sec.key:
        from wott_hub.security.tls import server_context

        try:
            server_context(sec.cert, sec.key)
        except ConfigError as e:
            out.append(f"{cfg.source}: {e}")
    return out


async def open_devices(checks: Sequence[DeviceCheck], cfg: HubConfig, registry: Registry | None = None,
                       timeout_s: float = OPEN_TIMEOUT_S, frame_s: float = FIRST_FRAME_S) -> None:
    """Open each device without problems through its plugin (``prepare``: model files...), read its
    first frame (the port, the camera, the stream: a driver may open those only when it reads),
    note what it is, and close it; one at a time, as a person reads the report."""
    from wott_hub.plugins.isolation import attempt_async
    from wott_hub.runtime.opening import CLOSE_TIMEOUT_S, open_driver

    by_id = {d.id: d for d in cfg.devices}
    for check in checks:
        if check.errors:
            continue
        try:
            driver = await asyncio.wait_for(open_driver(by_id[check.id], registry), timeout_s)
        except TimeoutError:
            check.open_error = f"did not open within {timeout_s:g} s"
            continue
        except DriverError as e:
            check.open_error = str(e)
            continue
        desc = driver.description
        what = f"{desc.mesh.n_nodes} nodes, shape {desc.shape.shape_type}"
        first = await _first_frame(driver, frame_s)
        if first is None:
            check.opened = f"{what}, first frame read"
        else:
            check.open_error = f"opened ({what}) but {first}"
        closed = await attempt_async("close()", driver.close, timeout_s=CLOSE_TIMEOUT_S)
        if closed.fault is not None and check.open_error is None:
            check.open_error = f"opened, but {closed.fault.reason}"


async def _first_frame(driver: Any, within_s: float) -> str | None:
    """None once the driver yields a frame; else what went wrong (its health says why)."""
    frames = driver.frames()
    try:
        await asyncio.wait_for(anext(frames), within_s)
        return None
    except TimeoutError:
        health = driver.health()
        return f"no frame within {within_s:g} s ({health.state}: {health.reason})"
    except StopAsyncIteration:
        return "its frames() ended without a frame"
    except Exception as e:  # the plugin's: reported as the device's, as the hub would
        return f"frames() raised {type(e).__name__}: {e}"
    finally:
        try:
            await asyncio.wait_for(frames.aclose(), 5)
        except Exception:  # noqa: S110 -- a stream that will not stop is closed with its driver next
            pass
