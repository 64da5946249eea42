"""What an import wrote: one summary per stream and notes for the user."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from fusion_vo.recording.rosbag.reader import BagTopic


@dataclass
class StreamSummary:
    """What became of one imported topic.

    Attributes
    ----------
    stream : str
        Folder of the recording (``cam0``, ``imu0``, ``odom0``, ``gps0``).
    topic, msgtype : str
        Source topic and its message type.
    messages : int
        Messages read from the bag.
    written : int
        Rows written.
    duplicates : int
        Samples dropped because an earlier sample of the stream had the same timestamp.
    dropped : int
        Samples dropped as unusable (non-finite values, undecodable image, GPS without a fix).
    bag_time_stamps : int
        Samples whose header stamp was zero and that took the bag's record time instead.
    rate_hz : float or None
        Rate measured from the written timestamps (inverse of the median interval).
    t_first_ns, t_last_ns : int
        First and last written timestamp.
    """

    stream: str
    topic: str
    msgtype: str
    messages: int = 0
    written: int = 0
    duplicates: int = 0
    dropped: int = 0
    bag_time_stamps: int = 0
    rate_hz: float | None = None
    t_first_ns: int = 0
    t_last_ns: int = 0

    @property
    def duration_s(self) -> float:
        return (self.t_last_ns - self.t_first_ns) * 1e-9


@dataclass
class ImportSummary:
    """Result of :func:`import_bag`: the output folder, one :class:`StreamSummary` per stream, notes."""

    bag: Path
    out: Path
    topics: list[BagTopic]
    streams: list[StreamSummary] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def stream(self, name: str) -> StreamSummary | None:
        """The summary of stream ``name`` (``"imu0"`` ...), or ``None`` when it was not imported."""
        return next((s for s in self.streams if s.stream == name), None)
