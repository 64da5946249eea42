"""A generated recording with camera images, wheels and IMU played into the node over DDS.

The node runs live visual odometry on the images (its own thread) and fuses it with the wheel ticks and
the IMU; its online track (``trajectory_file``, written on shutdown: each node's pose as filtered when it
was processed) must be within 1.5x of the batch EKF's ATE on the same recording (``fusion-vo run
--backend ekf``). The poses it published at 50 Hz are predicted to the node's clock from that state: at
the drive's starts and stops (steps in speed) they are off by the step times the node's lag behind the clock,
which is the machine's load; once the speed has been steady for longer than that lag they are exact.
"""

import numpy as np
import pytest

from fusion_vo.cli.main import main
from fusion_vo.evaluation.evaluate import evaluate_trajectories
from fusion_vo.evaluation.io import read_groundtruth
from fusion_vo.geometry import se2
from fusion_vo.recording import write_tum

from background import placed

pytestmark = pytest.mark.ros2
#: the recording and its batch EKF run, made ahead in the background (tests/background.py)
BATCH = ["run", "{standard:short}", "--out", "{out}", "--backend", "ekf", "--no-evaluate"]
BACKGROUND_COMMANDS = {"camera_batch/batch": BATCH}
BACKGROUND_JOBS = {"*": ["standard:short", "fusion-vo:camera_batch/batch"]}


@pytest.fixture(scope="module")
def camera_run(tmp_path_factory, standard_recording, ahead, peer):
    tmp = tmp_path_factory.mktemp("camera")
    rec, track = standard_recording("short"), tmp / "node_track.tum"

    def batch_here():
        out = tmp / "batch"
        assert main([placed(arg, {"standard:short": str(rec), "out": str(out)}) for arg in BATCH]) == 0
        return out

    batch = ahead("fusion-vo:camera_batch/batch", batch_here)
    spec = {"node": ["ros2", "--ros-args", "-p", f"calibration:={rec}", "-p", "use_sim_time:=true",
                     "-p", "diagnostics_period:=0.25", "-p", "fusion.reorder_window:=0.05",
                     # a busy machine may leave the node seconds behind: no frame dropped, no sample too late,
                     # so that the track does not depend on the machine's load (the benchmark measures speed)
                     "-p", "image_queue:=200", "-p", "history:=30.0",
                     "-p", f"trajectory_file:={track}"],
            "play": ["ros2-play", str(rec), "--speed", "1"], "signal": "SIGTERM",
            "stop_timeout": 120}  # (writing the track waits for the camera's last increment)
    out = peer(tmp, spec)
    published = tmp / "published.tum"
    poses = out["poses"]
    write_tum(published, [p["t"] for p in poses], [[p["x"], p["y"], p["yaw"]] for p in poses])
    reference = read_groundtruth(rec / "state_groundtruth_estimate0" / "data.csv")
    files = {"batch": batch / "ekf.tum", "wheel": batch / "wheel.tum", "node": track, "published": published}
    ate = {name: r.figures["ate_m"] for name, r in evaluate_trajectories(reference, files).items()}
    print("ATE [mm]: " + ", ".join(f"{name} {1e3 * v:.4f}" for name, v in ate.items()))
    return out, ate, _published_errors(reference, published)


def _published_errors(reference, published, before: float = 0.5):
    """Each published pose's position error against the truth at its stamp; whether the truth's twist (speed
    and yaw rate, which the node predicts as constant) was steady over the ``before`` seconds up to the stamp;
    the truth's speed there; the largest change of the truth's velocity over those seconds (m/s)."""
    t, xy = reference.timestamps, reference.positions_xyz[:, :2]
    yaw = np.unwrap(se2.yaw_of_quaternion(reference.orientations_quat_wxyz))
    v = np.gradient(xy, t, axis=0)
    twist = np.column_stack([np.hypot(*v.T), np.gradient(yaw, t)])
    poses = np.loadtxt(published, ndmin=2)
    stamps = poses[:, 0]
    truth = np.column_stack([np.interp(stamps, t, xy[:, 0]), np.interp(stamps, t, xy[:, 1])])
    error = np.hypot(*(poses[:, 1:3] - truth).T)
    window = stamps[:, None] + np.linspace(-before, 0.0, 101)  # (pose, instant), the last instant its stamp
    twist_w, v_w = (np.stack([np.interp(window, t, a[:, i]) for i in range(2)], axis=-1) for a in (twist, v))
    steady = np.all(np.ptp(twist_w, axis=1) < 1e-3, axis=1)
    step = np.max(np.hypot(*np.moveaxis(v_w - v_w[:, -1:], -1, 0)), axis=1)
    return error, steady, twist_w[:, -1, 0], step


def test_the_node_track_is_within_one_and_a_half_times_the_batch_ekf(camera_run):
    out, ate, _ = camera_run
    assert out["code"] == 0, out["stderr"][-5:]
    assert any("online track of" in line for line in out["stdout"])
    assert ate["node"] <= 1.5 * ate["batch"], ate
    assert ate["batch"] < 0.5 * ate["wheel"], ate  # the camera matters here: a track without it would fail


def test_the_camera_frames_were_measured_and_fused(camera_run):
    out, _, _ = camera_run
    cam = out["diagnostics"]["fusion_vo: camera"]
    n = {key: int(cam[key]) for key in ("received", "unusable", "frames", "dropped", "out_of_order", "camera.used")}
    # 101 frames sent best effort, as a camera driver sends them: on a busy machine DDS may lose a few before the
    # node sees them (95 in one run); every frame received was measured (or pushed out of the node's full queue)
    assert n["frames"] >= 90 and n["frames"] + n["dropped"] + n["out_of_order"] == n["received"] <= 101, cam
    assert n["camera.used"] >= 0.9 * n["frames"] and n["unusable"] == 0, cam


def test_the_published_poses_are_predicted_to_the_clock(camera_run):
    """Where the truth's speed and yaw rate were steady over the 0.5 s before a pose, the pose predicted from
    the processed state to its stamp is within 1 mm of the truth (0.06 mm measured on an idle machine, 0.4 mm
    beside four busy loops). The processed state stamped with the clock instead is off by the speed times the
    lag: 2.5 mm at the drive's 0.128 m/s and 20 ms, 6.4 mm at 50 ms (the published poses re-stamped so, from
    the same two runs). Around the steps in speed each pose is within 1 mm plus the step times 0.5 s, a lag of
    up to 0.5 s (3.8 mm the largest error measured idle; the ATE of the published poses was 0.9 mm idle and
    6.7 mm once at the end of a whole suite run)."""
    _, _, (error, steady, speed, step) = camera_run
    assert np.count_nonzero(steady) >= 0.5 * len(error), (np.count_nonzero(steady), len(error))
    assert np.count_nonzero(steady & (speed > 0.1)) >= 3, np.count_nonzero(steady & (speed > 0.1))  # cruising
    assert np.max(error[steady]) < 1e-3, np.sort(error[steady])[-5:]
    assert np.all(error < 1e-3 + 0.5 * step), np.max(error - 0.5 * step)


def test_the_poses_came_at_the_publish_rate_over_the_whole_drive(camera_run, standard_recording):
    """50 Hz on the played clock. A firing of the timer while the node is busy is skipped (rcl's timers do not
    catch up) and a late one stamps its pose late, so a busy machine shows uneven steps (10 ms after a late
    firing) but never more than 50 poses in a second of the played clock. The median step is 20 ms when the node
    runs alone (benchmarks/ros2_node.py measures the rate); at the end of a whole suite run it was once 90 ms, so
    the rate is the benchmark's figure and this test holds the node to publishing all along the drive: a median
    step of at most the diagnostics period (0.25 s), and poses from the first second to the last sample."""
    out, _, _ = camera_run
    poses, estimate = out["poses"], out["diagnostics"]["fusion_vo: estimate"]
    assert len(poses) == int(estimate["published"]), estimate  # every pose the node sent was received
    stamps = np.array([p["t"] for p in poses])
    steps = np.diff(stamps)
    in_a_second = np.searchsorted(stamps, stamps + 1.0 - 1e-6) - np.arange(len(stamps))  # from each pose on
    assert np.min(steps) > 0 and np.max(in_a_second) <= 51, (np.min(steps), np.max(in_a_second))
    assert np.median(steps) <= 0.25, np.percentile(steps, [0, 50, 90])
    t = np.loadtxt(standard_recording("short") / "imu0" / "data.csv", delimiter=",", usecols=0) * 1e-9
    assert stamps[0] < t[0] + 1.0 and stamps[-1] >= t[-1] - 1e-6, (stamps[[0, -1]], t[[0, -1]])


def test_sigterm_stops_the_node_cleanly(camera_run):
    """(Within 2 s: tests/ros2/test_faults.py; here the node writes its track first.)"""
    out, _, _ = camera_run
    assert out["code"] == 0 and out["stderr"][-1] == "fusion-vo ros2: stopped"
