"""Frame-to-frame similarities of a recording, measured by a visual frontend in rectified pixels.

The frontend is given the recording's :class:`GroundRectifier` as its point map, so each
:class:`FrameMotion` matrix ``S`` maps the rectified pixels of one frame to those of the next::

    u'_{k+1} = S u'_k = s R(θ) u'_k + t
"""

from __future__ import annotations

import logging

from frontends import make_frontend
from frontends.base import FrameMotion, MotionStatus
from fusion_vo.errors import InputError
from fusion_vo.geometry.ground import GroundGeometry
from fusion_vo.recording import Recording

logger = logging.getLogger(__name__)


def frame_motions(recording: Recording, frontend: str = "klt", options: dict | None = None
                  ) -> tuple[list[FrameMotion], GroundGeometry]:
    """Run ``frontend`` over every frame; returns the motions after the first frame and the geometry.

    Frames that cannot be read are skipped (the next motion then spans the gap); failed motions are
    kept with their status so that callers can count them.
    """
    try:
        geometry = GroundGeometry(recording.camera)
    except ValueError as exc:
        raise InputError(str(exc), recording.path / "cam0" / "sensor.yaml") from None
    fe = make_frontend(frontend, options or {}, point_map=geometry.rectifier)
    motions: list[FrameMotion] = []
    for frame in recording.frames():
        if frame.image is None:
            logger.warning("skipping frame %d: %s", frame.index, frame.error)
            continue
        m = fe.process(frame.image, frame.t)
        if m.status is not MotionStatus.FIRST:
            motions.append(m)
    if not motions:
        raise InputError("fewer than two usable frames", recording.path / "cam0")
    return motions, geometry
