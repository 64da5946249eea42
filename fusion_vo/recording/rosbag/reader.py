"""Opening a ROS bag (ROS 1 ``.bag``, ROS 2 folder, ``.mcap`` or ``.db3``), its topics and stamps.

The bag is read with :class:`rosbags.highlevel.AnyReader`; messages are decoded with the bag's own
message definitions, or with a ROS 2 typestore when the bag carries none.

Time
----
A sample's time is its header stamp ``sec * 10^9 + nanosec`` [ns]; a zero stamp falls back to the time
the bag recorded the message.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from fusion_vo.errors import InputError


IMAGE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
IMU = "sensor_msgs/msg/Imu"
ODOMETRY = "nav_msgs/msg/Odometry"
NAV_SAT_FIX = "sensor_msgs/msg/NavSatFix"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"

#: stream name -> (message types it accepts, command-line option that selects its topic)
STREAM_TYPES: dict[str, tuple[tuple[str, ...], str]] = {
    "cam0": ((IMAGE, COMPRESSED_IMAGE), "--image-topic"),
    "imu0": ((IMU,), "--imu-topic"),
    "odom0": ((ODOMETRY,), "--odom-topic"),
    "gps0": ((NAV_SAT_FIX,), "--gps-topic"),
}


@dataclass(frozen=True)
class BagTopic:
    """One topic of a bag: its name, message type (``pkg/msg/Type``) and message count."""

    topic: str
    msgtype: str
    count: int


#: what :func:`open_reader` can open, in the words of its error messages
BAG_KINDS = "a ROS 1 .bag file, a ROS 2 bag folder (holding metadata.yaml), or a .mcap or .db3 file"


def open_reader(bag: str | Path):
    """An unopened :class:`~rosbags.highlevel.AnyReader` for ``bag`` (ROS 1 file, ROS 2 folder or file)."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    bag = Path(bag)
    if not bag.exists():
        raise InputError("bag not found", bag)
    if bag.is_dir() and not (bag / "metadata.yaml").is_file():
        raise InputError(f"not a ROS bag: a folder without metadata.yaml (a bag is {BAG_KINDS})", bag)
    if bag.is_file() and bag.suffix not in (".bag", ".mcap", ".db3"):
        raise InputError(f"not a ROS bag: the name does not end in .bag, .mcap or .db3 (a bag is {BAG_KINDS})", bag)
    try:
        return AnyReader([bag], default_typestore=get_typestore(Stores.LATEST))
    except Exception as exc:  # rosbags raises several error types for unreadable input
        raise InputError(f"not a readable ROS bag ({one_line(exc)})", bag) from None


def list_topics(bag: str | Path) -> list[BagTopic]:
    """Topics of a bag with their message types and counts, sorted by name."""
    with opened(bag) as reader:
        return bag_topics(reader)


class opened:
    """Context manager opening a bag with :class:`InputError` for anything unreadable."""

    def __init__(self, bag: str | Path):
        self.bag = Path(bag)
        self.reader = open_reader(self.bag)

    def __enter__(self):
        try:
            self.reader.open()
        except Exception as exc:
            raise InputError(f"not a readable ROS bag ({one_line(exc)})", self.bag) from None
        return self.reader

    def __exit__(self, *exc) -> bool:
        try:
            self.reader.close()
        except Exception:  # closing a half-read corrupt bag may fail again; the first error matters
            pass
        return False


def bag_topics(reader) -> list[BagTopic]:
    counts: dict[tuple[str, str], int] = {}
    for c in reader.connections:
        counts[(c.topic, c.msgtype)] = counts.get((c.topic, c.msgtype), 0) + c.msgcount
    return [BagTopic(t, m, n) for (t, m), n in sorted(counts.items())]


def one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) < 200 else text[:197] + "..."


def select_topics(topics: Sequence[BagTopic], requested: dict[str, str | None], bag: Path) -> dict[str, BagTopic]:
    """Choose the topic of each stream.

    A requested topic must exist and carry a supported type for its stream. A stream without a request
    takes the single topic of its types; none means the stream is absent; several are ambiguous.

    Parameters
    ----------
    topics : the bag's topics.
    requested : stream name (``cam0``, ``imu0``, ``odom0``, ``gps0``; ``imu1``, ``odom1`` ... with a topic) -> topic
        or ``None``.
    bag : the bag, for error messages.
    """
    by_name = {t.topic: t for t in topics}
    chosen: dict[str, BagTopic] = {}
    # the further instances of a kind (imu1, odom2 ...) are written only for a topic named for them
    order = [(s, spec) for base, spec in STREAM_TYPES.items()
             for s in [base] + sorted((r for r in requested if r not in STREAM_TYPES and
                                       r.rstrip("0123456789") + "0" == base), key=lambda r: int(r[len(base) - 1:]))]
    for stream, (types, option) in order:
        want = requested.get(stream)
        if want:
            name = want if want in by_name else "/" + want.lstrip("/")
            if name not in by_name:
                raise InputError(f"{option} {want}: no such topic in the bag (topics: "
                                 f"{', '.join(t.topic for t in topics) or 'none'})", bag)
            if by_name[name].msgtype not in types:
                raise InputError(f"{option} {want}: topic carries {by_name[name].msgtype}, "
                                 f"expected {' or '.join(types)}", bag)
            chosen[stream] = by_name[name]
            continue
        found = [t for t in topics if t.msgtype in types]
        if len(found) > 1:
            raise InputError(f"several topics could be {stream} ({', '.join(t.topic for t in found)}); "
                             f"choose one with {option}", bag)
        if found:
            chosen[stream] = found[0]
    return chosen


def header_stamp(header, bag_t: int) -> tuple[int, bool]:
    t = int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)
    return (t, False) if t > 0 else (int(bag_t), True)
