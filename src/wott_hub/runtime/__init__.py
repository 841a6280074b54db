"""The frame runtime: a device's frames through its processor into records, here or in a worker process.

Between the parts it joins (``drivers`` and ``plugins`` for the device,
``tactile`` for processing, ``events`` for the records) and the hub that
serves the result, one job per module (docs/architecture.md):

- ``handle``: what the pipeline and the hub need of a device wherever it runs
  (``DeviceHandle``: a ``Driver`` here, a ``pool.WorkerDevice`` for one in a worker);
- ``capabilities``: the device actions a driver's capabilities give it;
- ``opening``: opening a device through its plugin (``open_driver``), the retry pacing;
- ``pipeline``: ``DevicePipeline``, frames to records into a ``types.RecordSink``, its
  state and counters, and the transitions between them;
- ``payloads``: the JSON texts of a frame's records, written from the processor's arrays;
- ``restart``: closing and opening a device again, and retrying one that does not open,
  the same in the hub's process and in a worker's;
- ``tasks``: one background task per device id (those retries);
- ``messages``: what crosses the pipe between the hub and a worker, one type per message;
- ``outbox``: the worker's end of the pipe (records batched per loop turn);
- ``worker``: the worker process's loop;
- ``pool``: the hub's end: the worker processes and their devices' proxies.

Nothing here imports the hub; no module of the package imports this one (the
pool's ``multiprocessing`` is imported only by a hub that has workers).
"""

from __future__ import annotations

__all__: list[str] = []
