"""Fixed transforms between sensor frames.

Extrinsics
----------
``/tf_static`` transforms (and any given with ``static_tfs``, in ``static_transform_publisher`` order
``x y z yaw pitch roll parent child``) form a tree; ``T_BS`` of a sensor is the chain of transforms from
the body frame (the odometry's ``child_frame_id``, else ``base_link``) to the sensor message's
``frame_id``. Rotations from yaw, pitch, roll are ``R = Rz(yaw) Ry(pitch) Rx(roll)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable

import numpy as np
from scipy.spatial.transform import Rotation

from fusion_vo.errors import InputError


@dataclass(frozen=True)
class StaticTransform:
    """A fixed transform: pose of frame ``child`` in frame ``parent`` as a 4x4 matrix ``T``."""

    parent: str
    child: str
    T: np.ndarray


def quat_to_matrix(w: float, x: float, y: float, z: float) -> np.ndarray:
    """Rotation matrix of a quaternion ``w + xi + yj + zk`` (normalised first; scipy's ``Rotation``).

    Raises
    ------
    ValueError
        For a zero or non-finite quaternion.
    """
    q = np.array([x, y, z, w], dtype=float)
    n = np.linalg.norm(q)
    if not np.isfinite(n) or n < 1e-9:
        raise ValueError("zero or non-finite quaternion")
    return Rotation.from_quat(q / n).as_matrix()


def ypr_to_matrix(yaw: float, pitch: float, roll: float) -> np.ndarray:
    """``Rz(yaw) Ry(pitch) Rx(roll)``, the rotation of ``static_transform_publisher x y z yaw pitch roll``."""
    return Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()


def parse_static_tf(text: str) -> StaticTransform:
    """Parse ``"x y z yaw pitch roll parent child"`` (or ``"x y z qx qy qz qw parent child"``).

    The order is that of ROS's ``static_transform_publisher``, so a line of a launch file can be pasted.
    """
    parts = text.replace(",", " ").split()
    if len(parts) not in (8, 9):
        raise InputError(f"--static-tf '{text}': expected 'x y z yaw pitch roll parent child' "
                         "or 'x y z qx qy qz qw parent child'")
    try:
        nums = [float(p) for p in parts[:-2]]
    except ValueError:
        raise InputError(f"--static-tf '{text}': the first {len(parts) - 2} fields must be numbers") from None
    if not all(math.isfinite(v) for v in nums):
        raise InputError(f"--static-tf '{text}': values must be finite")
    T = np.eye(4)
    T[:3, 3] = nums[:3]
    if len(nums) == 6:
        T[:3, :3] = ypr_to_matrix(*nums[3:6])
    else:
        try:
            T[:3, :3] = quat_to_matrix(nums[6], nums[3], nums[4], nums[5])
        except ValueError:
            raise InputError(f"--static-tf '{text}': zero quaternion") from None
    return StaticTransform(frame_name(parts[-2]), frame_name(parts[-1]), T)


def check_consistent(transforms: Iterable[StaticTransform], what: str = "--static-tf") -> None:
    """:class:`InputError` for two transforms between the same two frames (either way round) that disagree
    (by more than 1 µm or 1 µrad): the first one found would be used without a word. Repeating one is fine."""
    seen: dict[tuple[str, str], StaticTransform] = {}
    for tf in transforms:
        key = (tf.parent, tf.child)
        first = seen.get(key)
        T = tf.T
        if first is None and (tf.child, tf.parent) in seen:
            first, T = seen[(tf.child, tf.parent)], _inverse(tf.T)
        if first is None:
            seen[key] = tf
        elif not np.allclose(first.T, T, rtol=0, atol=1e-6):
            raise InputError(f"two {what} transforms between '{tf.parent}' and '{tf.child}' disagree "
                             f"(translations {_shown(first.T[:3, 3])} and {_shown(T[:3, 3])} m from "
                             f"'{first.parent}'); give one")


def _shown(v: np.ndarray) -> str:
    return "[" + ", ".join(f"{x:g}" for x in v) + "]"


def chain_transform(transforms: Iterable[StaticTransform], target: str, source: str) -> np.ndarray | None:
    """Pose of frame ``source`` in frame ``target`` from a set of fixed transforms, or ``None``.

    The transforms are edges of an undirected graph (walked backwards through their inverse); the
    first path found breadth-first is used.
    """
    target, source = frame_name(target), frame_name(source)
    if target == source:
        return np.eye(4)
    edges: dict[str, list[tuple[str, np.ndarray]]] = {}
    for tf in transforms:
        edges.setdefault(tf.parent, []).append((tf.child, tf.T))
        edges.setdefault(tf.child, []).append((tf.parent, _inverse(tf.T)))
    best = {target: np.eye(4)}
    queue = [target]
    while queue:
        frame = queue.pop(0)
        for nxt, T in edges.get(frame, []):
            if nxt not in best:
                best[nxt] = best[frame] @ T
                if nxt == source:
                    return best[nxt]
                queue.append(nxt)
    return None


def _inverse(T: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = T[:3, :3].T
    out[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return out


def frame_name(name: str) -> str:
    return name.strip().lstrip("/")
