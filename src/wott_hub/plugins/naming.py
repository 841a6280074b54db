"""Errors that say which device they are about, for ``wott_hub_open_device`` implementations.

A family's builder is easiest to test and reuse when its ``DriverError``s (a
``SettingsError`` for a setting at fault) name only the setting; the hook that
calls it for one configured device adds the device and family, worded as the
registry words its own (schema) errors: ``device 'left' (family
'barrel-vision'): fps: must be positive``. A ``SettingsError`` stays one.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from wott_hub.errors import DriverError, SettingsError

from .model import DeviceConfig

__all__ = ["naming_device"]


@contextmanager
def naming_device(config: DeviceConfig) -> Iterator[None]:
    try:
        yield
    except DriverError as e:
        kind = SettingsError if isinstance(e, SettingsError) else DriverError
        raise kind(f"device {config.id!r} (family {config.family!r}): {e}") from None
