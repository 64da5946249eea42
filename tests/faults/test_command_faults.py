"""The commands after ``run`` given bad input: a broken run folder (``export``, ``evaluate``, ``compare``),
options that override the configuration, output folders that are an input (``replay``, ``batch``,
``sweep``), and playback options that cannot work. Each is one line naming the file or the option, exit
status 2, and nothing written."""

from __future__ import annotations

import json
import shutil
import stat
from pathlib import Path

import pytest

from fault_tools import SMALL, assert_error, cli, snapshot
from sweep_faults_job import run_all as run_sweeps

#: the sweeps, run ahead in the background (tests/background.py, tests/conftest.py)
BACKGROUND_COMMANDS = {"python:sweep_faults": ["{repo}/tests/faults/sweep_faults_job.py", "{out}"]}
BACKGROUND_JOBS = {"test_sweep_ranking_by_a_trajectory_no_run_has_is_an_error_naming_the_option": ["python:sweep_faults"],
                   "test_a_sweep_whose_random_draws_repeat_says_how_many_sets_it_runs": ["python:sweep_faults"]}


def _files(root: Path) -> dict:
    """The snapshot without the folders' modification times."""
    return {k: v if not stat.S_ISDIR(v[0]) else v[0] for k, v in snapshot(root).items()}


@pytest.fixture(scope="module")
def sweeps(ahead_json, tmp_path_factory) -> dict:
    """Each case of sweep_faults_job.SWEEPS: its grid file, exit status, output, whether results.csv was written."""
    return ahead_json("python:sweep_faults", lambda: run_sweeps(tmp_path_factory.mktemp("sweeps")))


def _one_line(err: str) -> None:
    assert len([ln for ln in err.splitlines() if ln.strip()]) == 1, err


# ------------------------------------------------------------------ a broken run folder
def run_yaml_syntax_error(run):
    (run / "run.yaml").write_text("sequence: [unclosed\n")
    return "run.yaml:2", "not valid YAML"


def quaternion_of_rounding_noise(run):
    """A near-zero quaternion would be normalised into an arbitrary rotation (here 180 degrees of yaw)."""
    p = run / "ekf.tum"
    lines = p.read_text().splitlines()
    fields = lines[5].split()
    fields[4:8] = ["0", "0", "-0.000002", "0"]
    lines[5] = " ".join(fields)
    p.write_text("\n".join(lines) + "\n")
    return "ekf.tum:6", "quaternion has norm 0.000"


def folder_named_like_a_trajectory(run):
    (run / "extra.tum").mkdir()
    return "extra.tum", "is a folder"


def file_given_as_the_run(run):
    """A file where the run folder should be (a trajectory, say) is not a "run folder not found"."""
    shutil.rmtree(run)
    run.write_text("0 0 0 0 0 0 0 1\n")
    return str(run), "is a file, not a run folder"


def tum_in_nanoseconds(run):
    """Integer nanoseconds where TUM has seconds: 10^27 ns does not fit the int64 stamps."""
    p = run / "ekf.tum"
    lines = p.read_text().splitlines()
    rows = [i for i, ln in enumerate(lines) if ln.strip() and not ln.startswith("#")]
    for i in rows:
        fields = lines[i].split()
        fields[0] = str(round(float(fields[0]) * 1e9))
        lines[i] = " ".join(fields)
    p.write_text("\n".join(lines) + "\n")
    return f"ekf.tum:{rows[0] + 1}", "TUM timestamps are seconds"


def run_yaml_sequence_not_a_path(run):
    p = run / "run.yaml"
    p.write_text("".join("sequence: 5\n" if ln.startswith("sequence:") else ln
                         for ln in p.read_text().splitlines(keepends=True)))
    return "run.yaml: sequence:", "not 5"


RUN_FAULTS = [run_yaml_syntax_error, quaternion_of_rounding_noise, folder_named_like_a_trajectory,
              file_given_as_the_run, tum_in_nanoseconds, run_yaml_sequence_not_a_path]


def _export(run, tmp_path):
    return ("export", run, tmp_path / "x.mcap", "--to", "mcap")


def _evaluate(run, tmp_path):
    return ("evaluate", run)


def _compare(run, tmp_path):
    return ("compare", run, "--out", tmp_path / "cmp")


@pytest.mark.parametrize("command", [_export, _evaluate, _compare], ids=["export", "evaluate", "compare"])
@pytest.mark.parametrize("fault", RUN_FAULTS, ids=[f.__name__ for f in RUN_FAULTS])
def test_a_broken_run_folder_is_one_line_naming_the_file(fault, command, run_folder, tmp_path, capsys):
    where, what = fault(run_folder)
    before = _files(tmp_path)
    status, _, err = cli(capsys, *command(run_folder, tmp_path))
    assert_error(status, err, where, what)
    _one_line(err)
    assert _files(tmp_path) == before  # (evaluate's staging folder came and went: folders' times may change)


@pytest.mark.parametrize("command", [_evaluate, _compare], ids=["evaluate", "compare"])
def test_a_run_yaml_naming_a_recording_that_is_gone_gives_the_rest(command, run_folder, tmp_path, capsys):
    """The report and the comparison are built from the run folder's files: a recording moved away leaves out
    the accuracy only, and says so (export too says so in a note: see test_export_says_when_the_ground_truth...)."""
    gone = tmp_path / "moved-away"
    p = run_folder / "run.yaml"
    p.write_text("".join(f"sequence: {gone}\n" if ln.startswith("sequence:") else ln
                         for ln in p.read_text().splitlines(keepends=True)))
    status, out, err = cli(capsys, *command(run_folder, tmp_path))
    assert status == 0, err
    if command is _evaluate:
        assert f"note: The recording {gone} named in run.yaml is not found: no accuracy figures" in out
        assert not (run_folder / "metrics.json").exists()
    else:
        assert f"The recording {gone} named in run.yaml is not found" in out
        assert "ate_m" not in json.loads((tmp_path / "cmp" / "compare.json").read_text())[run_folder.name]["ekf"]


def test_compare_tells_apart_runs_of_the_same_name(pristine_run, tmp_path, capsys):
    a, b = tmp_path / "a" / "x" / "run", tmp_path / "b" / "x" / "run"
    shutil.copytree(pristine_run, a)
    shutil.copytree(pristine_run, b)
    status, _, err = cli(capsys, "compare", a, b, "--out", tmp_path / "cmp")
    assert status == 0, err
    assert sorted(json.loads((tmp_path / "cmp" / "compare.json").read_text())) == ["a/x/run", "b/x/run"]


def test_compare_refuses_a_run_given_twice(pristine_run, tmp_path, capsys):
    status, _, err = cli(capsys, "compare", pristine_run, f"{pristine_run}/", "--out", tmp_path / "cmp")
    assert_error(status, err, "given twice")
    assert not (tmp_path / "cmp").exists()


# ------------------------------------------------------------------ options over the configuration
OPTIONS = [
    (("run", "{rec}", "--out", "{out}", "--sensors", "sonar"), ["--sensors sonar", "'sonar'"]),
    (("run", "{rec}", "--out", "{out}", "--sensors", ""), ["--sensors ''", "no sensor"]),
    (("run", "{rec}", "--out", "{out}", "--focal-length", "200"), ["--focal-length", "--uncalibrated"]),
    (("run", "{rec}", "--out", "{out}", "--uncalibrated", "--focal-length", "-5"), ["--focal-length", "-5"]),
    (("run", "{rec}", "--out", "{out}", "--uncalibrated", "--focal-length", "nan"), ["--focal-length", "nan"]),
    (("calibrate", "lever-arm", "{rec}", "--height-std", "nan"), ["--height-std", "nan"]),
    (("calibrate", "height", "{rec}", "--distance", "inf", "--out", "{out}"), ["--distance", "inf"]),
    (("calibrate", "intrinsics", "{rec}/cam0/data", "--board", "9x6", "--square", "0.02", "--out", "{out}"),
     ["cam0/data", "is a folder"]),
    (("replay", "{rec}", "--out", "{out}", "--sensors", "sonar"), ["--sensors sonar"]),
    (("replay", "{rec}", "--out", "{out}", "--sensors", ","), ["--sensors ','", "no sensor"]),
    (("batch", "{rec}", "--out", "{out}", "--sensors", "sonar", "--workers", "1"), ["--sensors sonar"]),
    (("export", "{run}", "{out}", "--to", "mcap", "--frame-id", ""), ["--frame-id"]),
    (("export", "{run}", "{out}", "--to", "mcap", "--trajectories", ""), ["--trajectories ''"]),
    # work without an upper bound: 'replay --speed 0 --rate 1e9' was still busy after 100 s on a 12 s recording
    (("replay", "{rec}", "--out", "{out}", "--speed", "0", "--rate", "1e9"), ["--rate", "at most 1000", "1e9"]),
    (("replay", "{rec}", "--out", "{out}", "--speed", "1e-9"), ["--speed", "from 0.01 to 1e+06", "1e-9"]),
    (("replay", "{rec}", "--out", "{out}", "--window", "1e300"), ["--window 1e+300", "reorder_window must be at most 1000000, not 1e+300"]),
    (("batch", "{rec}", "--out", "{out}", "--workers", "100000"), ["--workers", "at most 256", "100000"]),
    (("bench", "{rec}", "--repeats", "1000000"), ["--repeats", "at most 100"]),
]


@pytest.mark.parametrize("args, fragments", OPTIONS, ids=[" ".join(a[:1] + a[3:]) or "x" for a, _ in OPTIONS])
def test_an_option_the_configuration_rejects_names_the_option(args, fragments, pristine, pristine_run, tmp_path,
                                                              capsys):
    out = tmp_path / "out"
    args = [str(a).format(rec=pristine, run=pristine_run, out=out) for a in args]
    status, _, err = cli(capsys, *args)
    assert_error(status, err, *fragments)
    assert not out.exists()


# ------------------------------------------------------------------ output folders that are an input
def test_replay_never_writes_into_the_recording_or_over_a_run(recording, run_folder, tmp_path, capsys):
    for out in (recording, recording / "cam0", run_folder):
        before = snapshot(tmp_path)
        status, _, err = cli(capsys, "replay", recording, "--out", out, "--speed", "0")
        assert_error(status, err, str(out))
        assert snapshot(tmp_path) == before


@pytest.mark.parametrize("command", ["batch", "sweep"])
@pytest.mark.parametrize("where", ["the_recording", "inside_the_recording", "beside_the_recording"])
def test_batch_output_folder_that_is_or_holds_a_run_of_the_recording_itself(command, where, recording, tmp_path,
                                                                            capsys):
    out = {"the_recording": recording, "inside_the_recording": recording / "batch",
           "beside_the_recording": tmp_path}[where]  # tmp_path/rec would be the run folder of rec
    grid = tmp_path.parent / f"{tmp_path.name}-grid.yaml"
    grid.write_text("grid: {fusion.max_gap: [0.25]}\n")
    extra = ["--grid", grid] if command == "sweep" else []
    before = snapshot(tmp_path)
    status, _, err = cli(capsys, command, recording, "--out", out, "--workers", "1", "--no-dashboard", *extra)
    assert_error(status, err, "give another output folder")
    assert snapshot(tmp_path) == before


# ------------------------------------------------------------------ playback options that cannot work
@pytest.mark.parametrize("option, fragment", [(("--camera-delay", "1e9"), "--camera-delay"),
                                              (("--sensors", "wheel,imu", "--rate", "1e-9"), "--rate")])
def test_replay_timing_that_reads_nothing_is_an_error(option, fragment, pristine, tmp_path, capsys):
    """(a camera delay of 1e9 s made the player query the estimate 50 times a second for 30 years)"""
    out = tmp_path / "out"
    status, _, err = cli(capsys, "replay", pristine, "--out", out, "--speed", "0", *option)
    assert_error(status, err, fragment)
    assert not out.exists()


# ------------------------------------------------------------------ show-matches
def test_show_matches_names_a_missing_frame_once(recording, tmp_path, capsys):
    frame = sorted((recording / "cam0" / "data").iterdir())[2]
    frame.unlink()
    status, _, err = cli(capsys, "show-matches", recording, "--frame", "2", "--out", tmp_path / "m.png")
    assert_error(status, err, "image file missing", "cam0/data.csv line 4")
    assert err.count(frame.name) == 1, err
    assert not (tmp_path / "m.png").exists()


# ------------------------------------------------------------------ compare: all three files or none
@pytest.mark.parametrize("failure", [RuntimeError("a plotting bug"), KeyboardInterrupt()], ids=["error", "ctrl_c"])
def test_a_failed_compare_leaves_no_part_of_a_comparison(failure, pristine_run, tmp_path, capsys, monkeypatch):
    import fusion_vo.evaluation.compare as compare

    earlier = tmp_path / "earlier"
    status, _, err = cli(capsys, "compare", pristine_run, "--out", earlier)
    assert status == 0, err

    def broken(*args, **kwargs):
        raise failure

    monkeypatch.setattr(compare, "plot_compare", broken)
    before = _files(tmp_path)
    for out in (tmp_path / "new", earlier):
        status, _, err = cli(capsys, "compare", pristine_run, "--out", out)
        assert status in (1, 130), err
        assert _files(tmp_path) == before  # no compare.json without its table and plot; the earlier one whole


# ------------------------------------------------------------------ evaluate: part of a trajectory on the clock
def test_a_trajectory_half_outside_the_ground_truth_is_said_to_be(run_folder, capsys, caplog):
    p = run_folder / "vo.tum"
    rows = [ln.split() for ln in p.read_text().splitlines() if not ln.startswith("#")]
    shift = (float(rows[-1][0]) - float(rows[0][0])) / 2  # half the drive later: another clock's offset
    p.write_text("".join(f"{float(r[0]) + shift:.9f} {' '.join(r[1:])}\n" for r in rows))
    status, _, err = cli(capsys, "evaluate", run_folder)
    assert status == 0, err
    said = [r.getMessage() for r in caplog.records if r.levelname == "WARNING" and "vo.tum" in r.getMessage()]
    assert len(said) == 1 and "lie within the ground truth's time span" in said[0], said
    assert not any("ekf.tum" in r.getMessage() for r in caplog.records if r.levelname == "WARNING")


# ------------------------------------------------------------------ outputs written into the recording
def test_show_matches_never_writes_over_a_frame_or_into_the_recording(recording, tmp_path, capsys):
    frame = sorted((recording / "cam0" / "data").iterdir())[0]
    for out, fragment in [(frame, "part of an input"), (recording / "m.png", "part of an input"),
                          (tmp_path / "m.txt", "ending in .png")]:
        before = snapshot(tmp_path)
        status, _, err = cli(capsys, "show-matches", recording, "--frame", "3", "--out", out)
        assert_error(status, err, str(out), fragment)
        assert snapshot(tmp_path) == before


def test_compare_never_writes_into_a_recording(pristine, pristine_run, capsys, tmp_path):
    before = snapshot(pristine)
    for out in (pristine, pristine / "cam0" / "data"):
        status, _, err = cli(capsys, "compare", pristine_run, "--out", out)
        assert_error(status, err, str(out), "part of an input")
    assert snapshot(pristine) == before


def test_compare_never_writes_into_a_run_folder_it_compares(pristine_run, run_folder, tmp_path, capsys,
                                                           monkeypatch):
    """'compare A B --out A' wrote into run folder A (and a later 'run --out A' deleted the files)."""
    def no_evaluation(*args, **kwargs):
        raise AssertionError("the runs were evaluated before the output folder was checked")

    monkeypatch.setattr("fusion_vo.evaluation.compare.evaluate_trajectories", no_evaluation)
    before = snapshot(tmp_path)
    for out in (run_folder, run_folder / "cmp"):
        status, _, err = cli(capsys, "compare", run_folder, pristine_run, "--out", out)
        assert_error(status, err, str(out), "part of an input", str(run_folder))
    assert snapshot(tmp_path) == before


def test_run_never_makes_its_folder_inside_the_recording(recording, tmp_path, capsys):
    before = snapshot(tmp_path)
    status, _, err = cli(capsys, "run", recording, "--out", recording / "newsub")
    assert_error(status, err, str(recording / "newsub"), "part of an input")
    assert snapshot(tmp_path) == before


def test_show_matches_replaces_only_a_picture_it_wrote(recording, tmp_path, capsys):
    """'show-matches REC --frame 5 -o mine.png' overwrote the user's own picture."""
    import cv2
    import numpy as np

    mine, ours = tmp_path / "mine.png", tmp_path / "ours.png"
    cv2.imwrite(str(mine), np.zeros((8, 8), np.uint8))
    (tmp_path / "folder.png").mkdir()
    before = snapshot(tmp_path)
    for out in (mine, tmp_path / "folder.png"):
        status, _, err = cli(capsys, "show-matches", recording, "--frame", "3", "--out", out)
        assert_error(status, err, str(out), "fusion-vo did not write it")
    assert snapshot(tmp_path) == before
    for frame in ("3", "4"):  # written, then replaced
        status, out, err = cli(capsys, "show-matches", recording, "--frame", frame, "--out", ours)
        assert status == 0 and f"frames {int(frame) - 1} -> {frame}" in out, err


def test_export_never_writes_into_the_run_or_its_recording(pristine, run_folder, tmp_path, capsys):
    """A bag inside the run folder would go when the run is redone (run replaces its folder whole)."""
    before_rec, before_run = snapshot(pristine), snapshot(run_folder)
    for out in (run_folder / "run.mcap", run_folder / "bag", pristine / "gt.mcap"):
        status, _, err = cli(capsys, "export", run_folder, out, "--to", "mcap")
        assert_error(status, err, str(out), "part of an input")
    assert snapshot(pristine) == before_rec and snapshot(run_folder) == before_run
    status, _, err = cli(capsys, "export", run_folder, tmp_path / "beside.mcap", "--to", "mcap")
    assert status == 0, err


@pytest.mark.parametrize("fmt, name", [("mcap", "same.mcap"), ("rosbag2", "same_bag")])
def test_of_two_exports_to_one_name_the_second_fails_naming_it(fmt, name, run_folder, tmp_path, capsys,
                                                              monkeypatch):
    """Both exited 0 and the second silently replaced the first's MCAP file; the loser of two rosbag2
    exports named a hidden temporary folder."""
    from fusion_vo.export import ros

    out = tmp_path / name
    writer = getattr(ros, f"_write_{fmt}")

    def rival_finishes_first(path, *args):  # the other export moves its output into place meanwhile
        writer(path, *args)
        if path.is_dir():
            out.mkdir()
            (out / "rival").write_text("rival")
        else:
            out.write_text("rival")

    monkeypatch.setattr(ros, f"_write_{fmt}", rival_finishes_first)
    status, _, err = cli(capsys, "export", run_folder, out, "--to", fmt)
    assert_error(status, err, f"{out}: already exists")
    assert ".partial" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["run", name])  # no staging folder left
    assert (out / "rival" if fmt == "rosbag2" else out).read_text() == "rival"


#: a ROS 2 topic or frame name: tokens of ASCII letters, digits and underscores, none starting with a digit, no "__"
_ROS2_NAME = r"/?(?!.*__)[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*"


def test_export_writes_trajectory_names_ros_2_accepts_and_says_so(run_folder, tmp_path, capsys):
    """'my-traj.tum' was exported on /fusion_vo/my-traj/odometry, a name ROS 2 tools reject."""
    import re

    from mcap.reader import make_reader
    from rosbags.typesys import Stores, get_typestore

    for name in ("my-traj", "2nd traj"):
        shutil.copy(run_folder / "ekf.tum", run_folder / f"{name}.tum")
    out = tmp_path / "x.mcap"
    status, printed, err = cli(capsys, "export", run_folder, out, "--to", "mcap", "--no-groundtruth")
    assert status == 0, err
    assert "note: trajectory 'my-traj' exported as /fusion_vo/my_traj/odometry and frame my_traj/base_link" in printed
    assert "note: trajectory '2nd traj' exported as /fusion_vo/t_2nd_traj/odometry" in printed
    store = get_typestore(Stores.ROS2_HUMBLE)
    topics, frames = set(), set()
    with open(out, "rb") as fh:
        for schema, channel, message in make_reader(fh).iter_messages():
            topics.add(channel.topic)
            msg = store.deserialize_cdr(message.data, schema.name)
            frames.update(tf.child_frame_id for tf in msg.transforms) if channel.topic == "/tf" else \
                frames.add(msg.child_frame_id)
    assert {"/fusion_vo/my_traj/odometry", "/fusion_vo/t_2nd_traj/odometry", "/fusion_vo/ekf/odometry"} <= topics
    assert "t_2nd_traj/base_link" in frames
    assert all(re.fullmatch(_ROS2_NAME, name) for name in topics | frames), topics | frames


def test_export_of_two_names_ros_2_would_see_as_one_names_both(run_folder, tmp_path, capsys):
    for name in ("my-traj", "my_traj"):
        shutil.copy(run_folder / "ekf.tum", run_folder / f"{name}.tum")
    status, _, err = cli(capsys, "export", run_folder, tmp_path / "x.mcap", "--to", "mcap")
    assert_error(status, err, "'my-traj' and 'my_traj'", "/fusion_vo/my_traj/odometry")
    assert not (tmp_path / "x.mcap").exists()


# ------------------------------------------------------------------ import-bag: a topic without messages
BAGS = Path(__file__).resolve().parents[1] / "data" / "robot_localization"


@pytest.fixture(scope="module")
def bag_without_imu_messages(tmp_path_factory) -> Path:
    """The Husky bag with its /imu/data connection kept and its messages left out."""
    rosbag1 = pytest.importorskip("rosbags.rosbag1")
    from rosbags.typesys import Stores, get_typestore

    out = tmp_path_factory.mktemp("bags") / "no_imu_messages.bag"
    store = get_typestore(Stores.ROS1_NOETIC)
    with rosbag1.Reader(BAGS / "test1_140s_to_152s.bag") as reader, rosbag1.Writer(out) as writer:
        conns = {c.id: writer.add_connection(c.topic, c.msgtype, typestore=store) for c in reader.connections}
        for conn, t, raw in reader.messages():
            if conn.topic != "/imu/data":
                writer.write(conns[conn.id], t, raw)
    return out


def test_a_topic_without_messages_is_left_out_or_an_error_when_named(bag_without_imu_messages, tmp_path, capsys):
    status, out, err = cli(capsys, "import-bag", bag_without_imu_messages, tmp_path / "rec")
    assert status == 0, err
    assert "/imu/data: no message; imu0/ not written" in out
    assert sorted(p.name for p in (tmp_path / "rec").iterdir() if not p.name.startswith(".")) == ["gps0", "odom0"]
    # the recording is usable as it is: no sensor claimed without a sample
    status, _, err = cli(capsys, "run", tmp_path / "rec", "--out", tmp_path / "run", "--backend", "ekf",
                         "--no-evaluate")
    assert status == 0, err

    status, _, err = cli(capsys, "import-bag", bag_without_imu_messages, tmp_path / "named", "--imu-topic", "/imu/data")
    assert_error(status, err, "--imu-topic /imu/data", "no message")
    assert not (tmp_path / "named").exists()


# ------------------------------------------------------------------ replay: all files or none
@pytest.mark.parametrize("failure", [OSError(28, "No space left on device"), KeyboardInterrupt()],
                         ids=["full_disk", "ctrl_c"])
def test_an_interrupted_replay_leaves_the_earlier_files_whole(failure, pristine, tmp_path, capsys, monkeypatch):
    import fusion_vo.backends.result as result

    args = ("replay", pristine, "--speed", "0", "--sensors", "wheel,imu", "--out")
    earlier = tmp_path / "earlier"
    status, _, err = cli(capsys, *args, earlier)
    assert status == 0, err
    calls = []

    def fail_late(*a, **kw):  # the covariances are written after the live poses
        calls.append(a)
        raise failure

    monkeypatch.setattr(result, "write_pose_covariances", fail_late)
    before = _files(tmp_path)
    for out in (tmp_path / "new", earlier):
        status, _, err = cli(capsys, *args, out)
        assert status in (2, 130), err
        assert _files(tmp_path) == before  # no new live poses beside old trajectories; no new folder
    assert calls


# ------------------------------------------------------------------ sweep: a ranking that cannot be made
def test_sweep_ranking_by_a_trajectory_no_run_has_is_an_error_naming_the_option(sweeps):
    sweep = sweeps["unknown_trajectory"]
    assert "Traceback" not in sweep["stderr"]
    assert_error(sweep["code"], sweep["stderr"], "--trajectory ekf_smothed", "ekf_smoothed")  # the names the runs have
    assert "no parameter set completed" not in sweep["stdout"]
    assert sweep["results"]  # the runs themselves are kept


def test_export_says_when_the_ground_truth_of_the_run_is_gone(run_folder, tmp_path, capsys):
    config = run_folder / "run.yaml"
    config.write_text("\n".join(f"sequence: {tmp_path / 'moved'}" if ln.startswith("sequence:") else ln
                                for ln in config.read_text().splitlines()) + "\n")
    status, out, err = cli(capsys, "export", run_folder, tmp_path / "x.mcap", "--to", "mcap")
    assert status == 0, err
    assert "no ground truth exported" in out and "groundtruth" not in out.split("note:")[0]
    assert "is not there (moved or deleted?)" in out


def test_export_of_a_recording_without_ground_truth_says_it_has_none(pristine, tmp_path, capsys):
    rec = Path(shutil.copytree(pristine, tmp_path / "rec"))
    shutil.rmtree(rec / "state_groundtruth_estimate0")
    assert cli(capsys, "-q", "run", rec, "--out", tmp_path / "run", "--backend", "ekf", "--no-evaluate")[0] == 0
    status, out, err = cli(capsys, "export", tmp_path / "run", tmp_path / "x.mcap", "--to", "mcap")
    assert status == 0, err
    assert f"its recording {rec.resolve()} has none" in out and "moved or deleted" not in out


def test_a_runs_own_run_yaml_configures_another_run(pristine_run, pristine, tmp_path, capsys):
    status, _, err = cli(capsys, "-q", "run", pristine, "--out", tmp_path / "again", "--config",
                         pristine_run / "run.yaml", "--no-evaluate")
    assert status == 0, err
    assert (tmp_path / "again" / "ekf.tum").read_text() == (pristine_run / "ekf.tum").read_text()


def test_uncalibrated_runs_a_camera_whose_sensor_yaml_has_no_intrinsics(recording, tmp_path, capsys):
    yaml_path = recording / "cam0" / "sensor.yaml"
    yaml_path.write_text("".join(ln for ln in yaml_path.read_text().splitlines(keepends=True)
                                 if not ln.startswith("intrinsics")))
    status, _, err = cli(capsys, "run", recording, "--out", tmp_path / "plain", "--backend", "none", "--no-evaluate")
    assert_error(status, err, "sensor.yaml", "missing key 'intrinsics'", "--uncalibrated")
    status, _, err = cli(capsys, "run", recording, "--out", tmp_path / "run", "--backend", "none", "--no-evaluate",
                         "--uncalibrated", "--focal-length", "200")
    assert status == 0, err
    assert (tmp_path / "run" / "vo.tum").is_file()


def test_output_cut_off_by_its_reader_is_no_error(tmp_path):
    import subprocess
    import sys

    for args in (["run", "--print-config"], ["simulate", "--standard", "hard", "--print-config"]):
        cmd = [sys.executable, "-c", "import sys; from fusion_vo.cli.main import main; sys.exit(main(sys.argv[1:]))",
               *args]
        reader = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        reader.stdout.close()  # gone before the command writes (as `| true` is): its first write fails
        err = reader.stderr.read()
        reader.wait(timeout=120)
        assert reader.returncode == 0, err
        assert b"error" not in err, err


@pytest.mark.filterwarnings("error")  # a warning is output the user did not ask for
@pytest.mark.parametrize("frontend", ["features", "klt"])
def test_show_matches_on_textureless_frames_draws_no_match_without_a_warning(frontend, recording, tmp_path, capsys):
    import cv2
    import numpy as np

    for png in sorted((recording / "cam0" / "data").iterdir())[2:4]:
        cv2.imwrite(str(png), np.full((120, 160), 90, np.uint8))  # readable, but nothing to match
    status, out, err = cli(capsys, "show-matches", recording, "--frame", "3", "--frontend", frontend,
                           "--out", tmp_path / "m.png")
    assert status == 0, err
    assert "0 matches" in out and (tmp_path / "m.png").is_file()
    assert err.strip() == ""  # (klt was an internal error; features printed matplotlib's legend warning)


# ------------------------------------------------------------------ calibrate lever-arm: a drive, not a turn
def test_lever_arm_from_a_drive_along_an_arc_is_refused(tmp_path, capsys):
    """The frames' fixed point of an arc is the arc's centre: the lever arm came out wrong, to 0.1 mm."""
    from fusion_vo.simulation import simulate

    small = {k: v for k, v in SMALL.items() if k != "length"}  # the camera and rates of the fault tests' drive
    rec = simulate(tmp_path / "arc", profile="circle", seed=4, radius=0.1, **small)
    out = tmp_path / "sensor.yaml"
    status, _, err = cli(capsys, "calibrate", "lever-arm", rec, "--out", out)
    assert_error(status, err, "wheel0/data.csv", "not a turn in place")
    assert not out.exists()


@pytest.mark.parametrize("what", ["plain_folder", "text_file"])
@pytest.mark.parametrize("listing", [False, True], ids=["import", "list"])
def test_import_bag_on_something_that_is_no_bag_says_what_a_bag_is(what, listing, pristine, tmp_path, capsys):
    if what == "plain_folder":
        bag, fragment = pristine, "a folder without metadata.yaml"  # a recording given where the bag goes
    else:
        bag, fragment = tmp_path / "topics.txt", "does not end in .bag, .mcap or .db3"
        bag.write_text("/imu/data\n")
    before = snapshot(tmp_path)
    args = ["--list"] if listing else [tmp_path / "rec"]
    status, _, err = cli(capsys, "import-bag", bag, *args)
    assert_error(status, err, str(bag), "not a ROS bag", fragment, "ROS 2 bag folder (holding metadata.yaml)")
    assert "Expected metadata file" not in err
    assert snapshot(tmp_path) == before


# ------------------------------------------------------------------ sweep: a grid with a value given twice
@pytest.mark.parametrize("text, line", [("grid:\n  features.detector: [harris, harris, fast]\n", 2),
                                        ("grid:\n  fusion.max_gap:\n    - 0.25\n    - 0.5\n    - 2.5e-1\n", 5)],
                         ids=["flow_list", "block_list_same_number"])
def test_a_sweep_grid_value_given_twice_names_the_file_line_and_key(text, line, pristine, tmp_path, capsys):
    grid = tmp_path / "grid.yaml"
    grid.write_text(text)
    before = snapshot(tmp_path)
    status, _, err = cli(capsys, "sweep", pristine, "--out", tmp_path / "sweep", "--grid", grid)
    key = text.split("\n")[1].strip().split(":")[0]
    assert_error(status, err, f"{grid}:{line}:", f"grid key '{key}'", "given twice")
    assert snapshot(tmp_path) == before


# ------------------------------------------------------------------ sweep: list and mapping values
#: a whole section swept as a mapping would replace the section (the base's other keys lost): refused before any run
MAPPING_GRIDS = [("grid:\n  klt: [{max_tracks: 60}]\n", 2, "klt"),
                 ("random: 3\nranges:\n  fusion.graph:\n    - {max_iterations: 5}\n", 4, "fusion.graph"),
                 ("grid:\n  klt: {max_tracks: 60}\n", None, "klt")]


@pytest.mark.parametrize("text, line, key", MAPPING_GRIDS, ids=["grid_list", "random_choice", "grid_single"])
def test_a_sweep_over_a_whole_section_is_refused_before_any_run(text, line, key, pristine, tmp_path, capsys):
    """It ran every task, then died with 'unhashable type', leaving results without report.html."""
    grid = tmp_path / "grid.yaml"
    grid.write_text(text)
    before = snapshot(tmp_path)
    status, _, err = cli(capsys, "sweep", pristine, "--out", tmp_path / "sweep", "--grid", grid)
    assert_error(status, err, f"{grid}:{line}:" if line else f"{grid}:", f"grid key '{key}'", "is a mapping",
                 f"'{key}.")
    assert snapshot(tmp_path) == before


def test_a_sweep_over_list_values_ranks_and_reports_them_as_json_text(tmp_path):
    """Swept lists (``fusion.initial_pose``) are one column of canonical JSON text: grouped, ranked, plotted."""
    import pandas as pd

    from fusion_vo.batch.columns import COLUMNS
    from fusion_vo.batch.grid import Grid, ParameterSet
    from fusion_vo.batch.ranking import best_sets, describe_set
    from fusion_vo.batch.runner import _frame, write_results

    key = "fusion.initial_pose"
    poses = {"p000": [0, 0, 0], "p001": [1.5, 0, 0.25]}
    rows = []
    for name, pose in poses.items():
        for rec, ate in (("a", 0.1), ("b", 0.3)):
            row = dict.fromkeys(COLUMNS, 0.0) | {"recording": rec, "trajectory": "vo", "status": "ok", "error": "",
                                                 "ate_m": ate + (name == "p001"), "cached": False, "run_dir": ""}
            rows.append(row | {"parameter_set": name, key: list(pose)})
    frame = _frame(rows, [key])
    grid = Grid([key], [ParameterSet(n, {key: p}) for n, p in poses.items()], [], None)
    write_results(frame, tmp_path, "sweep", grid)
    table = pd.read_csv(tmp_path / "results.csv")
    assert sorted(set(table[key])) == ["[0, 0, 0]", "[1.5, 0, 0.25]"]
    ranked, _ = best_sets(frame)
    assert list(ranked["parameter_set"]) == ["p000", "p001"] and ranked["mean"].round(6).tolist() == [0.2, 1.2]
    assert describe_set(frame, "p001") == f"{key}=[1.5, 0, 0.25]"
    assert "[1.5, 0, 0.25]" in (tmp_path / "report.html").read_text()


def test_optimize_refuses_list_choices_naming_the_key(pristine, tmp_path, capsys):
    grid = tmp_path / "grid.yaml"
    grid.write_text("grid:\n  fusion.initial_pose: [[0, 0, 0], [1, 0, 0]]\n")
    status, _, err = cli(capsys, "sweep", pristine, "--out", tmp_path / "sweep", "--grid", grid, "--optimize",
                         "ate_m")
    assert_error(status, err, f"{grid}", "key 'fusion.initial_pose'", "--optimize chooses among")
    assert not (tmp_path / "sweep").exists()


# ------------------------------------------------------------------ bench: frames that measured nothing
def test_bench_gives_no_rate_for_frames_that_measured_nothing(recording, pristine, capsys):
    """Textureless frames cost almost nothing: 2000+ frames/s beside 'ok 0.0 %' was printed as a speed."""
    import re

    import cv2
    import numpy as np

    status, out, err = cli(capsys, "bench", pristine, "--repeats", "1", "--threads", "1", "--frontend", "klt")
    assert status == 0, err  # the unbroken recording is measured
    assert "not a speed" not in out and re.search(r"\| klt, 1 thread \| \d+ \|", out), out

    for png in (recording / "cam0" / "data").iterdir():
        cv2.imwrite(str(png), np.full((120, 160), 90, np.uint8))
    status, out, err = cli(capsys, "bench", recording, "--repeats", "1", "--threads", "1", "--frontend", "klt")
    assert_error(status, err, str(recording), "no speed measured", "klt, 1 thread (0 %)")
    assert not re.search(r"\d frames/s", out), out  # no rate anywhere, in the progress lines or the tables
    assert "| klt, 1 thread | not a speed: 0 % of frame pairs tracked | not comparable |" in out
    assert "klt          33 frames" in out and "->  not a speed: 0 % of frame pairs tracked" in out


# ------------------------------------------------------------------ calibrate wheels: UMBmark without squares
def test_umbmark_on_runs_that_are_not_the_two_squares_is_refused(pristine, tmp_path, capsys):
    """A straight drive given as both squares printed a wheel base of 2e60 m (exit 0, and written with --out)."""
    other = Path(shutil.copytree(pristine, tmp_path / "other"))
    out = tmp_path / "wheel.yaml"
    status, _, err = cli(capsys, "calibrate", "wheels", pristine, "--method", "umbmark", "--ccw", other, "--out", out)
    assert_error(status, err, str(pristine), "not a clockwise square", "turns 0 deg clockwise")
    status, _, err = cli(capsys, "calibrate", "wheels", pristine, "--method", "umbmark", "--ccw", pristine,
                         "--out", out)
    assert_error(status, err, "--ccw", "the same recording")
    status, _, err = cli(capsys, "calibrate", "wheels", pristine, "--ccw", other, "--out", out)
    assert_error(status, err, "--ccw is used only with --method umbmark")
    assert not out.exists()


# ------------------------------------------------------------------ an output folder that is a file
@pytest.mark.parametrize("under", [False, True], ids=["a_file", "under_a_file"])
def test_compare_out_that_is_a_file_says_so_before_evaluating(under, pristine_run, tmp_path, capsys, monkeypatch):
    """It evaluated every run, then said only 'File exists'."""
    taken = tmp_path / "taken"
    taken.write_text("mine")
    out = taken / "cmp" if under else taken

    def no_evaluation(*args, **kwargs):
        raise AssertionError("the runs were evaluated before the output folder was checked")

    monkeypatch.setattr("fusion_vo.evaluation.compare.evaluate_trajectories", no_evaluation)
    before = snapshot(tmp_path)
    status, _, err = cli(capsys, "compare", pristine_run, "--out", out)
    assert_error(status, err, str(out), "must be a folder, but", f"{taken} is a file" if under else "a file of that name")
    assert snapshot(tmp_path) == before


def test_a_sweep_whose_random_draws_repeat_says_how_many_sets_it_runs(sweeps):
    """'random: 6' over two choices silently ran two parameter sets."""
    sweep = sweeps["repeated_draws"]
    assert "Traceback" not in sweep["stderr"]
    assert sweep["code"] == 0, sweep["stderr"]
    assert f"note: {sweep['grid']}: 'random: 6' drew 2 distinct parameter sets; each runs once" in sweep["stdout"]


# ------------------------------------------------------------------ empty option values, --threads' bound
#: an empty value was taken as '.' (run --config: "is a folder, not a file"; show-matches --out: a picture in the
#: current folder) or as no value (import-bag --imu-topic: the bag's only IMU topic): now a usage error naming it
EMPTY_OPTIONS = [
    (("run", "{rec}", "--out", "{out}", "--config", ""), "argument --config/-c: expected a configuration file"),
    (("run", "{rec}", "--out", "{out}", "--config", " "), "argument --config/-c: expected a configuration file"),
    (("import-bag", "{tmp}/x.bag", "{out}", "--imu-topic", ""), "argument --imu-topic: expected a topic name"),
    (("import-bag", "{tmp}/x.bag", "{out}", "--image-topic", ""), "argument --image-topic: expected a topic name"),
    (("import-bag", "{tmp}/x.bag", ""), "argument out: expected a recording folder"),
    (("show-matches", "{rec}", "--frame", "2", "--out", ""), "argument --out/-o: expected an image file name"),
    (("run", "{rec}", "--out", "{out}", "--threads", "257"), "argument --threads: must be at most 256, not 257"),
    (("run", "{rec}", "--out", "{out}", "--threads", "100000"), "argument --threads: must be at most 256"),
]


@pytest.mark.parametrize("args, fragment", EMPTY_OPTIONS, ids=[" ".join(a[:1] + a[-2:]) for a, _ in EMPTY_OPTIONS])
def test_an_empty_option_value_is_a_usage_error_naming_the_option(args, fragment, pristine, tmp_path, capsys,
                                                                   monkeypatch):
    work = tmp_path / "cwd"
    work.mkdir()
    monkeypatch.chdir(work)
    out = tmp_path / "out"
    args = [str(a).format(rec=pristine, out=out, tmp=tmp_path) for a in args]
    status, _, err = cli(capsys, *args)
    assert_error(status, err, fragment)
    assert not out.exists() and not any(work.iterdir())


def test_the_threads_bound_of_the_command_line_is_the_configuration_s():
    from fusion_vo.cli.arguments import MAX_THREADS
    from fusion_vo.odometry import OdometryConfig

    number = next(p for p in OdometryConfig.model_json_schema()["properties"]["threads"]["anyOf"] if "maximum" in p)
    assert number["maximum"] == MAX_THREADS
