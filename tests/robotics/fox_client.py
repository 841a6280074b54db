"""A small client of the Foxglove WebSocket protocol for the tests and benchmarks (``websockets``):
the JSON control messages and the binary message frames, nothing else.

Frames: ``serverInfo``, ``advertise`` (channels), ``unadvertise``, ``status``; a message is opcode
0x01, subscription id (uint32 LE), log time (uint64 LE), payload.
"""

from __future__ import annotations

import asyncio
import json
import struct
from typing import Any

import websockets

__all__ = ["FoxClient", "SUBPROTOCOL"]

SUBPROTOCOL = "foxglove.sdk.v1"


class FoxClient:
    def __init__(self, ws: Any) -> None:
        self.ws = ws
        self.channels: dict[str, dict[str, Any]] = {}  # topic -> advertised channel
        self.by_id: dict[int, dict[str, Any]] = {}
        self.subs: dict[int, str] = {}  # subscription id -> topic
        self.messages: list[tuple[str, int, bytes]] = []  # (topic, log time, payload)
        self.status: list[dict[str, Any]] = []
        self.info: dict[str, Any] = {}
        self._next = 1
        self._reader: asyncio.Task[None] | None = None

    @classmethod
    async def connect(cls, url: str, subprotocols: tuple[str, ...] = (SUBPROTOCOL,)) -> FoxClient:
        ws = await websockets.connect(url, subprotocols=list(subprotocols), max_size=64 * 2**20)
        self = cls(ws)
        self._reader = asyncio.create_task(self._read())
        return self

    async def _read(self) -> None:
        try:
            async for frame in self.ws:
                if isinstance(frame, bytes):
                    if frame[0] == 1:
                        sub, t = struct.unpack_from("<IQ", frame, 1)
                        topic = self.subs.get(sub)
                        if topic is not None:
                            self.messages.append((topic, t, frame[13:]))
                    continue
                msg = json.loads(frame)
                op = msg.get("op")
                if op == "serverInfo":
                    self.info = msg
                elif op == "advertise":
                    for ch in msg["channels"]:
                        self.channels[ch["topic"]] = ch
                        self.by_id[ch["id"]] = ch
                elif op == "unadvertise":
                    for cid in msg["channelIds"]:
                        ch = self.by_id.pop(cid, None)
                        if ch is not None:
                            self.channels.pop(ch["topic"], None)
                elif op == "status":
                    self.status.append(msg)
        except websockets.ConnectionClosed:
            pass

    async def subscribe(self, *topics: str) -> None:
        subs = []
        for topic in topics:
            sid = self._next
            self._next += 1
            self.subs[sid] = topic
            subs.append({"id": sid, "channelId": self.channels[topic]["id"]})
        await self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    async def unsubscribe(self, *topics: str) -> None:
        ids = [sid for sid, t in self.subs.items() if t in topics]
        await self.ws.send(json.dumps({"op": "unsubscribe", "subscriptionIds": ids}))
        for sid in ids:
            del self.subs[sid]

    def of(self, topic: str) -> list[tuple[int, bytes]]:
        return [(t, p) for tp, t, p in self.messages if tp == topic]

    async def close(self) -> None:
        await self.ws.close()
        if self._reader is not None:
            await self._reader
