"""Several instances of a kind: ``odom1`` (a second odometry twist, with a mask of the components it contributes) and
``imu1`` (a second gyro with its own mounting and bias), made by the library when a name asks for them and fused by
every backend (EKF, RTS, GTSAM batch, iSAM2, streaming) with no code of their own in the backends."""

from __future__ import annotations

import json
import pickle

import numpy as np
import pytest

from fusion_vo.backends import SensorStreams
from fusion_vo.errors import InputError
from fusion_vo.sensors import registry
from fusion_vo.sensors.imu import read_imu
from fusion_vo.sensors.wheel import read_twist

from instances_job import CHAIN_MASKS, CORRUPT, IMU1_BIAS, make, twist

TRACKS = ("ekf", "ekf_smoothed", "gtsam", "gtsam_online")
#: the fusion runs the tests read (tests/sensors/instances_job.py), made ahead in the background (tests/background.py)
BACKGROUND_COMMANDS = {"python:instance_runs": ["{repo}/tests/sensors/instances_job.py", "{out}"]}
BACKGROUND_JOBS = {name: ["python:instance_runs"] for name in (
    "test_odom1_alone_is_as_accurate_as_the_same_twist_in_odom0", "test_odom1_streams_like_odom0",
    "test_a_masked_component_has_no_influence", "test_a_masked_odometry_chains_between_keyframes",
    "test_odom1_noise_is_its_own_section", "test_an_upside_down_imu1_helps_like_imu0_and_its_bias_is_estimated",
    "test_imu1_streams")}


@pytest.fixture(scope="module", autouse=True)
def _instances_made_here_are_removed():
    """The instances these tests make are registered in this process only while they run."""
    yield
    for name in list(registry.names()):
        if registry.is_instance(name):
            registry.unregister(name)


@pytest.fixture(scope="module")
def runs(ahead, tmp_path_factory) -> dict:
    """Every fusion run of these tests by name (:func:`instances_job.runs`)."""
    out = ahead("python:instance_runs", lambda: make(tmp_path_factory.mktemp("instances") / "runs"))
    return pickle.loads((out / "runs.pkl").read_bytes())


def _position_rms(track, truth) -> float:
    xy = np.column_stack([np.interp(track.t, truth.t, truth.xyyaw[:, i]) for i in range(2)])
    return float(np.sqrt(np.mean(np.sum((track.xyyaw[:, :2] - xy) ** 2, axis=1))))


def _heading_rms(track, truth) -> float:
    yaw = np.interp(track.t, truth.t, np.unwrap(truth.xyyaw[:, 2]))
    return float(np.sqrt(np.mean(np.angle(np.exp(1j * (track.xyyaw[:, 2] - yaw))) ** 2)))


# --------------------------------------------------------------------------- odom1
def test_odom1_alone_is_as_accurate_as_the_same_twist_in_odom0(runs):
    """The wheels removed, the twist as ``odom1`` gives what it gives as ``odom0`` in every backend, alone and with
    the gyro (odom0's delay estimate is off: odom1 has none)."""
    truth = runs["truth/drive"]
    for others in ("alone", "imu"):
        zero, one = runs[f"odom0/{others}"], runs[f"odom1/{others}"]
        for name in TRACKS:
            a, b = _position_rms(zero.trajectories[name], truth), _position_rms(one.trajectories[name], truth)
            # measured: alone 0.0126-0.0131 m both; with the gyro 0.332-0.388 m (odom0), 0.334-0.385 m (odom1)
            assert abs(b - a) <= 0.03 * a + 1e-3, (others, name, a, b)
            assert one.counts[name]["odom1"].used >= 0.95 * (len(one.trajectories[name].t) - 1), one.counts[name]
        assert "odom1" not in zero.counts["ekf"]
        # a second odometer with its own noise beside odom0: measured 0.0081-0.0086 m alone, 0.206-0.267 with the
        # gyro
        both = runs[f"both/{others}"]
        for name in TRACKS:
            a, b = _position_rms(zero.trajectories[name], truth), _position_rms(both.trajectories[name], truth)
            assert b < 0.8 * a, (others, name, a, b)


@pytest.mark.parametrize("backend, track", [("ekf", "ekf"), ("gtsam", "gtsam_online")])
def test_odom1_streams_like_odom0(runs, backend, track):
    """``StreamingFusion.add("odom1", sample)``: the twist streamed as odom1 gives odom0's accuracy."""
    truth = runs["truth/drive"]
    zero, one = runs[f"stream/{backend}/odom0"], runs[f"stream/{backend}/odom1"]
    a, b = _position_rms(zero.trajectories[track], truth), _position_rms(one.trajectories[track], truth)
    assert a < 0.05 and abs(b - a) <= 0.03 * a + 1e-3, (backend, a, b)
    assert one.counts[track]["odom1"].used >= 700, one.counts[track]


@pytest.mark.parametrize("component", list(CORRUPT))
def test_a_masked_component_has_no_influence(runs, component):
    """A corrupted component left out of ``fusion.odom1.mask`` changes no estimate of any backend (equal to the
    last bit); kept in the mask, the same corruption moves the track."""
    truth = runs["truth/drive"]
    clean, corrupted, kept = (runs[f"mask/{component}/{name}"] for name in ("clean", "corrupted", "kept"))
    for name in TRACKS:
        assert np.array_equal(clean.trajectories[name].xyyaw, corrupted.trajectories[name].xyyaw), name
        moved = np.abs(kept.trajectories[name].xyyaw - clean.trajectories[name].xyyaw).max()
        assert moved > 0.05, (component, name, moved)
        if component != "vy":  # a sideways speed of 0.2 m/s moves the track without making this drive's worse
            a, b = _position_rms(clean.trajectories[name], truth), _position_rms(kept.trajectories[name], truth)
            # measured (EKF, RTS, GTSAM batch, iSAM2): masked 0.40, 0.26, 0.25, 0.40 m (yaw_rate left out) and
            # 0.36, 0.23, 0.23, 0.36 (vx left out); kept in, the corruption gives 0.76, 0.88, 0.88, 0.51 and
            # 0.51, 0.44, 0.43, 0.68
            assert b > 1.2 * a, (component, name, a, b)


def test_a_masked_odometry_chains_between_keyframes(runs):
    """With ``graph.keyframe_every: 3`` the masked readings between two keyframes are composed (the components left
    out held at zero) into one factor: the graph's track stays as accurate as with every node."""
    for mask in CHAIN_MASKS:
        rms = [_position_rms(runs[f"chain/{'+'.join(mask)}/{every}"].trajectories["gtsam"], runs["truth/drive"])
               for every in (1, 3)]
        # measured: 0.762 and 0.763 m ([vx, yaw_rate]: nothing measures the sideways motion), 0.757 and 0.750 m
        # ([vx, vy])
        assert rms[1] < 1.2 * rms[0], (mask, rms)


def test_odom1_noise_is_its_own_section(runs):
    """``fusion.odom1`` configures odom1 alone: its heading trusted (no skid terms), the track with the gyro moves,
    and odom0's does not."""
    truth = runs["truth/drive"]
    moved, kept = runs["section/odom1/own"], runs["section/odom1/plain"]
    zero_own, zero_plain = runs["section/odom0/own"], runs["section/odom0/plain"]
    for name in TRACKS:
        a, b = _position_rms(kept.trajectories[name], truth), _position_rms(moved.trajectories[name], truth)
        assert b < 0.5 * a, (name, a, b)  # the twist's heading outweighs the gyro's bias
        assert np.array_equal(zero_own.trajectories[name].xyyaw, zero_plain.trajectories[name].xyyaw), name


def test_instance_names_and_masks_are_checked():
    """odom1 ... odom9 and imu1 ... imu9 exist; instance 0 is odom/imu, and odom10, odom01, imu0 are no sensor; a
    bad mask names its key."""
    from fusion_vo.backends.config import FusionConfig

    assert registry.known("odom9") and registry.known("imu3")
    for name in ("odom10", "odom01", "odom0", "imu0", "odomx", "gyro1"):
        assert not registry.known(name), name
        with pytest.raises(InputError, match=f"unknown sensor '{name}'"):
            SensorStreams().select(["wheel", name])
    with pytest.raises(ValueError, match=r"odom2.mask: unknown component 'yaw' \(use vx, vy, yaw_rate\)"):
        FusionConfig.from_dict({"odom2": {"mask": ["vx", "yaw"]}})
    with pytest.raises(ValueError, match="odom2: mask must name at least one"):
        FusionConfig.from_dict({"odom2": {"mask": []}})
    assert FusionConfig.from_dict({"odom2": {"mask": ["yaw_rate", "vx"]}}).section("odom2").rows() == (0, 2)
    assert "odom2" not in FusionConfig().to_dict()  # an instance's section is listed once configured


# --------------------------------------------------------------------------- imu1
def test_an_upside_down_imu1_helps_like_imu0_and_its_bias_is_estimated(runs):
    """The wheels with imu1 (turned into the body frame by its T_BS) hold the heading as the wheels with imu0 do,
    in every backend, and imu1_gyro_bias is estimated; with its mounting ignored the gyro turns the wrong way."""
    truth = runs["truth/skewed"]
    wheels, zero, one, wrong = (runs[f"imu1/{name}"] for name in ("wheels", "imu0", "imu1", "flat"))
    for name in TRACKS:
        p_w, p0, p1 = (_position_rms(r.trajectories[name], truth) for r in (wheels, zero, one))
        h1, h_x = _heading_rms(one.trajectories[name], truth), _heading_rms(wrong.trajectories[name], truth)
        # measured (m): wheels 0.71-0.72; with imu0 0.25, 0.059, 0.056, 0.27; with imu1 0.27, 0.048, 0.025, 0.28
        # (EKF, RTS, GTSAM batch, iSAM2)
        assert p1 < 0.5 * p_w and p1 < 1.25 * p0 + 0.02, (name, p_w, p0, p1)
        assert h_x > 3.0 * h1, (name, h1, h_x)  # measured: 1.3-1.8 rad against 0.013-0.146
        bias = one.calibration[name]["imu1_gyro_bias"]
        assert abs(bias - IMU1_BIAS) < 0.003, (name, bias)  # measured: 0.0213-0.0218 (imu0's: 0.0113-0.0118 of 0.01)
        # its σ from the data (measured 0.0041 for the EKF), a quarter of the prior's 0.02 at most
        assert one.calibration[name]["imu1_gyro_bias_sigma"] < 0.25 * 0.02, (name, one.calibration[name])
        assert abs(one.calibration[name]["wheel_base_factor"] - 1.05) < 0.01, (name, one.calibration[name])


@pytest.mark.parametrize("backend, track", [("ekf", "ekf"), ("gtsam", "gtsam_online")])
def test_imu1_streams(runs, backend, track):
    """Replayed, imu1's samples arrive turned into the body frame; streamed it bounds the wheels' drift as in
    batch."""
    truth = runs["truth/skewed"]
    wheels, one = runs[f"stream/{backend}/wheels"], runs[f"stream/{backend}/imu1"]
    p_w, p1 = _position_rms(wheels.trajectories[track], truth), _position_rms(one.trajectories[track], truth)
    assert p1 < 0.5 * p_w, (backend, p_w, p1)
    assert one.counts[track]["imu1"].used >= 550, one.counts[track]


# --------------------------------------------------------------------------- command line and import-bag
@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """A generated recording (wheels, IMU, small camera) with an ``odom1/`` folder: another base's twist."""
    from fusion_vo.recording import Recording
    from fusion_vo.simulation import simulate

    tiny = {"width": 80, "height": 48, "fu": 60.0, "fv": 60.0, "cu": 39.5, "cv": 23.5, "supersample": 1,
            "camera_rate": 2.0}
    rec = simulate(tmp_path_factory.mktemp("instances") / "rec", profile="random", seed=3, duration=20.0, **tiny)
    twist_data = twist(Recording(rec).groundtruth(), seed=2)
    (rec / "odom1").mkdir()
    (rec / "odom1" / "data.csv").write_text("#timestamp [ns],v_x [m s^-1],v_y [m s^-1],w_z [rad s^-1]\n" + "".join(
        f"{int(round(t * 1e9))},{vx:.6f},{vy:.6f},{wz:.6f}\n" for t, vx, vy, wz in zip(*twist_data.__dict__.values())))
    return rec


def test_the_command_line_fuses_odom1(recording, tmp_path, capsys):
    """``fusion-vo run REC --sensors wheel,odom1`` reads odom1/ and every backend uses it; asked for on a recording
    without the folder, or with a bad mask, it stops in one line, exit status 2."""
    from fusion_vo.cli.main import main

    out = tmp_path / "out"
    assert main(["run", str(recording), "--out", str(out), "--sensors", "wheel,odom1"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    wheels = tmp_path / "wheels"
    assert main(["run", str(recording), "--out", str(wheels), "--sensors", "wheel"]) == 0
    alone = json.loads((wheels / "summary.json").read_text())
    for name in TRACKS:
        assert summary["fusion"]["counts"][name]["odom1"]["used"] >= 350, summary["fusion"]["counts"][name]
    metrics = json.loads((out / "metrics.json").read_text())
    before = json.loads((wheels / "metrics.json").read_text())
    for name in TRACKS:
        assert metrics[name]["ate_m"] < before[name]["ate_m"], (name, metrics[name]["ate_m"], before[name]["ate_m"])
    assert alone["fusion"]["counts"]["ekf"].get("odom1") is None
    capsys.readouterr()

    config = tmp_path / "run.yaml"
    config.write_text("fusion: {odom1: {mask: [vx, yaw]}}\n")
    for args, message in ((["--sensors", "wheel,odom2"], "the recording has no odom2/"),
                          (["--sensors", "wheel,odom10"], "got 'odom10'"),
                          (["--sensors", "wheel,odom1", "-c", str(config)], "fusion.odom1.mask: unknown component 'yaw'")):
        status = main(["run", str(recording), "--out", str(tmp_path / "bad"), *args])
        err = capsys.readouterr().err
        assert status == 2 and err.count("\n") == 1 and message in err, (args, err)
        assert not (tmp_path / "bad").exists()


def test_import_bag_writes_a_second_odometry_and_imu(tmp_path):
    """``--odom-topic`` and ``--imu-topic`` given twice write odom0/ and odom1/, imu0/ and imu1/ (one topic may feed
    both); given once, the recording is the one it always was."""
    from pathlib import Path

    from fusion_vo.recording import Recording
    from fusion_vo.recording.rosbag import import_bag

    bag = Path(__file__).parents[1] / "data" / "robot_localization" / "test2.bag"
    odom, imu = "/jackal_velocity_controller/odom", "/imu/data"
    two = import_bag(bag, tmp_path / "two", imu_topic=[imu, imu], odom_topic=[odom, odom])
    assert [s.stream for s in two.streams] == ["imu0", "imu1", "odom0", "odom1"]
    for kind in ("imu", "odom"):
        assert (tmp_path / "two" / f"{kind}0" / "data.csv").read_bytes() == \
            (tmp_path / "two" / f"{kind}1" / "data.csv").read_bytes()
    rec = Recording(tmp_path / "two")
    assert len(read_twist(rec, "odom1")) == 3060 and len(read_imu(rec, "imu1").t) == 3061
    import_bag(bag, tmp_path / "one", imu_topic=imu, odom_topic=[odom])
    assert sorted(p.name for p in (tmp_path / "one").iterdir() if p.is_dir()) == ["imu0", "odom0"]
    with pytest.raises(InputError, match="--odom-topic given 11 times"):
        import_bag(bag, tmp_path / "many", odom_topic=[odom] * 11)
