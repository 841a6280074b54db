# mypy: disable-error-code="empty-body"
# (specs are bare stubs, as in datasette: pluggy calls the plugins' implementations, never these)
"""The hooks a wott-hub driver plugin can implement (documented for users in docs/plugins.md).

A plugin is a module registered under the ``wott-hub`` entry-point
group; it implements any subset of these hooks with functions of the same name
decorated with ``wott_hub.plugin_api.hookimpl``. An implementation may accept
fewer arguments than the spec lists (pluggy passes only those it names).

Every call is isolated per plugin: if one plugin's implementation raises, the
registry records the error against that plugin (``wott-hub plugins list``
shows it) and carries on with the other plugins' results.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import pluggy

if TYPE_CHECKING:
    from wott_hub.drivers.base import Driver

    from .model import DeviceConfig, FamilyInfo, UsbMatch

__all__ = ["PROJECT", "hookimpl", "hookspec"]

PROJECT = "wott_hub"
hookspec = pluggy.HookspecMarker(PROJECT)
hookimpl = pluggy.HookimplMarker(PROJECT)


@hookspec
def wott_hub_families() -> list[FamilyInfo]:
    """The device families this plugin provides.

    Called once, when the registry loads the plugins (at hub start-up and by
    ``wott-hub plugins list``). Return a list of ``FamilyInfo(name,
    description, schema)``: ``name`` is what a device's ``family`` key refers
    to (unique across all plugins; a later plugin claiming a taken name gets an
    error), ``schema`` the family's settings model (a ``SettingsModel`` class,
    defined at module level; the registry derives its JSON Schema) or, the
    compatibility path for older plugins, a JSON Schema (draft 2020-12) dict of
    the device's settings. Keep it cheap: import no camera or model libraries here.
    """


@hookspec(firstresult=True)
def wott_hub_open_device(config: DeviceConfig) -> Driver:
    """Open one device of a family this plugin provides.

    Called by ``Registry.open_device`` for the plugin that provides
    ``config.family`` only (the registry dispatches by family: never check
    it again here), after ``config.settings`` has been validated against the
    family's model (or schema) and completed with its defaults.
    Return a ``Driver`` (not yet started: it starts when the hub iterates
    ``frames()``); anything else is an error of the plugin. Raise
    ``SettingsError`` with a message naming the setting at fault when the device
    cannot be opened with these settings (``DriverError`` when it cannot be
    opened at all). Do not block here: the transport is opened and kept alive
    inside the driver.
    """


@hookspec
def wott_hub_demo_devices() -> list[DeviceConfig]:
    """The simulated devices this plugin contributes to the demo scene.

    Called by ``wott-hub run`` when it is given no config. Return a list of
    ``DeviceConfig`` (each with a unique ``id`` and one of this plugin's
    families) that open without hardware, e.g. a simulator playing a scene
    shipped with the plugin; return an empty list to contribute none.
    """


@hookspec(firstresult=True)
def wott_hub_claim_td(td: dict[str, Any]) -> DeviceConfig | None:
    """Adopt a foreign Thing Description (a network device that speaks WoT itself).

    Called by ``Registry.claim`` with a TD found in a directory or fetched
    from a discovered Thing (a dict parsed from JSON, never modified by the
    hub), plugin by plugin until one claims it. Return a ``DeviceConfig`` whose
    driver consumes that Thing and yields ``TactileFrame``s, so the hub
    re-exposes it with a Tactile TD; or None if this plugin cannot adapt it.
    """


@hookspec
def wott_hub_usb_devices() -> list[UsbMatch]:
    """The USB devices this plugin knows, by their udev properties, and how each becomes a device.

    Called when the registry is asked for the USB matches (``wott-hub discover --usb``, and a hub
    with ``[usb] adopt`` at start-up). Return a list of ``UsbMatch(family, subsystem, label, ...)``:
    the rules on udev properties (``vendor_id``/``product_ids``, ``model``, ``v4l_product``), the
    setting that gets the device node (``device`` for a camera, ``port`` for a serial board; None:
    listed only), the Thing id prefix put before the serial number and any preset settings. A match
    may name a family no installed plugin provides (the device is then listed, never adopted); a
    declaration that can never match is an error of the plugin. Keep it cheap: no I/O here.
    """


@hookspec(firstresult=True)
def wott_hub_calibrate(family: str, data: str, out: str, options: dict[str, str]) -> str | None:
    """Calibrate devices of a family from recorded data, and write the calibration to a file.

    Called by ``Registry.calibrate`` (``wott-hub calibrate FAMILY DATA --out OUT [--option KEY=VALUE]``)
    for the plugin that provides ``family`` only. ``data`` is the path the user gave (its format is
    the family's, documented with it), ``out`` where to write, ``options`` the ``--option`` pairs as
    strings. Return a one-line summary of what was written (the command prints it). Raise
    ``SettingsError`` naming the option, or saying what is wrong with the data, when it cannot be
    done (the command prints it as one line). A family without a calibration does not implement it.
    """
