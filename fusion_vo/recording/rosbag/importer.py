"""Import a ROS bag into the recording layout, one pass over its messages.

Each supported topic becomes one stream of the recording folder::

    sensor_msgs/Image, CompressedImage  ->  cam0/data.csv + cam0/data/<t>.png (grey, 8 or 16 bit)
    sensor_msgs/CameraInfo              ->  cam0/sensor.yaml (unless --camera-yaml is given)
    sensor_msgs/Imu                     ->  imu0/data.csv (+ q_RS_w,x,y,z when the IMU gives an orientation)
    nav_msgs/Odometry                   ->  odom0/data.csv (body twist) and odom0/pose.csv (its pose)
    sensor_msgs/NavSatFix               ->  gps0/data.csv (latitude, longitude, altitude, local ENU, status,
                                            covariance type and the east-north covariance)
    tf2_msgs/TFMessage on /tf_static    ->  T_BS of imu0, cam0 and gps0

IMU noise densities, when the messages carry covariances, are ``sqrt(median(covariance) / rate_hz)``;
the GPS horizontal sigma is the median of ``sqrt((cov_xx + cov_yy) / 2)``.

The output is written by :class:`fusion_vo.recording.writer.RecordingWriter` (a staging folder moved into
place only when complete, so an interrupted import never leaves a folder that looks like a finished
recording; an existing folder is replaced only if fusion-vo wrote it, or with ``overwrite``).
"""

from __future__ import annotations

import logging
import math
from pathlib import Path
from typing import Sequence

import numpy as np

from fusion_vo.config.files import load_yaml
from fusion_vo.config.sensor_files import camera_model
from fusion_vo.errors import InputError
from fusion_vo.recording.rosbag.camera_info import camera_info_yaml, pick_camera_info
from fusion_vo.recording.rosbag.images import UnsupportedImage, compressed_to_grey, image_to_grey
from fusion_vo.recording.rosbag.reader import (
    CAMERA_INFO,
    IMAGE,
    TF_MESSAGE,
    BagTopic,
    bag_topics,
    header_stamp,
    one_line,
    opened,
    select_topics,
)
from fusion_vo.recording.rosbag.streams import Rows, finite, matrix_entry
from fusion_vo.recording.writer import RecordingWriter, check_target, write_csv, write_image, write_lines, write_yaml
from fusion_vo.recording.rosbag.summary import ImportSummary, StreamSummary
from fusion_vo.recording.rosbag.transforms import (
    StaticTransform,
    chain_transform,
    check_consistent,
    frame_name,
    quat_to_matrix,
)
from fusion_vo.recording.gps import HEADER as GPS_HEADER
from fusion_vo.recording.gps import format_rows as gps_rows
from fusion_vo.recording.gps import geodetic_to_enu

log = logging.getLogger(__name__)


def import_bag(
    bag: str | Path,
    out: str | Path,
    *,
    image_topic: str | None = None,
    imu_topic: str | Sequence[str] | None = None,
    odom_topic: str | Sequence[str] | None = None,
    gps_topic: str | None = None,
    camera_yaml: str | Path | None = None,
    static_tfs: Sequence[StaticTransform] = (),
    overwrite: bool = False,
) -> ImportSummary:
    """Write the recording folder ``out`` from the supported topics of ``bag``.

    Parameters
    ----------
    bag : path of a ROS 1 ``.bag`` file, a ROS 2 bag folder, or a ROS 2 ``.mcap``/``.db3`` file.
    out : the recording folder to create.
    image_topic, imu_topic, odom_topic, gps_topic : topic of each stream; when ``None`` the single topic
        of the stream's message type is taken (none: the stream is left out; several: an error). ``imu_topic``
        and ``odom_topic`` may be a list of topics: the first is written to ``imu0/`` (``odom0/``), the next to
        ``imu1/`` (``odom1/``) and so on, up to ``imu9/`` (``odom9/``); one topic may be listed more than once.
    camera_yaml : a ``cam0/sensor.yaml`` to use instead of the bag's ``CameraInfo``.
    static_tfs : fixed transforms to add to the bag's ``/tf_static`` (see :func:`parse_static_tf`); two
        between the same frames that disagree are an error.
    overwrite : replace ``out`` if it exists.

    Returns
    -------
    ImportSummary

    Raises
    ------
    InputError
        For a missing or unreadable bag, an unknown topic or one of the wrong type, an existing ``out``
        without ``overwrite``, or a bag without any supported topic.
    """
    bag, out = Path(bag), Path(out)
    check_consistent(static_tfs)  # two that disagree: which one holds?
    inputs = [bag] + ([Path(camera_yaml)] if camera_yaml is not None else [])
    check_target(out, overwrite, inputs)  # before reading the bag; again when the writer opens
    cam_yaml = load_yaml(camera_yaml) if camera_yaml is not None else None
    with opened(bag) as reader:
        topics = bag_topics(reader)
        requested = {"cam0": image_topic, **_instances("imu", imu_topic), **_instances("odom", odom_topic),
                     "gps0": gps_topic}
        chosen = select_topics(topics, requested, bag)
        if not chosen:
            raise InputError("no supported topic (sensor_msgs/Image, CompressedImage, Imu, NavSatFix, "
                             f"nav_msgs/Odometry); topics: {', '.join(t.topic for t in topics) or 'none'}", bag)
        if cam_yaml is not None and "cam0" not in chosen:
            raise InputError("--camera-yaml given but the bag has no image topic", bag)
        summary = ImportSummary(bag, out, topics)
        with RecordingWriter(out, force=overwrite, inputs=inputs, source=f"import-bag {bag.name}") as writer:
            _Importer(reader, bag, writer.root, chosen, topics, cam_yaml, camera_yaml, list(static_tfs),
                      summary).run({name for name, topic in requested.items() if topic})
            writer.commit()
    for s in summary.streams:
        log.debug("%s <- %s: %d rows, %.1f Hz, %d duplicates, %d dropped", s.stream, s.topic, s.written,
                 s.rate_hz or 0.0, s.duplicates, s.dropped)
    for note in summary.notes:
        log.debug("note: %s", note)
    return summary


#: the option of ``fusion-vo import-bag`` that names each stream's topic
TOPIC_OPTIONS = {"cam0": "--image-topic", "imu0": "--imu-topic", "odom0": "--odom-topic", "gps0": "--gps-topic"}
#: the most instances of a kind a recording holds (``imu0`` ... ``imu9``)
MAX_INSTANCES = 10


def _instances(kind: str, topics: str | Sequence[str] | None) -> dict[str, str | None]:
    """``{KIND0: topic, KIND1: topic, ...}`` of one topic or a list of them (``{KIND0: None}`` for none)."""
    if topics is None or isinstance(topics, str):
        return {f"{kind}0": topics}
    topics = list(topics)
    if len(topics) > MAX_INSTANCES:
        raise InputError(f"{TOPIC_OPTIONS[kind + '0']} given {len(topics)} times: at most {MAX_INSTANCES} "
                         f"({kind}0/ ... {kind}{MAX_INSTANCES - 1}/)")
    return {f"{kind}{i}": topic for i, topic in enumerate(topics)} if topics else {f"{kind}0": None}


def _kind(stream: str) -> str:
    """The stream's instance 0 (``imu0`` of ``imu2``)."""
    return stream.rstrip("0123456789") + "0"


class _Importer:
    """One pass over the bag's selected topics, writing into the temporary folder ``root``."""

    def __init__(self, reader, bag: Path, root: Path, chosen: dict[str, BagTopic], topics: list[BagTopic],
                 cam_yaml: dict | None, cam_yaml_path, static_tfs: list[StaticTransform], summary: ImportSummary):
        self.reader, self.bag, self.root = reader, bag, root
        self.chosen, self.summary = chosen, summary
        self.cam_yaml, self.cam_yaml_path = cam_yaml, cam_yaml_path
        self.transforms = list(static_tfs)
        self.frames: dict[str, str] = {}  # stream -> frame_id of its messages
        self.body_frame: str | None = None
        self.rows = {name: Rows(StreamSummary(name, t.topic, t.msgtype)) for name, t in chosen.items()}
        self.image_size: tuple[int, int] | None = None
        self.written_images: set[int] = set()
        self.imu_missing_orientation: dict[str, int] = {}  # IMU stream -> messages without an orientation
        self.imu_covariance: dict[str, dict[str, list[float]]] = {}  # IMU stream -> its gyro's and accel's
        self.gps_sigma: list[float] = []
        self.camera_info = None
        self.caminfo_topic = pick_camera_info(topics, chosen.get("cam0")) if cam_yaml is None else None
        self.tf_topics = [t.topic for t in topics if t.msgtype == TF_MESSAGE and frame_name(t.topic) == "tf_static"]

    # -------------------------------------------------------------- main loop
    def run(self, explicit: set[str] = frozenset()) -> None:
        """Read the messages and write the streams; a stream whose topic has no message is left out (its
        folder would make the recording claim a sensor it has no sample of), an error when its topic was
        given (``explicit``)."""
        wanted: dict[str, list[str]] = {}  # topic -> the streams it is written to
        for name, t in self.chosen.items():
            wanted.setdefault(t.topic, []).append(name)
        extra = set(self.tf_topics) | ({self.caminfo_topic} if self.caminfo_topic else set())
        conns = [c for c in self.reader.connections if c.topic in wanted or c.topic in extra]
        handlers = {"cam0": self._image, "imu0": self._imu, "odom0": self._odom, "gps0": self._gps}
        for conn, bag_t, msg in self._messages(conns):
            if conn.topic in wanted:
                for name in wanted[conn.topic]:
                    self.rows[name].summary.messages += 1
                    handlers[_kind(name)](msg, bag_t, name)
            elif conn.msgtype == TF_MESSAGE:
                self._tf(msg)
            elif self.camera_info is None and conn.msgtype == CAMERA_INFO and float(msg.k[0]) > 0:
                self.camera_info = msg
        self.body_frame = self.body_frame or "base_link"
        empty = [name for name in self.chosen if not self.rows[name].summary.messages]
        for name in empty:
            topic = self.chosen[name].topic
            if name in explicit:
                raise InputError(f"{TOPIC_OPTIONS[_kind(name)]} {topic}: the topic has no message", self.bag)
            self.summary.notes.append(f"{topic}: no message; {name}/ not written")
        if len(empty) == len(self.chosen):
            raise InputError("no message on any supported topic (" + ", ".join(self.chosen[n].topic for n in empty)
                             + ")", self.bag)
        for name in self.chosen:
            if name not in empty:
                finish = {"cam0": self._finish_cam0, "imu0": self._finish_imu, "odom0": self._finish_odom,
                          "gps0": self._finish_gps0}[_kind(name)]
                finish(name)
            self.summary.streams.append(self.rows[name].summary)

    def _messages(self, conns):
        """Decoded ``(connection, bag time, message)`` in bag order; a damaged bag is an InputError."""
        stream = iter(self.reader.messages(connections=conns))
        while True:
            try:
                conn, bag_t, raw = next(stream)
                msg = self.reader.deserialize(raw, conn.msgtype)
            except StopIteration:
                return
            except Exception as exc:  # damaged chunks fail in rosbags or its decompressors, in many ways
                raise InputError(f"cannot read the bag ({one_line(exc)})", self.bag) from None
            yield conn, bag_t, msg

    def _header_time(self, name: str, msg, bag_t: int) -> int:
        t, fallback = header_stamp(msg.header, bag_t)
        if fallback:
            self.rows[name].summary.bag_time_stamps += 1
        if name not in self.frames and msg.header.frame_id:
            self.frames[name] = frame_name(msg.header.frame_id)
        return t

    # -------------------------------------------------------------- per message
    def _image(self, msg, bag_t: int, name: str = "cam0") -> None:
        rows = self.rows["cam0"]
        t = self._header_time("cam0", msg, bag_t)
        if t in self.written_images:
            rows.summary.duplicates += 1  # the first image with this stamp is kept
            return
        try:
            img = image_to_grey(msg) if rows.summary.msgtype == IMAGE else compressed_to_grey(msg)
        except UnsupportedImage as exc:
            raise InputError(f"{rows.summary.topic}: {exc}", self.bag) from None
        except ValueError as exc:
            rows.summary.dropped += 1
            log.warning("%s: image at %d ns skipped: %s", rows.summary.topic, t, exc)
            return
        size = (img.shape[1], img.shape[0])
        if self.image_size is None:
            self.image_size = size
        elif size != self.image_size:
            rows.summary.dropped += 1
            log.warning("%s: image at %d ns is %dx%d, not %dx%d like the first; skipped", rows.summary.topic, t,
                        *size, *self.image_size)
            return
        path = self.root / "cam0" / "data" / f"{t}.png"
        write_image(path, img)
        self.written_images.add(t)
        rows.add(t, (path.name,))

    def _imu(self, msg, bag_t: int, name: str = "imu0") -> None:
        rows = self.rows[name]
        t = self._header_time(name, msg, bag_t)
        w, a, q = msg.angular_velocity, msg.linear_acceleration, msg.orientation
        values = (float(w.x), float(w.y), float(w.z), float(a.x), float(a.y), float(a.z))
        if not finite(values):
            rows.summary.dropped += 1
            return
        quat = (float(q.w), float(q.x), float(q.y), float(q.z))
        has_q = float(msg.orientation_covariance[0]) != -1.0 and finite(quat) and \
            abs(math.sqrt(sum(v * v for v in quat)) - 1.0) < 0.05
        if not has_q:
            self.imu_missing_orientation[name] = self.imu_missing_orientation.get(name, 0) + 1
        rows.add(t, values + (quat if has_q else None,))
        covariance = self.imu_covariance.setdefault(name, {"gyro": [], "accel": []})
        if len(covariance["gyro"]) < 1000:
            covariance["gyro"].append(float(msg.angular_velocity_covariance[0]))
            covariance["accel"].append(float(msg.linear_acceleration_covariance[0]))

    def _odom(self, msg, bag_t: int, name: str = "odom0") -> None:
        rows = self.rows[name]
        t = self._header_time(name, msg, bag_t)
        if self.body_frame is None and msg.child_frame_id and name == "odom0":
            self.body_frame = frame_name(msg.child_frame_id)
        tw, p = msg.twist.twist, msg.pose.pose
        twist = (float(tw.linear.x), float(tw.linear.y), float(tw.angular.z))
        pose = (float(p.position.x), float(p.position.y), float(p.position.z), float(p.orientation.w),
                float(p.orientation.x), float(p.orientation.y), float(p.orientation.z))
        if not finite(twist):
            rows.summary.dropped += 1
            return
        rows.add(t, (twist, pose if finite(pose) and any(pose[3:]) else None))

    def _gps(self, msg, bag_t: int, name: str = "gps0") -> None:
        rows = self.rows["gps0"]
        t = self._header_time("gps0", msg, bag_t)
        fix = (float(msg.latitude), float(msg.longitude), float(msg.altitude))
        if int(msg.status.status) < 0 or not finite(fix) or abs(fix[0]) > 90 or abs(fix[1]) > 180:
            rows.summary.dropped += 1
            return
        cov_type = int(msg.position_covariance_type)
        cov = msg.position_covariance
        cov_en = (float(cov[0]), float(cov[1]), float(cov[4])) if cov_type > 0 else (0.0, 0.0, 0.0)
        rows.add(t, (*fix, int(msg.status.status), cov_type, *cov_en))
        if cov_type > 0 and finite(cov_en) and cov_en[0] > 0 and cov_en[2] > 0:
            self.gps_sigma.append(math.sqrt(0.5 * (cov_en[0] + cov_en[2])))

    def _tf(self, msg) -> None:
        for ts in msg.transforms:
            tr, rq = ts.transform.translation, ts.transform.rotation
            T = np.eye(4)
            try:
                T[:3, :3] = quat_to_matrix(float(rq.w), float(rq.x), float(rq.y), float(rq.z))
            except ValueError:
                continue
            T[:3, 3] = [float(tr.x), float(tr.y), float(tr.z)]
            self.transforms.append(StaticTransform(frame_name(ts.header.frame_id), frame_name(ts.child_frame_id), T))

    # -------------------------------------------------------------- finishing
    def _extrinsics(self, stream: str) -> tuple[np.ndarray | None, str]:
        frame = self.frames.get(stream)
        if frame is None:
            return None, "its messages name no frame_id"
        if frame == self.body_frame:
            return np.eye(4), f"identity: the messages are in the body frame '{frame}'"
        T = chain_transform(self.transforms, self.body_frame, frame)
        if T is None:
            return None, f"no fixed transform from '{self.body_frame}' to '{frame}'"
        return T, f"from the fixed transforms '{self.body_frame}' -> '{frame}'"

    def _finish_cam0(self, name: str = "cam0") -> None:
        rows = self.rows["cam0"]
        t, values = rows.finish()
        write_csv(self.root / "cam0" / "data.csv", "#timestamp [ns],filename", t, values, "%s")
        if not len(t):
            self.summary.notes.append(f"{rows.summary.topic}: no usable image")
            return
        T, how = self._extrinsics("cam0")
        data: dict
        if self.cam_yaml is not None:
            data = dict(self.cam_yaml)
            data.setdefault("rate_hz", rows.summary.rate_hz)
            data.setdefault("resolution", list(self.image_size))
            source = f"from {self.cam_yaml_path}"
            if "T_BS" not in data and T is not None:
                data["T_BS"] = matrix_entry(T)
        elif self.camera_info is not None:
            data = camera_info_yaml(self.camera_info, rows.summary.rate_hz, self.summary.notes)
            source = f"from {self.caminfo_topic}"
            if T is not None:
                data["T_BS"] = matrix_entry(T)
        else:
            self.summary.notes.append("cam0/sensor.yaml not written: the bag has no CameraInfo topic; "
                                      "give --camera-yaml")
            return
        if "T_BS" not in data:
            self.summary.notes.append(f"cam0 T_BS unknown ({how}): the default mounting (looking straight "
                                      "down, 0.25 m ahead of the axle, 0.1 m up) was written; edit it")
        model = camera_model(data, self.cam_yaml_path or self.bag)
        if (model.width, model.height) != tuple(self.image_size):
            raise InputError(f"camera calibration is for {model.width}x{model.height} but the images are "
                             f"{self.image_size[0]}x{self.image_size[1]}", self.cam_yaml_path or self.bag)
        write_yaml(self.root / "cam0" / "sensor.yaml", model.to_dict(),
                   [f"camera of {rows.summary.topic} ({rows.summary.msgtype}), calibration {source}",
                    f"T_BS {how}" if "T_BS" in data else "T_BS: default mounting, not from the bag"])

    def _finish_imu(self, name: str = "imu0") -> None:
        rows = self.rows[name]
        t, values = rows.finish()
        with_q = bool(values) and all(v[6] is not None for v in values)
        header = ("#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
                  "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]")
        if with_q:
            header += ",q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []"
            table = [v[:6] + v[6] for v in values]
        else:
            table = [v[:6] for v in values]
            if any(v[6] is not None for v in values):
                self.summary.notes.append(f"{rows.summary.topic}: {self.imu_missing_orientation.get(name, 0)} messages "
                                          "without an orientation; the quaternion columns were left out")
        write_csv(self.root / name / "data.csv", header, t, table, "%.9g")
        T, how = self._extrinsics(name)
        comments = [f"IMU of {rows.summary.topic}, frame '{self.frames.get(name, '')}'"]
        if T is None:
            T = np.eye(4)
            comments.append(f"T_BS is the identity: {how}; edit it if the IMU is not aligned with the body")
            self.summary.notes.append(f"{name} T_BS set to the identity ({how})")
        else:
            comments.append(f"T_BS {how}")
        data = {"sensor_type": "imu", "rate_hz": rows.summary.rate_hz, "T_BS": matrix_entry(T)}
        rate = rows.summary.rate_hz or 0.0
        for key, sensor in (("gyroscope_noise_density", "gyro"), ("accelerometer_noise_density", "accel")):
            var = [v for v in self.imu_covariance.get(name, {}).get(sensor, []) if v > 0]
            if var and rate > 0:
                data[key] = float(f"{math.sqrt(float(np.median(var)) / rate):.6g}")
        if len(data) > 3:
            comments.append("noise densities = sqrt(message covariance / rate_hz)")
        write_yaml(self.root / name / "sensor.yaml", data, comments)

    def _finish_odom(self, name: str = "odom0") -> None:
        rows = self.rows[name]
        t, values = rows.finish()
        write_csv(self.root / name / "data.csv",
                   "#timestamp [ns],v_x [m s^-1],v_y [m s^-1],w_z [rad s^-1]", t, [v[0] for v in values], "%.9g")
        poses = [(ti, v[1]) for ti, v in zip(t, values) if v[1] is not None]
        write_csv(self.root / name / "pose.csv",
                   "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []",
                   np.array([p[0] for p in poses], dtype=np.int64), [p[1] for p in poses], "%.9g")

    def _finish_gps0(self, name: str = "gps0") -> None:
        rows = self.rows["gps0"]
        t, values = rows.finish()
        table = np.array(values, dtype=float).reshape(-1, 8)
        fixes = table[:, :3]
        enu = geodetic_to_enu(fixes[:, 0], fixes[:, 1], fixes[:, 2], fixes[0]) if len(fixes) else fixes
        lines = gps_rows(t, fixes, enu, table[:, 3], table[:, 4], table[:, 5:8])
        write_lines(self.root / "gps0" / "data.csv", GPS_HEADER, lines)
        T, how = self._extrinsics("gps0")
        data = {"sensor_type": "gnss", "rate_hz": rows.summary.rate_hz}
        if len(fixes):
            data["datum"] = {"latitude": float(fixes[0, 0]), "longitude": float(fixes[0, 1]),
                             "altitude": float(fixes[0, 2])}
        if self.gps_sigma:
            data["horizontal_sigma_m"] = float(f"{np.median(self.gps_sigma):.4g}")
        comments = [f"GNSS receiver of {rows.summary.topic}, frame '{self.frames.get('gps0', '')}'",
                    "e, n, u of data.csv: local East-North-Up [m] relative to datum (WGS-84)"]
        if T is not None:
            data["T_BS"] = matrix_entry(T)
            comments.append(f"T_BS (antenna in the body frame) {how}")
        write_yaml(self.root / "gps0" / "sensor.yaml", data, comments)
