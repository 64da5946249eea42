"""Streams that contradict each other, made by editing a generated recording's files, caught by ``fusion-vo run``
with one sentence naming the file and the key, and corrected so that the fused track is the unbroken one's."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from track_errors import ate, read_tum
from fusion_vo.simulation.faults import flip_left_encoder, shift_clock, state_imu_mounting, turn_imu, twist_from_truth

from fusion_vo.cli.main import main

#: an IMU on its side: the body's up is its +y axis, the body's forward its -z (robot_localization's Husky)
ON_ITS_SIDE = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def run(rec, out, sensors, *extra) -> dict:
    assert main(["-q", "run", str(rec), "--out", str(out), "--sensors", sensors, "--backend", "ekf",
                 "--no-evaluate", *extra]) == 0
    return json.loads((out / "summary.json").read_text())


def notes_about(summary: dict, file: str) -> list[str]:
    return [n for n in summary["notes"] if n.startswith(file)]


def decisions(summary: dict) -> dict:
    return {f["check"]: f["decision"] for f in summary["fusion"]["consistency"]}


@pytest.fixture(scope="module")
def unbroken(drive, tmp_path_factory):
    """The drive's wheels + IMU run, as recorded."""
    out = tmp_path_factory.mktemp("unbroken") / "run"
    return run(drive, out, "wheel,imu"), read_tum(out / "ekf.tum")


def test_unbroken_drive_keeps_every_stream(unbroken):
    summary, _ = unbroken
    assert set(decisions(summary).values()) == {"kept"}, summary["fusion"]["consistency"]
    assert not [n for n in summary["notes"] if "contradicts" in n or "this run" in n]


def test_encoder_counting_backwards_is_negated(broken, tmp_path, unbroken):
    flip_left_encoder(broken)
    summary = run(broken, tmp_path / "out", "wheel,imu")
    (sentence,) = notes_about(summary, "wheel0/data.csv")
    assert "the left encoder counts backwards" in sentence and "negates the left column:" in sentence
    np.testing.assert_allclose(read_tum(tmp_path / "out" / "ekf.tum"), unbroken[1], atol=1e-9)


def test_wheels_on_a_late_clock_are_moved_back(broken, tmp_path, unbroken, drive):
    shift_clock(broken, "wheel0", 0.3)
    summary = run(broken, tmp_path / "out", "wheel,imu")
    (sentence,) = notes_about(summary, "wheel0/data.csv")
    assert "timestamps are 0.30" in sentence and "behind the gyro's" in sentence, sentence
    (found,) = [f for f in summary["fusion"]["consistency"] if f["check"] == "clock"]
    assert abs(found["estimate"]["shift_s"] - 0.3) < 0.005
    fixed = ate(read_tum(tmp_path / "out" / "ekf.tum"), drive)
    assert fixed < 1.2 * ate(unbroken[1], drive) + 1e-3, fixed


def test_late_wheels_cost_the_track_without_the_check(broken, tmp_path, unbroken, drive):
    """The same shift with the checks off: the fused track is markedly worse (so the test above can fail)."""
    shift_clock(broken, "wheel0", 0.3)
    config = tmp_path / "off.yaml"
    config.write_text(yaml.safe_dump({"fusion": {"consistency": {"check": False}}}))
    run(broken, tmp_path / "out", "wheel,imu", "--config", str(config))
    assert ate(read_tum(tmp_path / "out" / "ekf.tum"), drive) > 2.0 * ate(unbroken[1], drive)


@pytest.mark.parametrize("frame, words", [("world", "in the odometry frame, not the robot's"),
                                          ("turned", "x axis points 90° left of the robot's forward axis")])
def test_twist_in_another_frame_is_turned_into_the_robots(drive, tmp_path, frame, words):
    import shutil

    tracks = {}
    for name in ("body", frame):
        rec = shutil.copytree(drive, tmp_path / name)
        twist_from_truth(rec, name)
        summary = run(rec, tmp_path / f"out_{name}", "odom,imu")
        tracks[name] = read_tum(tmp_path / f"out_{name}" / "ekf.tum")
        sentences = notes_about(summary, "odom0/data.csv")
        if name == "body":
            assert not sentences and decisions(summary)["twist frame"] == "kept"
        else:
            assert len(sentences) == 1 and words in sentences[0] and "vx, vy" in sentences[0], sentences
    assert np.abs(tracks[frame][:, 1:] - tracks["body"][:, 1:]).max() < 0.01


def test_twist_turning_the_wrong_way_is_negated(drive, tmp_path):
    import shutil

    from fusion_vo.simulation.faults import columns, write_csv

    tracks = {}
    for name in ("right", "negated"):
        rec = shutil.copytree(drive, tmp_path / name)
        twist_from_truth(rec, "body")
        if name == "negated":
            header, t, values = columns(rec / "odom0" / "data.csv")
            values[:, 2] = -values[:, 2]
            write_csv(rec / "odom0" / "data.csv", header, t, values)
        summary = run(rec, tmp_path / f"out_{name}", "odom,imu")
        tracks[name] = read_tum(tmp_path / f"out_{name}" / "ekf.tum")
    (sentence,) = notes_about(summary, "odom0/data.csv")
    assert "the twist's wz turns the other way from the gyro" in sentence and "negates wz" in sentence
    np.testing.assert_allclose(tracks["negated"], tracks["right"], atol=1e-6)


def test_imu_on_its_side_is_read_with_the_mounting_the_data_give(broken, tmp_path, unbroken):
    turn_imu(broken, ON_ITS_SIDE)
    summary = run(broken, tmp_path / "out", "wheel,imu")
    (sentence,) = notes_about(summary, "imu0/sensor.yaml")
    assert "T_BS contradicts the data" in sentence and "IMU's +y axis" in sentence
    assert "T_BS data: [0.0, 0.0, -1.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]" in sentence
    assert '--static-tf "0.0 0.0 0.0 -1.5708 0.0 1.5708 base_link imu_link"' in sentence
    # the estimated mounting is the true one: the same track as the unbroken IMU's, to the samples' rounding
    np.testing.assert_allclose(read_tum(tmp_path / "out" / "ekf.tum"), unbroken[1], atol=1e-5)


def test_imu_stated_on_its_side_is_kept(broken, tmp_path, unbroken):
    turn_imu(broken, ON_ITS_SIDE)
    state_imu_mounting(broken, ON_ITS_SIDE)
    summary = run(broken, tmp_path / "out", "wheel,imu")
    assert decisions(summary)["mounting"] == "kept" and not notes_about(summary, "imu0/sensor.yaml")


def test_imu_whose_gyro_and_gravity_disagree_is_left_out(broken, tmp_path):
    turn_imu(broken, ON_ITS_SIDE, accel_rotation=np.eye(3))
    summary = run(broken, tmp_path / "out", "wheel,imu")
    (sentence,) = notes_about(summary, "imu0/sensor.yaml")
    assert "the IMU is left out of this run" in sentence and "disagree by 90°" in sentence
    assert "gyro" not in summary["fusion"]["counts"]["ekf"]


def test_drive_too_straight_to_decide_leaves_the_streams_as_stated(tmp_path):
    """A straight drive whose accelerometer has no gravity in it: nothing turns, so neither the clocks nor the
    gyro's axis can be estimated; the run says so and its track is the one without the checks. (The encoders'
    signs can: a wheel counting backwards would make a straight drive turn.)"""
    from fusion_vo.simulation.faults import columns, write_csv

    from fusion_vo.simulation import simulate

    rec = simulate(tmp_path / "rec", profile="straight", seed=4, length=0.5, width=64, height=36, fu=42.0, fv=42.0,
                   cu=31.5, cv=17.5, camera_rate=5.0, supersample=1)
    header, t, values = columns(rec / "imu0" / "data.csv")
    values[:, 3:6] = 0.0  # an accelerometer with gravity removed
    write_csv(rec / "imu0" / "data.csv", header, t, values)
    summary = run(rec, tmp_path / "on", "wheel,imu")
    config = tmp_path / "off.yaml"
    config.write_text(yaml.safe_dump({"fusion": {"consistency": {"check": False}}}))
    run(rec, tmp_path / "off", "wheel,imu", "--config", str(config))
    (sentence,) = notes_about(summary, "imu0/sensor.yaml")
    assert "T_BS not checked against the data" in sentence and "is not gravity" in sentence
    assert sentence.endswith("the IMU is used as stated")
    (sentence,) = [n for n in summary["notes"] if n.startswith("the clocks of")]
    assert "not checked" in sentence and "used as stamped" in sentence
    assert decisions(summary) == {"mounting": "undecided", "wheel sign": "kept", "clock": "undecided"}
    np.testing.assert_array_equal(read_tum(tmp_path / "on" / "ekf.tum"), read_tum(tmp_path / "off" / "ekf.tum"))
