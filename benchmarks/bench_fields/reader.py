"""The client process: wott-client against the bench hub (``python -m bench_fields.reader SPEC``).

Protocol: prints ``ready`` once connected, then one JSON line with its result. ``stream``: the
``skinDisplacement`` binary stream of a Thing until ``expect`` packets (or ``seconds``) are in;
``images``: the camera's latest image through each form for ``seconds`` each.
"""

from __future__ import annotations

import asyncio
import json
import sys
import time


async def stream(spec: dict) -> dict:
    from contextlib import aclosing

    from wott_client import AsyncClient

    async with AsyncClient() as client:
        thing = await client.async_thing(spec["url"])
        got, seqs = 0, []
        t_first = t_last = None
        agen = thing.async_displacement_batches()
        print("ready", flush=True)
        deadline = time.monotonic() + spec["seconds"]
        async with aclosing(agen) as batches:
            async for batch in batches:
                now = time.perf_counter()
                t_first = t_first or now
                t_last = now
                got += len(batch)
                seqs += [int(p.event_id) for p in batch]
                if got >= spec["expect"] or time.monotonic() > deadline:
                    break
        in_order = seqs == sorted(seqs) and len(set(seqs)) == len(seqs)
        return {"received": got, "span_s": (t_last or 0) - (t_first or 0), "in_order": in_order,
                "transport": thing._displacement_form()[0].content_type}


async def images(spec: dict) -> dict:
    from wott_client import AsyncClient

    out = {}
    async with AsyncClient() as client:
        thing = await client.async_thing(spec["url"])
        first = await thing.async_image()
        print("ready", flush=True)
        out["shape"] = list(first.shape)
        t0 = time.perf_counter()
        n, size = 0, 0
        while time.perf_counter() - t0 < spec["seconds"]:
            image = await thing.async_image()
            n += 1
            size += image.nbytes
        out["npy"] = (n, time.perf_counter() - t0, size / n)
        base = spec["url"] + "/properties/rawImage"
        for fmt in ("jpeg", "png"):
            t0 = time.perf_counter()
            n, size = 0, 0
            while time.perf_counter() - t0 < spec["seconds"] / 2:
                _, _, body = await client.bulk.get(f"{base}?format={fmt}")  # the client's path for bodies
                n += 1
                size += len(body)
            out[fmt] = (n, time.perf_counter() - t0, size / n)
    return out


def main() -> None:
    spec = json.loads(sys.argv[1])
    res = asyncio.run(stream(spec) if spec["kind"] == "stream" else images(spec))
    print(json.dumps(res), flush=True)


if __name__ == "__main__":
    main()
