"""The registry: the loaded plugins, the families they provide, and devices opened through them.

Each hook is called with pluggy, but one plugin at a time (a subset hook
caller holding only that plugin), in pluggy's own call order. A plugin whose
hook raises, or returns something that is not what the hook promises, gets
the error recorded against it and is skipped for that call; the other
plugins' results stand. One plugin cannot take down the hub. Every hook call
goes through ``isolation.attempt``, the mechanism the hub uses for every call
into a driver too; each distinct error is logged once (with its traceback). The checks of the
hooks that answer with lists or claims (demo devices, foreign TDs, USB matches) are in
``answers.py``.
"""

from __future__ import annotations

import copy
import logging
import threading
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import pluggy

from wott_hub.drivers.base import Driver, DriverError
from wott_hub.errors import SettingsError

from . import answers, hookspecs
from .dict_schema import with_defaults
from .isolation import Fault, attempt
from .loader import ENTRY_POINT_GROUP, describe_exception, discover, selected_names
from .model import DeviceConfig, FamilyInfo, PluginInfo, UsbMatch
from .settings import model_settings, settings_schema

if TYPE_CHECKING:
    from jsonschema.exceptions import SchemaError
    from jsonschema.protocols import Validator

__all__ = ["BUILTIN_PLUGINS", "Registry", "get_registry", "loaded_registry", "reset_registry"]

log = logging.getLogger("wott_hub.plugins")

# Plugins inside the core package (like datasette's default plugins): always loaded.
BUILTIN_PLUGINS = {"builtin": "wott_hub.plugins.builtin"}

_FROM_ENV: Any = object()
_MAX_ERRORS_PER_HOOK = 5


@dataclass
class _Record:
    name: str
    distribution: str | None
    version: str | None
    plugin: Any = None
    families: list[str] = field(default_factory=list)
    errors: dict[str, list[str]] = field(default_factory=dict)  # "load" / "register" / hook -> messages


class Registry:
    """The plugins of one hub. Build it with ``get_registry()`` unless a test needs its own.

    ``only`` limits the entry-point plugins imported (names as in
    ``WOTT_HUB_PLUGINS``, which is read when ``only`` is not given); the
    built-in plugins are always registered.
    """

    def __init__(
        self,
        *,
        only: Iterable[str] | None = _FROM_ENV,
        entry_points: bool = True,
        builtins: bool = True,
        group: str = ENTRY_POINT_GROUP,
    ) -> None:
        self.pm = pluggy.PluginManager(hookspecs.PROJECT)
        self.pm.add_hookspecs(hookspecs)
        self._records: dict[str, _Record] = {}
        self._lock = threading.RLock()
        self._callers: dict[tuple[str, str], Any] = {}
        self._families: dict[str, FamilyInfo] | None = None
        self._validators: dict[str, Any] = {}
        self._models: dict[str, type[Any]] = {}  # families declared as a settings model (settings.py)
        if builtins:
            import importlib

            for name, module_name in BUILTIN_PLUGINS.items():
                self.register(importlib.import_module(module_name), name, "wott-hub", _core_version())
        if entry_points:
            wanted = selected_names() if only is _FROM_ENV else only
            for cand in discover(group, wanted):
                if cand.error is not None:
                    self._records[cand.name] = _Record(cand.name, cand.distribution, cand.version,
                                                       errors={"load": [cand.error]})
                else:
                    self.register(cand.module, cand.name, cand.distribution, cand.version)

    # -- loading -------------------------------------------------------------
    def register(
        self, plugin: Any, name: str, distribution: str | None = None, version: str | None = None
    ) -> PluginInfo:
        """Register a plugin object (usually a module); failures are recorded, never raised."""
        with self._lock:
            if name in self._records:
                other = self._records[name]
                self._records[f"{name} ({distribution})"] = _Record(
                    name, distribution, version,
                    errors={"register": [f"plugin name {name!r} is already taken by {other.distribution}"]},
                )
                return self._info(self._records[f"{name} ({distribution})"])
            rec = self._records[name] = _Record(name, distribution, version)
            try:
                self.pm.register(plugin, name=name)
            except Exception as e:
                rec.errors["register"] = [describe_exception(e)]
                if self.pm.has_plugin(name):  # a bad hook signature can leave half a registration
                    self.pm.unregister(name=name)
                return self._info(rec)
            rec.plugin = plugin
            for caller in self.pm.get_hookcallers(plugin) or []:
                if not caller.has_spec():
                    rec.errors[caller.name] = ["not a wott-hub hook (misspelt?); never called"]
            self._callers.clear()
            self._families = None
            return self._info(rec)

    # -- calling hooks, one plugin at a time (``answers.py`` checks some hooks' answers with these) ------
    def plugin_names(self) -> list[str]:
        """The plugins' names, in the order they were registered."""
        return list(self._records)

    def record_error(self, plugin: str, hook: str, message: str, fault: Fault | None = None) -> None:
        """Keep each distinct message once (a hook failing on every call must not grow memory), and log
        it when it is new (``fault``: with the traceback)."""
        with self._lock:
            messages = self._records[plugin].errors.setdefault(hook, [])
            if message in messages:
                return
            messages.append(message)
            del messages[:-_MAX_ERRORS_PER_HOOK]
        exc_info = None if fault is None else (type(fault.error), fault.error, fault.error.__traceback__)
        log.error("plugin %s: %s %s", plugin, hook, message, exc_info=exc_info)

    def _caller(self, hook: str, plugin: Any, name: str) -> Any:
        key = (hook, name)
        caller = self._callers.get(key)
        if caller is None:
            others = [p for p in self.pm.get_plugins() if p is not plugin]
            caller = self._callers[key] = self.pm.subset_hook_caller(hook, remove_plugins=others)
        return caller

    def call_each(self, hook: str, copy_args: bool = False, **kwargs: Any) -> Iterator[tuple[str, Any]]:
        """Yield (plugin name, what its implementation returned), skipping and recording failures.

        ``copy_args`` gives each plugin its own deep copy of the arguments, so one
        plugin mutating a dict cannot change what the next one sees.
        """
        hook_caller = getattr(self.pm.hook, hook)
        firstresult = bool(hook_caller.spec and hook_caller.spec.opts.get("firstresult"))
        done: list[Any] = []
        for impl in reversed(hook_caller.get_hookimpls()):
            if any(impl.plugin is p for p in done):
                continue
            done.append(impl.plugin)
            name = impl.plugin_name
            args = copy.deepcopy(kwargs) if copy_args else kwargs
            out = attempt(f"{hook}()", self._caller(hook, impl.plugin, name), **args)
            if out.fault is not None:
                self.record_error(name, hook, f"raised {out.fault.detail}", out.fault)
                continue
            if firstresult:
                yield name, out.value
            else:
                for value in out.value or ():  # no fault: the hook's list
                    yield name, value

    # -- families ------------------------------------------------------------
    def families(self) -> dict[str, FamilyInfo]:
        """Every family a loaded plugin provides, by name."""
        with self._lock:
            if self._families is None:
                self._families = self._collect_families()
            return dict(self._families)

    def _collect_families(self) -> dict[str, FamilyInfo]:
        from jsonschema import Draft202012Validator
        from jsonschema.exceptions import SchemaError

        hook = "wott_hub_families"
        found: dict[str, FamilyInfo] = {}
        for rec in self._records.values():
            rec.families = []
            rec.errors.pop(hook, None)  # asked afresh: old answers no longer apply
        answers: dict[str, list[Any]] = {}
        for name, result in self.call_each(hook):
            answers.setdefault(name, []).append(result)
        # On a name clash the plugin registered first keeps the family (built-ins, then entry
        # points by name), whatever order pluggy calls them in: stable across runs and installs.
        for name in [n for n in self._records if n in answers]:
            for result in answers[name]:
                self._accept_families(name, result, found, Draft202012Validator, SchemaError)
        self._validators.clear()
        self._models = {n: m for n, m in self._models.items() if n in found}
        return found

    def _accept_families(self, name: str, result: Any, found: dict[str, FamilyInfo],
                         validator_cls: type[Validator], schema_error: type[SchemaError]) -> None:
        hook = "wott_hub_families"
        if not isinstance(result, list | tuple):
            self.record_error(name, hook, f"returned {type(result).__name__}, not a list of FamilyInfo")
            return
        for fam in result:
            if not isinstance(fam, FamilyInfo):
                self.record_error(name, hook, f"returned a {type(fam).__name__}, not a FamilyInfo")
                continue
            model = fam.schema if isinstance(fam.schema, type) else None
            schema = fam.schema
            if isinstance(schema, type):  # a settings model: its JSON Schema for docs and the first check
                try:
                    schema = settings_schema(schema)
                except Exception as e:
                    self.record_error(name, hook, f"family {fam.name!r}: invalid settings model: {e}")
                    continue
                fam = replace(fam, schema=schema)
            try:
                validator_cls.check_schema(schema)
            except schema_error as e:
                self.record_error(name, hook, f"family {fam.name!r}: invalid settings schema: {e.message}")
                continue
            if fam.name in found:
                self.record_error(name, hook, f"family {fam.name!r} is already provided by plugin "
                                               f"{found[fam.name].plugin!r}")
                continue
            found[fam.name] = replace(fam, plugin=name)
            if model is not None:
                self._models[fam.name] = model
            self._records[name].families.append(fam.name)

    # -- devices -------------------------------------------------------------
    def validate(self, cfg: DeviceConfig) -> DeviceConfig:
        """``cfg`` with its settings checked against the family's schema and defaults filled in; a
        ``SettingsError`` names the device, family and setting at fault."""
        families = self.families()
        info = families.get(cfg.family)
        if info is None:
            known = ", ".join(sorted(families)) or "none"
            raise SettingsError(f"device {cfg.id!r}: unknown family {cfg.family!r} "
                                f"(installed families: {known})")
        schema = info.schema
        assert isinstance(schema, dict)  # a settings model became its JSON Schema when accepted
        validator = self._validators.get(cfg.family)
        if validator is None:
            from jsonschema import Draft202012Validator

            validator = self._validators[cfg.family] = Draft202012Validator(schema)
        from jsonschema.exceptions import best_match

        error = best_match(validator.iter_errors(cfg.settings))
        if error is not None:
            raise SettingsError(_explain(cfg, error))
        from .naming import naming_device

        model = self._models.get(cfg.family)
        with naming_device(cfg):  # NaN, infinities and numbers beyond any bound
            if model is not None:  # the model's bounds and defaults; the plugin gets plain values
                return replace(cfg, settings=model_settings(model, cfg.settings))
            return replace(cfg, settings=with_defaults(schema, cfg.settings))  # a dict: dict_schema.py

    def open_device(self, cfg: DeviceConfig) -> Driver:
        """Open ``cfg`` through the plugin of its family; a SettingsError names the setting at fault.

        A DriverError (a SettingsError too) from the plugin is the device's problem
        and passes through; any other exception is the plugin's bug: recorded
        against it, then reported as a DriverError for this device.
        """
        cfg = self.validate(cfg)
        plugin = self.families()[cfg.family].plugin
        hook = "wott_hub_open_device"
        rec = self._records[plugin]
        if not any(impl.plugin is rec.plugin for impl in getattr(self.pm.hook, hook).get_hookimpls()):
            raise DriverError(f"device {cfg.id!r}: plugin {plugin!r} provides family {cfg.family!r} "
                              f"but does not implement {hook}")
        out = attempt(f"{hook}()", self._caller(hook, rec.plugin, plugin), config=cfg)
        if out.fault is not None:
            if isinstance(out.fault.error, DriverError):  # the device's problem, in the plugin's words
                raise out.fault.error
            msg = f"raised {out.fault.detail}"
            self.record_error(plugin, hook, msg, out.fault)
            raise DriverError(f"device {cfg.id!r}: plugin {plugin!r} {msg}") from out.fault.error
        driver = out.value
        if not isinstance(driver, Driver):
            msg = f"returned {type(driver).__name__} for device {cfg.id!r}, not a Driver"
            self.record_error(plugin, hook, msg)
            raise DriverError(f"device {cfg.id!r}: plugin {plugin!r} {msg}")
        return driver

    def calibrate(self, family: str, data: str, out: str, options: dict[str, str]) -> str:
        """Calibrate ``family`` from ``data`` into ``out`` through its plugin (``wott_hub_calibrate``): the
        plugin's one-line summary. ``SettingsError`` for an unknown family or one without a calibration;
        a plugin's ``DriverError`` (a ``SettingsError`` too) passes through, anything else is its bug."""
        families = self.families()
        if family not in families:
            raise SettingsError(f"family {family!r} is not installed (wott-hub plugins families)")
        plugin = families[family].plugin
        hook = "wott_hub_calibrate"
        rec = self._records[plugin]
        if not any(impl.plugin is rec.plugin for impl in getattr(self.pm.hook, hook).get_hookimpls()):
            raise SettingsError(f"family {family!r} has no calibration (plugin {plugin!r})")
        res = attempt(f"{hook}()", self._caller(hook, rec.plugin, plugin), family=family, data=data, out=out,
                      options=dict(options))
        if res.fault is not None:
            if isinstance(res.fault.error, DriverError):
                raise res.fault.error
            msg = f"raised {res.fault.detail}"
            self.record_error(plugin, hook, msg, res.fault)
            raise DriverError(f"calibrate {family!r}: plugin {plugin!r} {msg}") from res.fault.error
        if not isinstance(res.value, str):
            raise DriverError(f"calibrate {family!r}: plugin {plugin!r} returned {type(res.value).__name__}, "
                              "not a summary")
        return res.value

    # -- the hooks whose answers are lists or claims: each checked in answers.py --
    def demo_devices(self) -> list[DeviceConfig]:
        """Each plugin's simulated demo devices, for ``wott-hub run`` without a config."""
        return answers.demo_devices(self)

    def claim(self, td: Mapping[str, Any]) -> DeviceConfig | None:
        """The device config of the first plugin that adopts a foreign TD (``wott_hub_claim_td``), or None."""
        return answers.claim(self, td)

    def usb_matches(self) -> list[UsbMatch]:
        """Every plugin's USB matches (``wott_hub_usb_devices``), built-ins first; a declaration that can
        never match is recorded against its plugin and left out, a repeated one kept once."""
        return answers.usb_matches(self)

    # -- reporting -----------------------------------------------------------
    def failed_plugins(self) -> dict[str, str]:
        """The plugins that could not be loaded or registered, with why (for ``wott-hub run`` and the
        hub's health); cheap: no hook is called."""
        with self._lock:
            return {key: "; ".join(m for k in ("load", "register") for m in rec.errors.get(k, ()))
                    for key, rec in self._records.items() if "load" in rec.errors or "register" in rec.errors}

    def plugins(self) -> list[PluginInfo]:
        """Every plugin seen: loaded ones with their families and hooks, failed ones with their error."""
        self.families()  # a plugin's families (and errors in providing them) are part of its report
        with self._lock:
            return [self._info(rec) for rec in self._records.values()]

    def _info(self, rec: _Record) -> PluginInfo:
        hooks: tuple[str, ...] = ()
        if rec.plugin is not None and self.pm.is_registered(rec.plugin):
            hooks = tuple(sorted(c.name for c in self.pm.get_hookcallers(rec.plugin) or []))
        error = "; ".join(
            msg if key in ("load", "register") else f"{key}: {msg}"
            for key, messages in rec.errors.items() for msg in messages
        )
        return PluginInfo(rec.name, rec.distribution, rec.version, tuple(rec.families), hooks, error or None)


def _explain(cfg: DeviceConfig, error: Any) -> str:
    """A one-line validation message that names the setting at fault."""
    path = [str(p) for p in error.absolute_path]
    instance = error.instance
    message = error.message
    if error.validator == "required" and isinstance(instance, Mapping):
        missing = [k for k in error.validator_value if k not in instance]
        path += missing[:1]
        message = "required setting is missing"
    elif error.validator == "additionalProperties" and isinstance(instance, Mapping):
        allowed = sorted((error.schema.get("properties") or {}).keys())
        extra = [k for k in instance if k not in allowed]
        path += [str(k) for k in extra[:1]]
        message = "unknown setting" + (f" (allowed: {', '.join(allowed)})" if allowed else "")
    elif error.validator in ("oneOf", "anyOf") and isinstance(instance, Mapping):
        # Schemas say "one of these settings" as alternatives that each require one key.
        names = [b["required"][0] for b in error.validator_value
                 if isinstance(b, Mapping) and len(b.get("required") or ()) == 1]
        if names and len(names) == len(error.validator_value):
            given = [n for n in names if n in instance]
            listed = " or ".join(repr(n) for n in names)
            message = f"give only one of {listed}" if given else f"needs one of {listed}"
            path += given[:1] or names[:1]
    where = f"setting {'.'.join(path)!r}" if path else "settings"
    return f"device {cfg.id!r} (family {cfg.family!r}): {where}: {message}"


def _core_version() -> str | None:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("wott-hub")
    except PackageNotFoundError:
        return None


_registry: Registry | None = None
_registry_lock = threading.Lock()


def get_registry() -> Registry:
    """The process's registry, loaded on first use (plugins are imported once)."""
    global _registry
    with _registry_lock:
        if _registry is None:
            _registry = Registry()
        return _registry


def loaded_registry() -> Registry | None:
    """The process's registry if something has loaded it already, else None (no plugin is imported)."""
    return _registry


def reset_registry() -> None:
    """Forget the cached registry (tests, or after installing a plugin in a running process)."""
    global _registry
    with _registry_lock:
        _registry = None
