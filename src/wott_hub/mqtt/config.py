"""The ``[mqtt]`` table of the hub config: the broker the hub publishes its events to.

Declared like the other tables (``wott_hub.configspec``); nothing here imports
aiomqtt or paho: a config without ``[mqtt]`` never loads them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated, Any

from wott_hub.configspec import ConfigError, Flag, check, doc, read, says, table_of

__all__ = ["MQTT_TABLE", "MqttConfig", "parse_mqtt"]

MqttUrl = Annotated[str, says("an mqtt:// URL with a host (mqtt://host:1883)",
                              pattern=r"^mqtt://[^/?#\s:]+(:[0-9]{1,5})?/?$")]
Topic = Annotated[str, says("an MQTT topic without wildcards", pattern=r"^[^#+\s]+$")]
QueueMax = Annotated[int, says("a positive integer", ge=1, le=10_000_000)]
Qos = Annotated[int, says("an MQTT QoS (0, 1 or 2)", ge=0, le=2)]
Seconds = Annotated[float, says("a positive number of seconds", gt=0, le=3_600)]


@dataclass(frozen=True)
class MqttConfig:
    url: MqttUrl | None = field(default=None, metadata=doc(
        "The broker the hub publishes every event and observable property change to "
        "(mqtt://host:port); unset: no MQTT."))
    public_url: MqttUrl | None = field(default=None, metadata=doc(
        "The broker's URL written into TD forms (clients connect there); default: url."))
    prefix: Topic | None = field(default=None, metadata=doc(
        "Topic prefix; default wott/<hub id>. Topics: <prefix>/<thing>/events/<name>, "
        "<prefix>/<thing>/properties/<name>, <prefix>/<thing>/td."))
    event_qos: Qos = field(default=0, metadata=doc(
        "QoS of what changes every frame: the skinDeformedDetection event and the "
        "contactInformation property (retained); other events, properties and the TDs use 1."))
    immediate: Flag = field(default=True, metadata=doc(
        "Write each QoS 0 message to the broker the moment it is made while nothing waits before "
        "it (lowest latency); false: every message waits for the publisher's next batch, one write "
        "per batch (fewer writes: more frames processed on a saturated hub; docs/scale-out.md)."))
    queue_max: QueueMax = field(default=100_000, metadata=doc(
        "Messages waiting for the broker at most; beyond, the oldest are dropped and counted "
        "(a slow or absent broker never slows the hub)."))
    reconnect_max_s: Seconds = field(default=10.0, metadata=doc(
        "Longest wait between two connection attempts (the backoff doubles from 0.2 s up to it)."))

    def __post_init__(self) -> None:
        check(self, MQTT_TABLE, "[mqtt]")

    @property
    def enabled(self) -> bool:
        return self.url is not None

    def topic_prefix(self, hub_id: str) -> str:
        return (self.prefix or f"wott/{hub_id}").rstrip("/")

    def host_port(self, public: bool = False) -> tuple[str, int]:
        url = (self.public_url if public and self.public_url else self.url) or ""
        rest = url.removeprefix("mqtt://").rstrip("/")
        host, _, port = rest.partition(":")
        return host, int(port) if port else 1883


MQTT_TABLE = table_of(MqttConfig, "mqtt")
"""The ``[mqtt]`` table as it is written in a file."""


def parse_mqtt(table: Any, source: str) -> MqttConfig:
    where = f"{source}: [mqtt]"
    t = read(MQTT_TABLE, table, where)
    cfg = MqttConfig(**{k: getattr(t, k) for k in MQTT_TABLE.__struct_fields__})
    if table and cfg.url is None:
        raise ConfigError(f"{where}.url: missing; the broker's mqtt://host:port")
    port = cfg.host_port()[1]
    if not 0 < port <= 65535:
        raise ConfigError(f"{where}.url: port {port} is out of range (1 to 65535)")
    return cfg
