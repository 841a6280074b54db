"""Decode Foxglove's protobuf messages from the schema a channel carries (its FileDescriptorSet),
with Google's protobuf runtime: a decoder independent of the SDK that encoded them."""

from __future__ import annotations

from typing import Any

__all__ = ["decode"]

_CLASSES: dict[tuple[str, bytes], Any] = {}


def decode(schema_name: str, schema: bytes, data: bytes) -> Any:
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    key = (schema_name, schema)
    cls = _CLASSES.get(key)
    if cls is None:
        fds = descriptor_pb2.FileDescriptorSet.FromString(schema)
        pool = descriptor_pool.DescriptorPool()
        for f in fds.file:
            pool.Add(f)
        cls = _CLASSES[key] = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema_name))
    return cls.FromString(data)
