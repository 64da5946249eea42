"""``fusion-vo run`` on copies of a generated drive broken as a user's log can be: the runs
``test_cli_faults.py`` checks.

``python tests/consistency/cli_faults_job.py FOLDER`` writes the unbroken drive (``FOLDER/drive``), the straight
drive (``FOLDER/straight``) and, for each case of :data:`CASES`, the run ``FOLDER/CASE`` of the copy broken as the
case says (``summary.json``, ``ekf.tum``, ...; the broken copy itself is removed). Each run is
``fusion-vo -q run COPY --out FOLDER/CASE --sensors SENSORS --backend ekf --no-evaluate`` (with the consistency
checks off where the case says so), called in this interpreter as a user's script would. The session's second
process runs it ahead (tests/background.py); a test run without that process calls :func:`run_all` itself.
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import numpy as np
import yaml

from fusion_vo.cli.main import main
from fusion_vo.simulation import simulate
from fusion_vo.simulation.faults import (columns, flip_left_encoder, shift_clock, state_imu_mounting, turn_imu,
                                         twist_from_truth, write_csv)

from drives import TOKEN_CAMERA, make_drive

#: an IMU on its side: the body's up is its +y axis, the body's forward its -z (robot_localization's Husky)
ON_ITS_SIDE = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def _negate_twist_wz(rec: Path) -> None:
    twist_from_truth(rec, "body")
    header, t, values = columns(rec / "odom0" / "data.csv")
    values[:, 2] = -values[:, 2]
    write_csv(rec / "odom0" / "data.csv", header, t, values)


def _gravity_removed(rec: Path) -> None:
    header, t, values = columns(rec / "imu0" / "data.csv")
    values[:, 3:6] = 0.0  # an accelerometer with gravity removed
    write_csv(rec / "imu0" / "data.csv", header, t, values)


def _turned_on_its_side(rec: Path) -> None:
    turn_imu(rec, ON_ITS_SIDE)


def _stated_on_its_side(rec: Path) -> None:
    turn_imu(rec, ON_ITS_SIDE)
    state_imu_mounting(rec, ON_ITS_SIDE)


#: case -> (the recording it breaks: ``drive`` or ``straight``, how it breaks a copy, the sensors fused, whether the
#: consistency checks are on)
CASES = {
    "unbroken": ("drive", lambda rec: None, "wheel,imu", True),
    "left_encoder_backwards": ("drive", flip_left_encoder, "wheel,imu", True),
    "late_wheels": ("drive", lambda rec: shift_clock(rec, "wheel0", 0.3), "wheel,imu", True),
    "late_wheels_unchecked": ("drive", lambda rec: shift_clock(rec, "wheel0", 0.3), "wheel,imu", False),
    "twist_body": ("drive", lambda rec: twist_from_truth(rec, "body"), "odom,imu", True),
    "twist_world": ("drive", lambda rec: twist_from_truth(rec, "world"), "odom,imu", True),
    "twist_turned": ("drive", lambda rec: twist_from_truth(rec, "turned"), "odom,imu", True),
    "twist_negated": ("drive", _negate_twist_wz, "odom,imu", True),
    "imu_on_its_side": ("drive", _turned_on_its_side, "wheel,imu", True),
    "imu_stated_on_its_side": ("drive", _stated_on_its_side, "wheel,imu", True),
    "imu_gyro_and_gravity_disagree": ("drive", lambda rec: turn_imu(rec, ON_ITS_SIDE, accel_rotation=np.eye(3)),
                                      "wheel,imu", True),
    "straight_without_gravity": ("straight", _gravity_removed, "wheel,imu", True),
    "straight_without_gravity_unchecked": ("straight", _gravity_removed, "wheel,imu", False),
}


def make_straight(path: Path) -> Path:
    """A 0.5 m straight drive through the token camera (nothing turns: neither clocks nor axes can be estimated)."""
    return simulate(path, profile="straight", seed=4, length=0.5, **TOKEN_CAMERA)


def run_all(folder: Path) -> Path:
    """The recordings and every case's run into ``folder`` (module docstring); returns ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    recordings = {"drive": make_drive(folder / "drive"), "straight": make_straight(folder / "straight")}
    checks_off = folder / "checks_off.yaml"
    checks_off.write_text(yaml.safe_dump({"fusion": {"consistency": {"check": False}}}))
    for case, (source, breaks, sensors, checked) in CASES.items():
        copy = Path(shutil.copytree(recordings[source], folder / f"{case}_recording"))
        breaks(copy)
        extra = [] if checked else ["--config", str(checks_off)]
        code = main(["-q", "run", str(copy), "--out", str(folder / case), "--sensors", sensors, "--backend", "ekf",
                     "--no-evaluate", *extra])
        if code != 0:
            raise RuntimeError(f"{case}: fusion-vo run exited with status {code}")
        shutil.rmtree(copy)
    return folder


if __name__ == "__main__":
    run_all(Path(sys.argv[1]))
