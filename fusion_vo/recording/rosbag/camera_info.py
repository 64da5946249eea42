"""``sensor_msgs/CameraInfo`` to the entries of ``cam0/sensor.yaml``.

The pinhole intrinsics are ``fx = K[0]``, ``fy = K[4]``, ``cx = K[2]``, ``cy = K[5]`` of the row-major
``K``; ``plumb_bob`` and ``rational_polynomial`` distortions become ``radial-tangential`` (``k1, k2, p1,
p2[, k3]``), ``equidistant``/``fisheye`` stays ``equidistant`` (``k1..k4``).
"""

from __future__ import annotations

from typing import Sequence

from fusion_vo.errors import InputError
from fusion_vo.recording.rosbag.reader import CAMERA_INFO, BagTopic


def pick_camera_info(topics: Sequence[BagTopic], image: BagTopic | None) -> str | None:
    """The ``CameraInfo`` topic that goes with ``image``: the only one, or the one in its namespace."""
    if image is None:
        return None
    infos = [t.topic for t in topics if t.msgtype == CAMERA_INFO]
    if len(infos) == 1:
        return infos[0]
    parts = image.topic.rstrip("/").split("/")
    for depth in range(len(parts) - 1, 0, -1):
        ns = "/".join(parts[:depth])
        near = [i for i in infos if i.rsplit("/", 1)[0] == ns]
        if len(near) == 1:
            return near[0]
    return None


def camera_info_yaml(info, rate_hz: float | None, notes: list[str]) -> dict:
    """``cam0/sensor.yaml`` entries from a ``sensor_msgs/CameraInfo`` message."""
    K = [float(v) for v in info.k]
    D = [float(v) for v in info.d]
    model = str(info.distortion_model).lower()
    data = {"sensor_type": "camera", "rate_hz": rate_hz, "resolution": [int(info.width), int(info.height)],
            "camera_model": "pinhole", "intrinsics": [K[0], K[4], K[2], K[5]]}
    if not any(D):
        data["distortion_model"] = "none"
        data["distortion_coefficients"] = []
    elif model in ("plumb_bob", "rational_polynomial") and len(D) >= 4:
        keep = D[:5] if len(D) >= 5 else D[:4]
        if model == "rational_polynomial" and any(D[5:]):
            notes.append("CameraInfo rational_polynomial: only k1, k2, p1, p2, k3 were kept")
        data["distortion_model"] = "radial-tangential"
        data["distortion_coefficients"] = keep
    elif model in ("equidistant", "fisheye") and len(D) >= 4:
        data["distortion_model"] = "equidistant"
        data["distortion_coefficients"] = D[:4]
    else:
        raise InputError(f"CameraInfo distortion model '{info.distortion_model}' with {len(D)} coefficients "
                         "is not supported; give --camera-yaml")
    return data
