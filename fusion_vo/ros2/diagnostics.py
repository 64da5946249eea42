"""What the node tells on ``diagnostics``: per input, what came and what became of it; the node's latency.

One ``diagnostic_msgs/DiagnosticStatus`` per input, named ``fusion_vo: <sensor>`` with ``hardware_id`` its
topic, holding these keys (whole numbers since start-up):

``received``
    messages taken from the topic;
``unusable``
    messages the node cannot use at all (a frame, an encoding, a size or a layout:
    :class:`~fusion_vo.ros2.conversions.Unusable`); ``unusable_reason`` says why, for the first one (and
    the node logs it once per topic, not per message);
``skipped``
    messages stating no measurement (a GPS without a fix, a range out of its limits);
``future``
    messages stamped more than ``horizon`` seconds ahead of the node's clock;
``out_of_order``
    messages stamped before an earlier message of the topic (counted as they arrive; they still go to the
    fusion, which applies them in time order within its history: ``reordered`` or, when a busy node had them
    sorted before the fusion saw them, not even that; ``late`` beyond it);
``<name>.used``, ``<name>.gated``, ``<name>.late``, ``<name>.reordered``, ``<name>.missing``
    the fusion's counts (:class:`~fusion_vo.backends.result.SensorCount`) under the names it keeps them:
    ``gyro`` and ``ahrs`` for the IMU, ``wheel`` for odometry and wheel ticks, else the sensor's. ``used``
    and ``missing`` count node intervals, ``gated`` messages with NaN values (and intervals a gate rejected),
    ``late`` messages older than the history, ``reordered`` messages out of order but applied in time order.

The camera's status adds ``frames`` (processed by the frontend), ``failed`` (not measured),
``dropped`` (pushed out of the full frame queue), ``out_of_order`` (there: frames not newer than the last one
taken, left out), ``queue`` and ``latency_ms_p50`` /
``latency_ms_max`` (arrival of a frame to its increment in the fusion). The status is WARN while an input
has unusable messages or frames are dropped.

``fusion_vo: estimate`` holds ``backend``, ``frame`` (``start`` or ``enu``), ``published``,
``input_age_s`` (the node's clock minus the newest measurement: how stale the inputs are),
``predicted_s`` (how far the last published pose was predicted beyond the processed state),
``predicted_max_s`` (the longest such prediction since start-up: the node's worst lag behind its clock), ``rewinds``,
and ``monitor_drops`` (the consistency monitor's spans, heading sources and speeds, each as ``sensor component from t0 to t1``);
WARN when the inputs are older than ``horizon`` (stalled) or the monitor drops a sensor.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

log = logging.getLogger(__name__)

NAME = "fusion_vo"


@dataclass
class TopicStats:
    """Counts of one input topic kept by the node (the fusion keeps its own)."""

    sensor: str
    topic: str
    received: int = 0
    unusable: int = 0
    unusable_reason: str = ""
    skipped: int = 0
    future: int = 0
    out_of_order: int = 0
    newest: float = float("-inf")  # the newest stamp taken

    def arrived(self, t: float) -> None:
        """Count a message stamped ``t`` that goes to the fusion: out of order when older than the newest."""
        if t < self.newest:
            self.out_of_order += 1
        else:
            self.newest = t

    def reject(self, reason: str) -> None:
        """Count an unusable message; the first one of the topic is logged, later ones only counted."""
        self.unusable += 1
        if self.unusable == 1:
            self.unusable_reason = reason
            log.warning("%s: messages cannot be used: %s (counted in diagnostics, not logged again)",
                        self.topic, reason)


def _kv(key: str, value) -> KeyValue:
    return KeyValue(key=key, value=str(value))


def input_status(stats: TopicStats, counts: dict, camera=None) -> DiagnosticStatus:
    status = DiagnosticStatus(name=f"{NAME}: {stats.sensor}", hardware_id=stats.topic)
    values = [_kv("received", stats.received), _kv("unusable", stats.unusable), _kv("skipped", stats.skipped),
              _kv("future", stats.future)]
    if camera is None:  # (the camera's own count below)
        values.append(_kv("out_of_order", stats.out_of_order))
    if stats.unusable_reason:
        values.append(_kv("unusable_reason", stats.unusable_reason))
    values += [_kv(f"{name}.{k}", v) for name, c in counts.items() for k, v in c.items()]
    warn = stats.unusable > 0
    if camera is not None:
        lat = list(camera.latency_ms)
        values += [_kv("frames", camera.frames), _kv("failed", camera.failed), _kv("dropped", camera.dropped),
                   _kv("out_of_order", camera.out_of_order), _kv("queue", camera.backlog()),
                   _kv("latency_ms_p50", f"{np.median(lat):.2f}" if lat else "nan"),
                   _kv("latency_ms_max", f"{max(lat):.2f}" if lat else "nan")]
        warn = warn or camera.dropped > 0
    status.values = values
    status.level = DiagnosticStatus.WARN if warn else DiagnosticStatus.OK
    used = ", ".join(f"{name} {c.get('used', 0)}" for name, c in counts.items())
    status.message = (f"{stats.unusable} unusable: {stats.unusable_reason}" if stats.unusable else
                      f"{stats.received} received" + (f"; intervals used: {used}" if used else ""))
    return status


def estimate_status(backend: str, frame: str, published: int, input_age: float | None, predicted: float | None,
                    predicted_max: float, rewinds: int, episodes: list[dict], horizon: float) -> DiagnosticStatus:
    status = DiagnosticStatus(name=f"{NAME}: estimate", hardware_id=NAME)
    drops = "; ".join(f"{e['sensor']} {e['component']} from {e['start']:.2f} to {e['end']:.2f}" for e in episodes)
    status.values = [_kv("backend", backend), _kv("frame", frame), _kv("published", published),
                     _kv("input_age_s", "nan" if input_age is None else f"{input_age:.3f}"),
                     _kv("predicted_s", "nan" if predicted is None else f"{predicted:.3f}"),
                     _kv("predicted_max_s", f"{predicted_max:.3f}"), _kv("rewinds", rewinds), _kv("monitor_drops", drops or "none")]
    stalled = input_age is not None and input_age > horizon
    status.level = DiagnosticStatus.WARN if stalled or episodes else DiagnosticStatus.OK
    status.message = ("inputs stalled" if stalled else "no input yet" if input_age is None else
                      f"heading source dropped: {drops}" if episodes else "ok")
    return status


def diagnostic_array(statuses: list[DiagnosticStatus], stamp_setter) -> DiagnosticArray:
    msg = DiagnosticArray()
    stamp_setter(msg.header.stamp)
    msg.status = statuses
    return msg
