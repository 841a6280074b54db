"""Several async iterators as one: each runs in its own task, in arrival order.

A failing source ends the merged iterator with its exception (the others are
cancelled); so do the caller's ``aclose()`` and cancellation. The queue is
bounded so that a slow consumer slows the sources (TCP then pushes back on the
server, which cuts off and later resumes a subscriber that falls too far behind).
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncGenerator
from contextlib import aclosing
from typing import TypeVar, cast

__all__ = ["merge"]

T = TypeVar("T")
_DONE = object()


async def merge(sources: list[AsyncGenerator[T, None]], maxsize: int = 256) -> AsyncGenerator[T, None]:
    if len(sources) == 1:
        async with aclosing(sources[0]) as only:
            async for x in only:
                yield x
        return
    queue: asyncio.Queue[object] = asyncio.Queue(maxsize)

    async def pump(src: AsyncGenerator[T, None]) -> None:
        try:
            async with aclosing(src):
                async for x in src:
                    await queue.put(x)
            await queue.put(_DONE)
        except asyncio.CancelledError:
            raise
        except BaseException as e:  # handed to the consumer, which raises it
            await queue.put(_Failed(e))

    tasks = [asyncio.ensure_future(pump(s)) for s in sources]
    live = len(tasks)
    try:
        while live:
            got = await queue.get()
            if got is _DONE:
                live -= 1
            elif isinstance(got, _Failed):
                raise got.error
            else:
                yield cast(T, got)  # neither marker: a source's item
    finally:
        for t in tasks:
            t.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)


class _Failed:
    __slots__ = ("error",)

    def __init__(self, error: BaseException) -> None:
        self.error = error
