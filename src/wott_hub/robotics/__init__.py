"""Into the robotics tools users already have: ROS 2 bags and Foxglove, from one mapping.

A record of the hub (an event or a property change of a Thing, ``events.record.Record``) becomes
the same messages wherever it goes: in an MCAP file for Foxglove (``history/mcap.py``), live on
the Foxglove WebSocket endpoint (``live.py``), and, as ROS 2 messages, in a rosbag2 folder
(``history/rosbag2.py``). What each record becomes is decided in one place, ``mapping.py``; the
two encodings of it are ``foxglove_msgs.py`` (Foxglove's well-known schemas, protobuf, encoded by
``foxglove-sdk``) and ``ros2_msgs.py`` (ROS 2 Jazzy message types, CDR, serialised by
``rosbags``). docs/robotics.md says what goes where, in which units and frames.

One job per module; no module imports this package's ``__init__``, which holds only this map:

| module | job |
|---|---|
| ``names.py`` | topic names and frame ids (ROS 2 names from Thing ids) |
| ``geometry.py`` | a Thing's skin from its TD's values: nodes in metres, triangles, the sensor frame's pose |
| ``payloads.py`` | the hub's JSON payloads read into arrays (skin packets, contacts) |
| ``raw_signals.py`` | the displacement field, camera images and taxel grids (issue 29): their inputs |
| ``foxglove_msgs.py`` | Foxglove messages (SceneUpdate, Log, FrameTransforms, images, point clouds) |
| ``ros2_msgs.py`` | ROS 2 messages (PointCloud2, MarkerArray, WrenchStamped, Log, TFMessage, images...) |
| ``mapping.py`` | the one mapping: a Thing's channels and what each record becomes; the scene throttle |
| ``layout.py`` | a Foxglove layout that opens on a fleet's skins |
| ``config.py`` | the ``[foxglove]`` table (light: imports no foxglove) |
| ``live.py`` | the live Foxglove endpoint, fed by taps on the event plane: a message encoded, sent once |
| ``relay.py`` | a process running ``foxglove-sdk``'s server and its per-client fan-out, off the hub's GIL |
| ``relay_wire.py`` | the frames between the hub and its relay |
| ``guard.py``, ``nagle.py`` | the relay's clients kept to a bound; Nagle's algorithm off on their sockets |

Heavy libraries (``foxglove``, ``rosbags``) are imported inside the modules that use them, which
are loaded only by an export or a hub with ``[foxglove]`` on.
"""

__all__: list[str] = []
