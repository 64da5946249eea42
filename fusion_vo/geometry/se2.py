"""Planar rigid motions SE(2).

A pose or increment is a vector ``(x, y, yaw)``; its matrix is::

    T = [[cos yaw, -sin yaw, x],
         [sin yaw,  cos yaw, y],
         [0,        0,       1]]

``compose(a, b)`` is ``T_a T_b`` (``b`` expressed in the frame of ``a``). ``log``/``exp`` map between an
increment and the constant body twist ``(vx, vy, w)`` that produces it in unit time.
"""

from __future__ import annotations

import math

import numpy as np


def wrap_angle(a):
    """Wrap an angle (or array of angles) to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi


def yaw_of_quaternion(q_wxyz) -> np.ndarray:
    """Yaw (rotation about the world z axis, ZYX convention) of quaternions ``(w, x, y, z)`` (N x 4), in
    [-pi, pi] (scipy's ``Rotation``; the quaternions are normalised first)."""
    from scipy.spatial.transform import Rotation  # on first use: scipy.spatial is slow to load

    q = np.asarray(q_wxyz, dtype=np.float64).reshape(-1, 4)
    return Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_euler("ZYX")[:, 0]


def quaternion_of_yaw(yaw) -> np.ndarray:
    """Quaternions ``(w, x, y, z)`` (N x 4) of rotations by ``yaw`` [rad] about the z axis."""
    from scipy.spatial.transform import Rotation

    q_xyzw = Rotation.from_euler("z", np.asarray(yaw, dtype=np.float64).reshape(-1, 1)).as_quat()
    return q_xyzw[:, [3, 0, 1, 2]]


def to_matrix(p) -> np.ndarray:
    """3x3 homogeneous matrix of ``(x, y, yaw)``."""
    x, y, th = (float(v) for v in p)
    c, s = math.cos(th), math.sin(th)
    return np.array([[c, -s, x], [s, c, y], [0.0, 0.0, 1.0]])


def from_matrix(m: np.ndarray) -> np.ndarray:
    """``(x, y, yaw)`` of a 3x3 (or 2x3) rigid matrix."""
    return np.array([m[0, 2], m[1, 2], math.atan2(m[1, 0], m[0, 0])])


def compose(a, b) -> np.ndarray:
    """``a ⊕ b``: the pose ``b`` (given in frame ``a``) expressed in the frame ``a`` is given in."""
    ax, ay, at = a
    bx, by, bt = b
    c, s = math.cos(at), math.sin(at)
    return np.array([ax + c * bx - s * by, ay + s * bx + c * by, float(wrap_angle(at + bt))])


def inverse(a) -> np.ndarray:
    """``a⁻¹``."""
    x, y, th = a
    c, s = math.cos(th), math.sin(th)
    return np.array([-c * x - s * y, s * x - c * y, float(wrap_angle(-th))])


def between(a, b) -> np.ndarray:
    """``a⁻¹ ⊕ b``: the pose of ``b`` in the frame of ``a``."""
    return compose(inverse(a), b)


def sinc_terms(th):
    """``sin(th)/th`` and ``(1 - cos th)/th`` of an angle or array of angles.

    Written as ``sin(th)/th`` and ``(th/2) (sin(th/2)/(th/2))²`` (numpy's ``sinc`` for arrays), so both
    are exact at 0 and free of cancellation near it: no small-angle cut-off or series is needed. A
    scalar takes a ``math`` path (numpy's ``sinc`` costs tens of microseconds per call).
    """
    if isinstance(th, (int, float)) or np.ndim(th) == 0:
        t = float(th)
        if t == 0.0:
            return 1.0, 0.0
        half = 0.5 * t
        s = math.sin(half) / half if half != 0.0 else 1.0  # half underflows for the smallest subnormal t
        return math.sin(t) / t, half * s * s
    th = np.asarray(th, dtype=np.float64)
    return np.sinc(th / np.pi), 0.5 * th * np.sinc(th / (2.0 * np.pi)) ** 2


def sinc_derivatives(th):
    """Derivatives of ``sin(th)/th`` and ``(1 - cos th)/th`` with respect to ``th`` (scalar or array).

    ``(th cos th - sin th)/th²`` and ``(th sin th - (1 - cos th))/th²``, by their series
    ``-th/3`` and ``1/2 - th²/8`` below ``|th| < 1e-4`` (where the closed forms cancel).
    """
    if isinstance(th, (int, float)) or np.ndim(th) == 0:
        t = float(th)
        if abs(t) < 1e-4:
            return -t / 3.0, 0.5 - t * t / 8.0
        s, c = math.sin(t), math.cos(t)
        return (t * c - s) / (t * t), (t * s - (1.0 - c)) / (t * t)
    th = np.asarray(th, dtype=np.float64)
    small = np.abs(th) < 1e-4
    safe = np.where(small, 1.0, th)
    da = np.where(small, -th / 3.0, (safe * np.cos(safe) - np.sin(safe)) / safe**2)
    db = np.where(small, 0.5 - th**2 / 8.0, (safe * np.sin(safe) - (1.0 - np.cos(safe))) / safe**2)
    return da, db


def _v_coefficients(th: float) -> tuple[float, float]:
    return sinc_terms(float(th))


def exp(twist) -> np.ndarray:
    """Increment produced by the constant body twist ``(vx, vy, w)`` over unit time."""
    vx, vy, w = (float(v) for v in twist)
    a, b = _v_coefficients(w)
    return np.array([a * vx - b * vy, b * vx + a * vy, float(wrap_angle(w))])


def log(p) -> np.ndarray:
    """Constant body twist ``(vx, vy, w)`` that produces increment ``p`` in unit time."""
    x, y, th = (float(v) for v in p)
    a, b = _v_coefficients(th)
    det = a * a + b * b
    return np.array([(a * x + b * y) / det, (-b * x + a * y) / det, th])


def exp_many(twist) -> np.ndarray:
    """:func:`exp` of twists (N, 3) at once (the heading not wrapped)."""
    xi = np.asarray(twist, dtype=np.float64).reshape(-1, 3)
    a, b = sinc_terms(xi[:, 2])
    return np.stack([a * xi[:, 0] - b * xi[:, 1], b * xi[:, 0] + a * xi[:, 1], xi[:, 2]], axis=1)


def log_many(p) -> np.ndarray:
    """:func:`log` of increments ``p`` (N, 3) at once."""
    p = np.asarray(p, dtype=np.float64).reshape(-1, 3)
    a, b = sinc_terms(p[:, 2])
    det = a * a + b * b
    return np.stack([(a * p[:, 0] + b * p[:, 1]) / det, (-b * p[:, 0] + a * p[:, 1]) / det, p[:, 2]], axis=1)


def exp_jacobian(twist) -> np.ndarray:
    """``∂ exp(ξ) / ∂ξ`` (N, 3, 3) of the increments ``exp(ξ) = (a v_x - b v_y, b v_x + a v_y, ω)`` of twists
    ``ξ = (v_x, v_y, ω)`` (N, 3) over unit time, with ``a = sin ω / ω`` and ``b = (1 - cos ω) / ω``::

        [[a, -b, a' v_x - b' v_y],
         [b,  a, b' v_x + a' v_y],
         [0,  0, 1]]
    """
    xi = np.asarray(twist, dtype=np.float64).reshape(-1, 3)
    a, b = sinc_terms(xi[:, 2])
    da, db = sinc_derivatives(xi[:, 2])
    J = np.zeros((len(xi), 3, 3))
    J[:, 0, 0], J[:, 0, 1], J[:, 0, 2] = a, -b, da * xi[:, 0] - db * xi[:, 1]
    J[:, 1, 0], J[:, 1, 1], J[:, 1, 2] = b, a, db * xi[:, 0] + da * xi[:, 1]
    J[:, 2, 2] = 1.0
    return J


def log_jacobian(p) -> np.ndarray:
    """``∂ log(p) / ∂p`` (N, 3, 3) of increments ``p`` (N, 3): the inverse of :func:`exp_jacobian` at ``log(p)``."""
    return log_with_jacobian(p)[1]


def log_with_jacobian(p) -> tuple[np.ndarray, np.ndarray]:
    """``log(p)`` (N, 3) of increments ``p`` (N, 3) (:func:`log_many`) and its Jacobian (:func:`log_jacobian`)."""
    xi = log_many(p)
    return xi, np.linalg.inv(exp_jacobian(xi))


def integrate(increments) -> np.ndarray:
    """Chain increments from the origin: returns ``(N+1) x 3`` poses, the first at the origin."""
    inc = np.asarray(increments, dtype=np.float64).reshape(-1, 3)
    out = np.zeros((len(inc) + 1, 3))
    for i, d in enumerate(inc):
        out[i + 1] = compose(out[i], d)
    return out


def fit_rigid_2d(source, target, weights=None) -> tuple[float, np.ndarray]:
    """Weighted least-squares rotation and translation with ``target ≈ R(yaw) source + t``.

    The closed form of Umeyama (1991) without scale: with centroids ``s̄, t̄`` and the cross-covariance
    ``C = Σ w_i (t_i - t̄)(s_i - s̄)ᵀ``, ``yaw = atan2(C₁₀ - C₀₁, C₀₀ + C₁₁)`` and ``t = t̄ - R s̄``.

    Parameters
    ----------
    source, target : array_like, shape (N, 2)
        Corresponding points.
    weights : array_like, shape (N,), optional

    Returns
    -------
    yaw : float
    translation : ndarray, shape (2,)
    """
    src = np.asarray(source, dtype=np.float64).reshape(-1, 2)
    dst = np.asarray(target, dtype=np.float64).reshape(-1, 2)
    w = np.ones(len(src)) if weights is None else np.asarray(weights, dtype=np.float64)
    ms, md = np.average(src, axis=0, weights=w), np.average(dst, axis=0, weights=w)
    C = ((dst - md) * w[:, None]).T @ (src - ms)
    yaw = math.atan2(C[1, 0] - C[0, 1], C[0, 0] + C[1, 1])
    c, s = math.cos(yaw), math.sin(yaw)
    return yaw, md - np.array([[c, -s], [s, c]]) @ ms
