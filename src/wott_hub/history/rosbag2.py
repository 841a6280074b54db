"""Export a range of history as a rosbag2 folder: ROS 2 message types, CDR, MCAP storage.

Contract (``docs/robotics.md``): ``DIR/`` holds ``DIR.mcap`` (profile ``ros2``, schemas
``ros2msg``, messages ``cdr``) and ``metadata.yaml`` (rosbag2 version 9, ROS 2 Jazzy), written by
``rosbags``' rosbag2 writer; ``ros2 bag play DIR`` publishes it. What each record becomes is
``robotics.mapping``'s profile ``ros2`` (every record, no throttle): skins as PointCloud2 and a
MarkerArray mesh, contacts as arrow markers and a net WrenchStamped, actions as
``rcl_interfaces/msg/Log``, anything else as ``std_msgs/msg/String`` of its JSON, and one
``/tf_static`` placing each sensor frame. A message's log time is the record's recorded time; its
header stamp the event's own ``timeStamp`` where it has one. The mesh and ``/tf_static`` are offered
transient local (latched), as robot_state_publisher offers ``/tf_static``.

The folder must not exist (as ``ros2 bag record -o``); an export that fails, or finds no record,
leaves nothing behind. The name is taken first (``os.mkdir``: atomic, and it refuses whatever is
there, a dangling symlink too), the bag written in a private folder beside it and moved onto the
name at the end (``os.rename`` over the empty folder it took): two exports into one folder at
once give one bag and one clear refusal, never a folder mixed or deleted under the other; a
failure (a full disk, Ctrl-C) removes both the partial bag and the name it took.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from wott_hub.errors import InvalidInput, NotFound
from wott_hub.robotics.mapping import FleetMapping

from .merge import merged_pages

if TYPE_CHECKING:
    from wott_hub.robotics.channel import Channel

    from .storage import StorageReader

__all__ = ["BagSummary", "Progress", "export_rosbag2"]

Progress = Callable[[int, int], None]
"""Called after each page with the records done so far and the time (ns) reached."""


@dataclass
class BagSummary:
    records: int = 0
    messages: int = 0
    topics: dict[str, str] = field(default_factory=dict)  # topic -> ROS 2 type


def _qos(latched: bool) -> list[Any]:
    """rosbag2's recorded offer: reliable, keep last; transient local for latched topics."""
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

    never = QosTime(sec=0, nsec=0)
    return [Qos(QosHistory.KEEP_LAST, 1 if latched else 100, QosReliability.RELIABLE,
                QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE, never, never,
                QosLiveliness.AUTOMATIC, never, False)]


def export_rosbag2(reader: StorageReader, out_dir: Path, things: Sequence[str], *,
                   t_from_ns: int | None = None, t_to_ns: int | None = None, names: list[str] | None = None,
                   progress: Progress | None = None) -> BagSummary:
    """Write the records of ``things`` in [t_from, t_to] as the rosbag2 folder ``out_dir``.

    ``NotFound``: a Thing never recorded; ``InvalidInput``: ``out_dir`` exists, or no record is in
    the range (nothing is written then)."""
    things = list(dict.fromkeys(things))  # a Thing named twice is exported once (issue 48)
    infos = {}
    for thing in things:
        info = reader.thing_info(thing)
        if info is None:
            raise NotFound(f"no recorded device {thing!r} (see `wott-hub history list`)")
        infos[thing] = info
    taken = _take(out_dir)
    work: Path | None = None
    try:
        work = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.", suffix=".partial", dir=out_dir.parent))
        summary = _write(reader, work / out_dir.name, infos, t_from_ns, t_to_ns, names, progress)
        os.rename(work / out_dir.name, taken)  # onto the empty folder taken above
    except BaseException:
        with contextlib.suppress(OSError):
            taken.rmdir()
        raise
    finally:
        if work is not None:
            shutil.rmtree(work, ignore_errors=True)
    return summary


def _take(out_dir: Path) -> Path:
    """The export's own name: made here, empty, or ``InvalidInput`` if anything is there."""
    try:
        os.mkdir(out_dir)
    except FileExistsError:
        raise InvalidInput(f"{str(out_dir)!r} exists: a rosbag2 export writes a new folder") from None
    return out_dir


def _write(reader: StorageReader, out_dir: Path, infos: dict[str, Any], t_from_ns: int | None,
           t_to_ns: int | None, names: list[str] | None, progress: Progress | None) -> BagSummary:
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

    from wott_hub.robotics.ros2_msgs import typestore

    things = list(infos)
    ts = typestore()
    fleet = FleetMapping("ros2")
    for thing, info in infos.items():
        fleet.add(thing, info["td"], info["static_values"])
    summary = BagSummary()
    writer = Writer(out_dir, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    conns: dict[Channel, Any] = {}
    serialize = ts.serialize_cdr
    ok = False
    try:
        writer.open()
        write = writer.write

        def emit(outs: list[Any]) -> None:
            for o in outs:
                ch = o.channel
                conn = conns.get(ch)
                if conn is None:
                    conn = conns[ch] = writer.add_connection(ch.topic, ch.schema_name, typestore=ts,
                                                             offered_qos_profiles=_qos(ch.latched))
                    summary.topics[ch.topic] = ch.schema_name
                write(conn, o.t_ns, serialize(o.payload, ch.schema_name))
            summary.messages += len(outs)

        first = True
        for records in merged_pages(reader, list(things), t_from_ns, t_to_ns, names):
            for rec in records:
                if first:
                    tf = fleet.transforms(rec.t_ns)
                    if tf is not None:
                        emit([tf])
                    first = False
                emit(fleet.record(rec))
            summary.records += len(records)
            if progress is not None and records:
                progress(summary.records, records[-1].t_ns)
        if summary.records == 0:
            raise InvalidInput(f"no records of {', '.join(things)} in that range: nothing to export")
        writer.close()
        ok = True
    finally:
        if not ok and writer.storage is not None:
            with contextlib.suppress(Exception):  # a full disk may fail this too: the folder goes anyway
                writer.storage.abort()  # closes the file it opened
    return summary
