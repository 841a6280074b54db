"""``wott-hub bench client``: the Python client (wott-client) against wotpy's ConsumedThing.

Two groups, each client in its own process, one after the other against the same hub:

- throughput: one Thing publishing ``skinDeformedDetection`` at an offered rate; how many
  records each client turns into a dense NumPy field, in order, with none lost, and the CPU
  time it spends per thousand;
- latency: 32 Things at 120 Hz each; publish-to-NumPy latency (wall clock, same machine).

Records are published straight into the hub's event plane (the processing of frames is
not what is measured here; ``bench hub`` measures it), with real Tactile TDs, so each client
consumes the TD, reads the mesh and streams exactly as it would from a device.
"""
