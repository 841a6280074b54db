"""The MQTT event path: the hub's events and property changes, published to a broker.

Only ``config`` is light; ``publisher`` imports aiomqtt (paho) and is loaded by the
hub only when ``[mqtt] url`` is set.
"""

from .config import MqttConfig

__all__ = ["MqttConfig"]
