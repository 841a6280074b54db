"""The driver contract every device family implements (see base.py)."""

from .base import Driver, DriverError, Health, HealthStatus

__all__ = ["Driver", "DriverError", "Health", "HealthStatus"]
