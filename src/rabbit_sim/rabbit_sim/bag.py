"""Writing a rosbag2 bag (metadata.yaml, rosbag2 version 9, as Jazzy writes it, plus one
MCAP file with the ``ros2`` profile, ``ros2msg`` schemas and ``cdr`` messages) through the
``rosbags`` library; no hand-written format code. ROS-free: messages arrive serialized.
"""

from __future__ import annotations

import re
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import Writer, WriterError
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode, StoragePlugin
from rosbags.typesys import Stores, get_typestore

COMPRESSIONS = ("none", "zstd")


ROS_DISTRO = "jazzy"
BAG_FILE_SUFFIXES = (".mcap", ".db3", ".zstd")


def is_bag_directory(path: Path) -> bool:
    """True for a directory holding only what a rosbag2 bag holds (``metadata.yaml`` and
    storage files), at least one of them: the only kind ``overwrite`` may delete."""
    if not path.is_dir() or path.is_symlink():
        return False
    entries = list(path.iterdir())
    return bool(entries) and all(
        e.is_file() and (e.name == "metadata.yaml" or e.name.endswith(BAG_FILE_SUFFIXES)) for e in entries)


def set_ros_distro(metadata: Path, distro: str) -> None:
    """Write ``ros_distro: <distro>`` into a bag's metadata.yaml (the rosbags writer puts its
    own name there; ``ros2 bag info`` shows the distribution)."""
    text = metadata.read_text()
    metadata.write_text(re.sub(r"^(\s*ros_distro:).*$", rf"\1 {distro}", text, count=1, flags=re.M))


class BagError(RuntimeError):
    """The bag cannot be created, written or read (exists, unwritable path, full disk, not a bag)."""


def open_bag(path: Path):
    """An open ``rosbags`` reader of the bag directory ``path`` (the caller closes it; it is
    open already, so not for a ``with``); :class:`BagError` with one line when it is not a
    bag or cannot be read."""
    from rosbags.rosbag2 import Reader

    if not (Path(path) / "metadata.yaml").is_file():
        raise BagError(f"{path} is not a rosbag2 bag directory (no metadata.yaml)")
    try:
        reader = Reader(path)
        reader.open()
    except Exception as exc:  # noqa: BLE001 - rosbags raises its own kinds for damaged bags
        raise BagError(f"cannot read {path}: {exc}") from None
    return reader


def joint_state_stamps(path: Path) -> set[int]:
    """The distinct header stamps (ns) of the ``/joint_states`` messages in the bag ``path``
    (:class:`BagError` as :func:`open_bag`)."""
    from rosbags.typesys import Stores, get_typestore

    typestore = get_typestore(Stores.ROS2_JAZZY)
    reader = open_bag(path)
    try:
        connections = [c for c in reader.connections if c.topic == "/joint_states"]
        stamps = set()
        for connection, _t, raw in reader.messages(connections):
            stamp = typestore.deserialize_cdr(raw, connection.msgtype).header.stamp
            stamps.add(stamp.sec * 1_000_000_000 + stamp.nanosec)
        return stamps
    finally:
        reader.close()


@dataclass(frozen=True)
class QosSpec:
    """The QoS a publisher offers, as recorded in metadata.yaml."""

    reliable: bool
    transient_local: bool
    depth: int

    def to_rosbags(self) -> Qos:
        zero = QosTime(0, 0)
        return Qos(
            history=QosHistory.KEEP_LAST,
            depth=self.depth,
            reliability=QosReliability.RELIABLE if self.reliable else QosReliability.BEST_EFFORT,
            durability=QosDurability.TRANSIENT_LOCAL if self.transient_local else QosDurability.VOLATILE,
            deadline=zero,
            lifespan=zero,
            liveliness=QosLiveliness.AUTOMATIC,
            liveliness_lease_duration=zero,
            avoid_ros_namespace_conventions=False,
        )


class BagWriter:
    """One bag directory. ``add_topic`` then ``write`` serialized CDR messages with a log
    time in ns; ``close`` writes the MCAP summary and metadata.yaml. Counts per topic."""

    def __init__(self, path: str | Path, compression: str = "none", overwrite: bool = False) -> None:
        path = Path(path)
        if compression not in COMPRESSIONS:
            raise BagError(f"compression must be one of {COMPRESSIONS}, got {compression!r}")
        if path.exists():
            if not overwrite:
                raise BagError(f"{path} exists; choose another directory or pass --overwrite")
            if not is_bag_directory(path):
                raise BagError(f"{path} is not a bag directory (only metadata.yaml and *.mcap/*.db3 files); "
                               "refusing to overwrite it")
            shutil.rmtree(path)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)  # runs/walk1 on a fresh clone: runs/ is made
        except OSError as exc:
            raise BagError(f"cannot create {path}: {exc}") from exc
        self.path = path
        self._typestore = get_typestore(Stores.ROS2_JAZZY)
        self._writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
        if compression == "zstd":  # zstd-compressed MCAP chunks
            self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        try:
            self._writer.open()
        except (OSError, WriterError) as exc:
            raise BagError(f"cannot create bag {path}: {exc}") from exc
        self._connections: dict[str, object] = {}
        self.counts: dict[str, int] = {}
        self.closed = False

    def add_topic(self, topic: str, type_name: str, qos: QosSpec) -> None:
        if topic in self._connections:
            return
        self._connections[topic] = self._writer.add_connection(
            topic, type_name, typestore=self._typestore, serialization_format="cdr",
            offered_qos_profiles=[qos.to_rosbags()],
        )
        self.counts[topic] = 0

    def write(self, topic: str, log_time_ns: int, data: bytes) -> None:
        try:
            self._writer.write(self._connections[topic], log_time_ns, data)
        except OSError as exc:
            raise BagError(f"cannot write to {self.path}: {exc}") from exc
        self.counts[topic] += 1

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        try:
            self._writer.close()
            set_ros_distro(self.path / "metadata.yaml", ROS_DISTRO)
        except OSError as exc:
            raise BagError(f"cannot finish {self.path}: {exc}") from exc


@dataclass(frozen=True)
class Recovery:
    """What :func:`recover_bag` saved: messages per topic, and why reading stopped."""

    output: Path
    counts: dict[str, int]
    stopped: str

    @property
    def messages(self) -> int:
        return sum(self.counts.values())


def recover_bag(damaged: str | Path, output: str | Path,
                qos_of: Callable[[str], QosSpec] = lambda _topic: QosSpec(True, False, 10)) -> Recovery:
    """Rebuild a complete bag in ``output`` (a new directory) from the MCAP file of a bag
    cut short (SIGKILL, full disk, power loss: no summary, no metadata.yaml), as ``ros2 bag
    reindex`` would: every message of every chunk written whole is kept; reading stops at
    the first truncated or corrupt record. ``qos_of(topic)``: the QoS to record for a topic
    (the damaged file's channel metadata is not parsed). Raises :class:`BagError`."""
    from mcap.stream_reader import StreamReader
    from mcap.records import Channel, Message, Schema

    damaged = Path(damaged)
    files = sorted(damaged.glob("*.mcap")) if damaged.is_dir() else [damaged]
    if not files or not files[0].is_file():
        raise BagError(f"no MCAP file in {damaged}")
    schemas: dict[int, str] = {}
    channels: dict[int, tuple[str, str]] = {}
    messages: list[tuple[int, int, bytes]] = []
    stopped = "end of file"
    with files[0].open("rb") as stream:
        try:
            for record in StreamReader(stream, skip_magic=False, validate_crcs=True).records:
                if isinstance(record, Schema):
                    schemas[record.id] = record.name
                elif isinstance(record, Channel):
                    channels[record.id] = (record.topic, schemas.get(record.schema_id, ""))
                elif isinstance(record, Message) and record.channel_id in channels:
                    messages.append((record.channel_id, record.log_time, bytes(record.data)))
        except Exception as exc:  # noqa: BLE001 - a cut file ends in any kind of broken record
            stopped = f"{type(exc).__name__} after {len(messages)} messages (the cut-off end)"
    writer = BagWriter(output)
    try:
        for topic, type_name in channels.values():
            writer.add_topic(topic, type_name, qos_of(topic))
        for channel_id, log_time, data in sorted(messages, key=lambda m: m[1]):
            writer.write(channels[channel_id][0], log_time, data)
    finally:
        writer.close()
    return Recovery(writer.path, dict(writer.counts), stopped)
