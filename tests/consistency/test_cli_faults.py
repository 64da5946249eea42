"""Streams that contradict each other, made by editing a generated recording's files, caught by ``fusion-vo run``
with one sentence naming the file and the key, and corrected so that the fused track is the unbroken one's.

The runs are made by ``cli_faults_job.py`` (one per case of its ``CASES``), ahead in the session's second process
(tests/background.py) or here when the session has none."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from cli_faults_job import run_all
from track_errors import ate, read_tum

#: the runs, made ahead in the background (tests/background.py, tests/conftest.py)
BACKGROUND_COMMANDS = {"python:cli_faults": ["{repo}/tests/consistency/cli_faults_job.py", "{out}"]}
BACKGROUND_JOBS = {"*": ["python:cli_faults"]}


@pytest.fixture(scope="module")
def runs(ahead, tmp_path_factory) -> Path:
    """The folder of every case's run and of the recordings they broke (cli_faults_job.py)."""
    return ahead("python:cli_faults", lambda: run_all(tmp_path_factory.mktemp("cli_faults") / "runs"))


def summary_of(runs: Path, case: str) -> dict:
    return json.loads((runs / case / "summary.json").read_text())


def track_of(runs: Path, case: str) -> np.ndarray:
    return read_tum(runs / case / "ekf.tum")


def notes_about(summary: dict, file: str) -> list[str]:
    return [n for n in summary["notes"] if n.startswith(file)]


def decisions(summary: dict) -> dict:
    return {f["check"]: f["decision"] for f in summary["fusion"]["consistency"]}


def test_unbroken_drive_keeps_every_stream(runs):
    summary = summary_of(runs, "unbroken")
    assert set(decisions(summary).values()) == {"kept"}, summary["fusion"]["consistency"]
    assert not [n for n in summary["notes"] if "contradicts" in n or "this run" in n]


def test_encoder_counting_backwards_is_negated(runs):
    (sentence,) = notes_about(summary_of(runs, "left_encoder_backwards"), "wheel0/data.csv")
    assert "the left encoder counts backwards" in sentence and "negates the left column:" in sentence
    np.testing.assert_allclose(track_of(runs, "left_encoder_backwards"), track_of(runs, "unbroken"), atol=1e-9)


def test_wheels_on_a_late_clock_are_moved_back(runs):
    summary = summary_of(runs, "late_wheels")
    (sentence,) = notes_about(summary, "wheel0/data.csv")
    assert "timestamps are 0.30" in sentence and "behind the gyro's" in sentence, sentence
    (found,) = [f for f in summary["fusion"]["consistency"] if f["check"] == "clock"]
    assert abs(found["estimate"]["shift_s"] - 0.3) < 0.005
    fixed = ate(track_of(runs, "late_wheels"), runs / "drive")
    assert fixed < 1.2 * ate(track_of(runs, "unbroken"), runs / "drive") + 1e-3, fixed


def test_late_wheels_cost_the_track_without_the_check(runs):
    """The same shift with the checks off: the fused track is markedly worse (so the test above can fail)."""
    assert ate(track_of(runs, "late_wheels_unchecked"), runs / "drive") > 2.0 * ate(track_of(runs, "unbroken"),
                                                                                  runs / "drive")


@pytest.mark.parametrize("frame, words", [("world", "in the odometry frame, not the robot's"),
                                          ("turned", "x axis points 90° left of the robot's forward axis")])
def test_twist_in_another_frame_is_turned_into_the_robots(runs, frame, words):
    body = summary_of(runs, "twist_body")
    assert not notes_about(body, "odom0/data.csv") and decisions(body)["twist frame"] == "kept"
    sentences = notes_about(summary_of(runs, f"twist_{frame}"), "odom0/data.csv")
    assert len(sentences) == 1 and words in sentences[0] and "vx, vy" in sentences[0], sentences
    assert np.abs(track_of(runs, f"twist_{frame}")[:, 1:] - track_of(runs, "twist_body")[:, 1:]).max() < 0.01


def test_twist_turning_the_wrong_way_is_negated(runs):
    (sentence,) = notes_about(summary_of(runs, "twist_negated"), "odom0/data.csv")
    assert "the twist's wz turns the other way from the gyro" in sentence and "negates wz" in sentence
    np.testing.assert_allclose(track_of(runs, "twist_negated"), track_of(runs, "twist_body"), atol=1e-6)


def test_imu_on_its_side_is_read_with_the_mounting_the_data_give(runs):
    (sentence,) = notes_about(summary_of(runs, "imu_on_its_side"), "imu0/sensor.yaml")
    assert "T_BS contradicts the data" in sentence and "IMU's +y axis" in sentence
    assert "T_BS data: [0.0, 0.0, -1.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]" in sentence
    assert '--static-tf "0.0 0.0 0.0 -1.5708 0.0 1.5708 base_link imu_link"' in sentence
    # the estimated mounting is the true one: the same track as the unbroken IMU's, to the samples' rounding
    np.testing.assert_allclose(track_of(runs, "imu_on_its_side"), track_of(runs, "unbroken"), atol=1e-5)


def test_imu_stated_on_its_side_is_kept(runs):
    summary = summary_of(runs, "imu_stated_on_its_side")
    assert decisions(summary)["mounting"] == "kept" and not notes_about(summary, "imu0/sensor.yaml")


def test_imu_whose_gyro_and_gravity_disagree_is_left_out(runs):
    summary = summary_of(runs, "imu_gyro_and_gravity_disagree")
    (sentence,) = notes_about(summary, "imu0/sensor.yaml")
    assert "the IMU is left out of this run" in sentence and "disagree by 90°" in sentence
    assert "gyro" not in summary["fusion"]["counts"]["ekf"]


def test_drive_too_straight_to_decide_leaves_the_streams_as_stated(runs):
    """A straight drive whose accelerometer has no gravity in it: nothing turns, so neither the clocks nor the
    gyro's axis can be estimated; the run says so and its track is the one without the checks. (The encoders'
    signs can: a wheel counting backwards would make a straight drive turn.)"""
    summary = summary_of(runs, "straight_without_gravity")
    (sentence,) = notes_about(summary, "imu0/sensor.yaml")
    assert "T_BS not checked against the data" in sentence and "is not gravity" in sentence
    assert sentence.endswith("the IMU is used as stated")
    (sentence,) = [n for n in summary["notes"] if n.startswith("the clocks of")]
    assert "not checked" in sentence and "used as stamped" in sentence
    assert decisions(summary) == {"mounting": "undecided", "wheel sign": "kept", "clock": "undecided"}
    np.testing.assert_array_equal(track_of(runs, "straight_without_gravity"),
                                  track_of(runs, "straight_without_gravity_unchecked"))
