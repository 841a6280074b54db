"""The hub: devices in, one servient out, every event recorded (lifecycle.py says how).

The package's public names are here (``from wott_hub.hub import Hub, serve``);
its modules are internal and never import this one (tests/test_architecture.py).
"""

from .collector import tune_for_hub
from .devices import DeviceRuntime
from .lifecycle import Hub
from .replay import ReplayRuntime
from .serve import serve

__all__ = ["DeviceRuntime", "Hub", "ReplayRuntime", "serve", "tune_for_hub"]
