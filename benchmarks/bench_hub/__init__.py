"""Hub benchmarks: latency, events/s, Things per servient, start-up, history; plain wotpy in the same run.

    uv run wott-hub bench hub [--quick] [--groups latency,throughput,expose,startup,history]
                              [--devices 32] [--duration 6] [--no-write]

One module per scenario group (``latency``, ``throughput``, ``expose``, ``startup``,
``history``), the client processes in ``clients``, the tables in ``report``; what the
numbers mean is hand-written in docs/benchmarks.md ("Hub: what the tables measure"), not
generated here. Every hub internal the groups reach for is imported in ``_hub_internals``
only, so a reshaping of the hub is followed there in one line.

This package is imported by its client processes too: keep it free of imports.
"""

__all__: list[str] = []
