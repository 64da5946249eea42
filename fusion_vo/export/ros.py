"""A run's trajectories as ROS 2 messages, in a rosbag2 folder or a single MCAP file.

Every trajectory ``NAME.tum`` of a run folder becomes the topic ``/fusion_vo/NAME/odometry`` of
``nav_msgs/msg/Odometry`` messages, one per pose, stamped with the pose's timestamp, which is on the
recording's clock (the nanosecond timestamps of its ``data.csv`` files). Each pose is also broadcast on
``/tf`` (``tf2_msgs/msg/TFMessage``) as the transform from ``frame_id`` (default ``odom``) to
``NAME/base_link``, so that RViz and Foxglove can show every trajectory at once. A ``NAME`` that ROS 2 does
not allow in a name (``my-traj``, ``2nd traj``) is written as :func:`ros_name` makes it (``my_traj``,
``t_2nd_traj``); two trajectories that would share a topic are an error.

Covariance (ROS order ``x, y, z, rot x, rot y, rot z``, row-major 6 x 6):

* ``pose.covariance`` holds the planar (x, y, yaw) covariance read from ``NAME.cov.csv`` beside the
  trajectory (header ``# timestamp [s],xx,xy,xyaw,yy,yyaw,yawyaw``, one row per pose with the same
  timestamps, the upper triangle). The rows and columns of z, roll and pitch are 0: the motion is
  planar by construction, they are not estimated.
* Without a covariance file the whole matrix is 0, which the ROS message definitions read as
  "covariance unknown".
* ``twist`` holds the body velocity (vx, vy, yaw rate) between a pose and the next one (the last pose
  repeats the one before); its covariance is unknown (all 0).

The ``rosbag2`` format writes a folder (``metadata.yaml`` and an SQLite ``.db3``) with the rosbags
library; ``mcap`` writes one ``.mcap`` file (ROS 2 profile, CDR messages, ``ros2msg`` schemas) with
the mcap library. Both open in Foxglove; the rosbag2 folder plays back with ``ros2 bag play`` for RViz.
The output is written under a temporary name beside ``out`` and moved to ``out`` only when complete; an
existing ``out`` is an error and is never overwritten, also when another command created it meanwhile.
"""

from __future__ import annotations

import errno
import logging
import os
import re
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fusion_vo.backends.result import COV_HEADER  # noqa: F401  (the format read here, written by the backends)
from fusion_vo.errors import InputError
from fusion_vo.evaluation.io import find_trajectories, read_run_config, read_tum_poses
from fusion_vo.geometry import se2
from fusion_vo.recording import Recording

log = logging.getLogger(__name__)

FORMATS = ("rosbag2", "mcap")
#: indices of (x, y, yaw) in ROS's 6 x 6 pose covariance (x, y, z, rot x, rot y, rot z)
_ROS_INDEX = (0, 1, 5)
_ODOMETRY = "nav_msgs/msg/Odometry"
_TF = "tf2_msgs/msg/TFMessage"


@dataclass
class ExportTrajectory:
    """One trajectory to export.

    Attributes
    ----------
    name : str
        Trajectory name (``vo``, ``ekf``, ``gtsam``, ...): topic ``/fusion_vo/NAME/odometry``.
    stamp_ns : ndarray of int64, shape (n,)
        Timestamps on the recording's clock [ns].
    xyz : ndarray, shape (n, 3)
        Positions [m].
    quat_wxyz : ndarray, shape (n, 4)
        Orientations.
    covariance : ndarray, shape (n, 3, 3), or None
        Covariance of (x, y, yaw) per pose [m², m·rad, rad²]; ``None`` when unknown.
    """

    name: str
    stamp_ns: np.ndarray
    xyz: np.ndarray
    quat_wxyz: np.ndarray
    covariance: np.ndarray | None = None

    @property
    def ros_name(self) -> str:
        """The name as ROS 2 allows it in a topic or frame (:func:`ros_name`)."""
        return ros_name(self.name)

    @property
    def topic(self) -> str:
        return f"/fusion_vo/{self.ros_name}/odometry"


def ros_name(name: str) -> str:
    """``name`` as one token of a ROS 2 name: ASCII letters, digits and single underscores, not starting with a
    digit. Every other character (and a run of them) becomes one underscore, underscores at the ends go, and
    a name that would start with a digit (or be empty) gets ``t_`` in front: ``my-traj`` -> ``my_traj``,
    ``2nd traj`` -> ``t_2nd_traj``; a valid name is kept as it is."""
    token = re.sub(r"_+", "_", re.sub(r"[^A-Za-z0-9_]", "_", name)).strip("_")
    return token if token and not token[0].isdigit() else f"t_{token}".rstrip("_")


def read_pose_covariances(path: str | Path, stamp_ns: np.ndarray) -> np.ndarray:
    """Read ``NAME.cov.csv``: the (x, y, yaw) covariance of each pose of ``NAME.tum``.

    Parameters
    ----------
    path : str or Path
        The file: header ``# timestamp [s],xx,xy,xyaw,yy,yyaw,yawyaw``, then one row per pose.
    stamp_ns : ndarray of int64
        The trajectory's timestamps [ns]; every one needs a row with the same timestamp (to 1 µs).

    Returns
    -------
    ndarray, shape (n, 3, 3)
        Symmetric covariance matrices, in the order of ``stamp_ns``.

    Raises
    ------
    InputError
        Naming the file and line: a row without seven finite numbers, a negative variance, or a pose of
        the trajectory without a row.
    """
    from decimal import Decimal, InvalidOperation

    path = Path(path)
    try:
        lines = path.read_text(encoding="utf-8-sig").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read file: {exc}", path) from None
    rows: dict[int, np.ndarray] = {}
    for number, text in enumerate(lines, start=1):
        text = text.strip()
        if not text or text.startswith("#"):
            continue
        fields = [f.strip() for f in text.split(",")]
        if len(fields) != 7:
            raise InputError(f"expected 7 columns 'timestamp,xx,xy,xyaw,yy,yyaw,yawyaw', got {len(fields)}",
                             path, number)
        try:
            stamp = int((Decimal(fields[0]) * 1_000_000_000).to_integral_value())
            values = np.array([float(f) for f in fields[1:]])
        except (InvalidOperation, ValueError):
            raise InputError(f"expected numbers, got {text!r}", path, number) from None
        if not np.all(np.isfinite(values)):
            raise InputError("non-finite covariance (NaN or inf)", path, number)
        xx, xy, xyaw, yy, yyaw, yawyaw = values
        if min(xx, yy, yawyaw) < 0:
            raise InputError("negative variance", path, number)
        rows[stamp // 1000] = np.array([[xx, xy, xyaw], [xy, yy, yyaw], [xyaw, yyaw, yawyaw]])
    out = np.empty((len(stamp_ns), 3, 3))
    for i, stamp in enumerate(np.asarray(stamp_ns, dtype=np.int64)):
        key = int(stamp) // 1000
        cov = rows.get(key, rows.get(key - 1, rows.get(key + 1)))
        if cov is None:
            raise InputError(f"no covariance row for the pose at {int(stamp) * 1e-9:.9f} s", path)
        out[i] = cov
    return out


def load_run_trajectories(run_dir: str | Path, names: list[str] | None = None) -> list[ExportTrajectory]:
    """The trajectories of a run folder, each with its per-pose covariance when ``NAME.cov.csv`` exists.

    Raises
    ------
    InputError
        If the folder has no trajectory, a requested name is not in it, or a file is malformed.
    """
    files = find_trajectories(run_dir)
    if names:
        missing = [n for n in names if n not in files]
        if missing:
            raise InputError(f"no trajectory '{missing[0]}' (the run has: {', '.join(files)})", run_dir)
        files = {n: files[n] for n in names}
    out = []
    for name, path in files.items():
        poses = read_tum_poses(path)
        cov_path = path.with_name(f"{name}.cov.csv")
        cov = read_pose_covariances(cov_path, poses.stamp_ns) if cov_path.is_file() else None
        if cov is None:
            log.info("%s has no %s: its covariance is exported as unknown", path.name, cov_path.name)
        out.append(ExportTrajectory(name, poses.stamp_ns, poses.xyz, poses.quat_wxyz, cov))
    return out


def groundtruth_of_run(run_dir: str | Path) -> ExportTrajectory | None:
    """The ground truth of the recording named by ``run.yaml`` (as ``groundtruth``), or ``None`` when the
    run names no recording, it is not there or has no ground truth."""
    named = read_run_config(run_dir).get("sequence")
    if not named or not Path(str(named)).is_dir():
        return None
    rec = Recording(named)
    if not rec.has_groundtruth():
        return None
    gt = rec.groundtruth()
    quat = gt.quat_wxyz if gt.quat_wxyz is not None else se2.quaternion_of_yaw(gt.xyyaw[:, 2])
    z = gt.z if gt.z is not None else np.zeros(len(gt))
    stamp_ns = np.round(np.asarray(gt.t, dtype=np.float64) * 1e9).astype(np.int64)
    return ExportTrajectory("groundtruth", stamp_ns, np.column_stack([gt.xyyaw[:, :2], z]), quat, None)


def _ros_covariance(cov3: np.ndarray | None) -> np.ndarray:
    full = np.zeros((6, 6))
    if cov3 is not None:
        full[np.ix_(_ROS_INDEX, _ROS_INDEX)] = cov3
    return full.reshape(36)


def _body_twists(traj: ExportTrajectory) -> np.ndarray:
    """(vx, vy, yaw rate) from each pose to the next (the last repeats the one before)."""
    n = len(traj.stamp_ns)
    twists = np.zeros((n, 3))
    if n < 2:
        return twists
    yaw = se2.yaw_of_quaternion(traj.quat_wxyz)
    t = traj.stamp_ns.astype(np.float64) * 1e-9
    for i in range(n - 1):
        dt = t[i + 1] - t[i]
        if dt > 0:
            a = (traj.xyz[i, 0], traj.xyz[i, 1], yaw[i])
            b = (traj.xyz[i + 1, 0], traj.xyz[i + 1, 1], yaw[i + 1])
            twists[i] = se2.log(se2.between(a, b)) / dt
    twists[-1] = twists[-2]
    return twists


class _Messages:
    """Builds and serialises the ROS 2 messages (rosbags' type store, CDR)."""

    def __init__(self) -> None:
        from rosbags.typesys import Stores, get_typestore

        self.store = get_typestore(Stores.ROS2_HUMBLE)
        self.t = self.store.types

    def msgdef(self, typename: str) -> str:
        return self.store.generate_msgdef(typename, ros_version=2)[0]

    def header(self, stamp_ns: int, frame_id: str):
        sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
        return self.t["std_msgs/msg/Header"](stamp=self.t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec),
                                             frame_id=frame_id)

    def odometry(self, traj: ExportTrajectory, i: int, twist: np.ndarray, frame_id: str) -> bytes:
        t = self.t
        x, y, z = (float(v) for v in traj.xyz[i])
        w, qx, qy, qz = (float(v) for v in traj.quat_wxyz[i])
        pose = t["geometry_msgs/msg/PoseWithCovariance"](
            pose=t["geometry_msgs/msg/Pose"](position=t["geometry_msgs/msg/Point"](x=x, y=y, z=z),
                                             orientation=t["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=w)),
            covariance=_ros_covariance(None if traj.covariance is None else traj.covariance[i]))
        vel = t["geometry_msgs/msg/TwistWithCovariance"](
            twist=t["geometry_msgs/msg/Twist"](
                linear=t["geometry_msgs/msg/Vector3"](x=float(twist[0]), y=float(twist[1]), z=0.0),
                angular=t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=float(twist[2]))),
            covariance=np.zeros(36))
        msg = t[_ODOMETRY](header=self.header(traj.stamp_ns[i], frame_id), child_frame_id=f"{traj.ros_name}/base_link",
                           pose=pose, twist=vel)
        return bytes(self.store.serialize_cdr(msg, _ODOMETRY))

    def tf(self, traj: ExportTrajectory, i: int, frame_id: str) -> bytes:
        t = self.t
        x, y, z = (float(v) for v in traj.xyz[i])
        w, qx, qy, qz = (float(v) for v in traj.quat_wxyz[i])
        stamped = t["geometry_msgs/msg/TransformStamped"](
            header=self.header(traj.stamp_ns[i], frame_id), child_frame_id=f"{traj.ros_name}/base_link",
            transform=t["geometry_msgs/msg/Transform"](
                translation=t["geometry_msgs/msg/Vector3"](x=x, y=y, z=z),
                rotation=t["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=w)))
        return bytes(self.store.serialize_cdr(t[_TF](transforms=[stamped]), _TF))


def _timeline(trajectories: list[ExportTrajectory], messages: _Messages, frame_id: str):
    """(stamp_ns, topic, typename, payload) of every message, in time order."""
    items = []
    for traj in trajectories:
        twists = _body_twists(traj)
        for i, stamp in enumerate(traj.stamp_ns):
            items.append((int(stamp), traj.topic, _ODOMETRY, messages.odometry(traj, i, twists[i], frame_id)))
            items.append((int(stamp), "/tf", _TF, messages.tf(traj, i, frame_id)))
    items.sort(key=lambda item: item[0])
    return items


def _write_rosbag2(path: Path, items, topics: dict[str, str], messages: _Messages) -> None:
    from rosbags.rosbag2 import Writer

    with Writer(path, version=8) as writer:
        connections = {topic: writer.add_connection(topic, typename, typestore=messages.store)
                       for topic, typename in topics.items()}
        for stamp, topic, _, data in items:
            writer.write(connections[topic], stamp, data)


def _write_mcap(path: Path, items, topics: dict[str, str], messages: _Messages) -> None:
    from mcap.writer import Writer

    with open(path, "wb") as stream:
        writer = Writer(stream)
        writer.start(profile="ros2", library="fusion-vo")
        schemas = {typename: writer.register_schema(name=typename, encoding="ros2msg",
                                                    data=messages.msgdef(typename).encode())
                   for typename in sorted(set(topics.values()))}
        channels = {topic: writer.register_channel(topic=topic, message_encoding="cdr", schema_id=schemas[typename])
                    for topic, typename in topics.items()}
        sequence: dict[str, int] = {}
        for stamp, topic, _, data in items:
            sequence[topic] = sequence.get(topic, 0) + 1
            writer.add_message(channels[topic], log_time=stamp, data=data, publish_time=stamp,
                               sequence=sequence[topic])
        writer.finish()


def export_trajectories(trajectories: list[ExportTrajectory], out: str | Path, fmt: str,
                        frame_id: str = "odom") -> Path:
    """Write trajectories as ``nav_msgs/msg/Odometry`` and ``/tf`` to a rosbag2 folder or an MCAP file.

    Parameters
    ----------
    trajectories : list of ExportTrajectory
        What to write.
    out : str or Path
        The rosbag2 folder or the ``.mcap`` file; it must not exist.
    fmt : str
        ``"rosbag2"`` or ``"mcap"``.
    frame_id : str
        Fixed frame of the poses (``header.frame_id``).

    Returns
    -------
    Path
        ``out``.

    Raises
    ------
    InputError
        For an unknown format, an existing ``out`` or an empty list.
    """
    if fmt not in FORMATS:
        raise InputError(f"unknown export format '{fmt}' (known: {', '.join(FORMATS)})")
    out = Path(out)
    if out.exists() or out.is_symlink():
        raise InputError("already exists; choose another name or remove it first", out)
    if not trajectories:
        raise InputError("nothing to export")
    topics_of: dict[str, str] = {}
    for traj in trajectories:  # two names that ROS 2 would see as one (my-traj and my_traj)
        first = topics_of.setdefault(traj.topic, traj.name)
        if first != traj.name or sum(t.name == traj.name for t in trajectories) > 1:
            raise InputError(f"trajectories '{first}' and '{traj.name}' would both be the topic {traj.topic} "
                             "(ROS 2 names hold letters, digits and underscores only); rename one of them")
    if not out.parent.is_dir():
        raise InputError("folder not found", out.parent)
    messages = _Messages()
    topics = {traj.topic: _ODOMETRY for traj in trajectories}
    topics["/tf"] = _TF
    items = _timeline(trajectories, messages, frame_id)
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-", dir=out.parent))
    try:
        target = staging / out.name
        if fmt == "rosbag2":
            _write_rosbag2(target, items, topics, messages)
        else:
            _write_mcap(target, items, topics, messages)
        _move_into_place(target, out)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    log.info("wrote %d messages on %d topics to %s", len(items), len(topics), out)
    return out


def _move_into_place(target: Path, out: Path) -> None:
    """Move the finished ``target`` to ``out``, only if nothing is at ``out``: of two exports to one name
    started together, the second to finish fails naming ``out`` and the first's output stays.

    A file is hard-linked (``link`` fails atomically when ``out`` exists; ``rename`` would replace it); a
    folder is renamed, which fails when ``out`` is a file or a folder that is not empty.
    """
    taken = InputError("already exists (written meanwhile by another command?); choose another name or remove "
                       "it first", out)
    if not target.is_dir():
        try:
            os.link(target, out)
            return
        except FileExistsError:
            raise taken from None
        except OSError:  # a file system without hard links: checked, then renamed
            pass
    if out.exists() or out.is_symlink():
        raise taken
    try:
        os.rename(target, out)
    except OSError as exc:
        if exc.errno in (errno.EEXIST, errno.ENOTEMPTY, errno.ENOTDIR, errno.EISDIR):
            raise taken from None
        raise


def export_run(run_dir: str | Path, out: str | Path, fmt: str, names: list[str] | None = None,
               frame_id: str = "odom") -> tuple[Path, list[ExportTrajectory]]:
    """Export the trajectories of a run folder (see the module description); returns ``out`` and them."""
    trajectories = load_run_trajectories(run_dir, names)
    return export_trajectories(trajectories, out, fmt, frame_id), trajectories


def pose_covariance_6x6(message_covariance) -> np.ndarray:
    """The (x, y, yaw) block of a ROS 6 x 6 pose covariance (for reading exported messages back)."""
    full = np.asarray(message_covariance, dtype=np.float64).reshape(6, 6)
    return full[np.ix_(_ROS_INDEX, _ROS_INDEX)]


def is_unknown(message_covariance) -> bool:
    """Whether a ROS covariance is the "unknown" all-zero matrix."""
    return not np.any(np.asarray(message_covariance))
