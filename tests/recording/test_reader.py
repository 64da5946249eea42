"""Reading the recording layout, and the errors a user gets for a broken one."""

import math

import cv2
import numpy as np
import pytest
import yaml

from fusion_vo.cli.main import main
from fusion_vo.errors import InputError
from fusion_vo.evaluation.io import read_tum
from fusion_vo.evaluation.metrics import yaw_of
from fusion_vo.geometry.camera import CameraModel
from fusion_vo.recording import Recording, write_tum
from fusion_vo.sensors.imu import read_imu
from fusion_vo.sensors.range import read_range
from fusion_vo.sensors.wheel import read_ticks, read_twist

T0 = 1_600_000_000_000_000_000


def make_recording(root, n_frames=4, size=(64, 48)):
    """A tiny but complete recording: frames, IMU, wheels, odom, range, ground truth."""
    cam = root / "cam0"
    (cam / "data").mkdir(parents=True)
    rng = np.random.default_rng(0)
    rows = []
    for i in range(n_frames):
        t = T0 + i * 50_000_000
        cv2.imwrite(str(cam / "data" / f"{t}.png"), rng.integers(0, 255, (size[1], size[0]), dtype=np.uint8))
        rows.append(f"{t},{t}.png")
    (cam / "data.csv").write_text("#timestamp [ns],filename\n" + "\n".join(rows) + "\n")
    CameraModel(size[0], size[1], 50.0, 50.0, size[0] / 2, size[1] / 2).write_yaml(cam / "sensor.yaml")
    (root / "imu0").mkdir()
    (root / "imu0" / "data.csv").write_text(
        "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y,w_RS_S_z,a_RS_S_x [m s^-2],a_RS_S_y,a_RS_S_z\n"
        + "".join(f"{T0 + i * 5_000_000},0,0,0.1,0,0,9.81\n" for i in range(10)))
    (root / "imu0" / "sensor.yaml").write_text("rate_hz: 200\ngyroscope_noise_density: 1.0e-4\n")
    (root / "wheel0").mkdir()
    (root / "wheel0" / "data.csv").write_text(
        "#timestamp [ns],left_ticks,right_ticks\n" + f"{T0},2147483600,-5\n{T0 + 20_000_000},-2147483600,5\n")
    (root / "wheel0" / "sensor.yaml").write_text(yaml.safe_dump(
        {"ticks_per_revolution": 4096, "wheel_radius_left": 0.05, "wheel_radius_right": 0.05, "wheel_base": 0.3}))
    (root / "odom0").mkdir()
    (root / "odom0" / "data.csv").write_text(f"#timestamp [ns],v_x,v_y,w_z\n{T0},0.1,0,0.2\n")
    (root / "range0").mkdir()
    (root / "range0" / "data.csv").write_text(f"#timestamp [ns],distance [m]\n{T0},0.1\n{T0 + 10**9},0.11\n")
    gt = root / "state_groundtruth_estimate0"
    gt.mkdir()
    q = (math.cos(0.25), 0, 0, math.sin(0.25))  # yaw 0.5 rad
    gt.joinpath("data.csv").write_text(
        "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z [],v_x\n"
        + f"{T0},1.0,2.0,0.0,{q[0]},{q[1]},{q[2]},{q[3]},7\n")
    return root


def test_reads_every_stream(tmp_path):
    rec = Recording(make_recording(tmp_path / "seq"))
    assert rec.streams() == ["cam0", "imu0", "odom0", "range0", "state_groundtruth_estimate0", "wheel0"]
    assert len(rec) == 4 and np.allclose(np.diff(rec.frame_times), 0.05)
    frames = list(rec.frames())
    assert [f.index for f in frames] == [0, 1, 2, 3]
    assert all(f.image is not None and f.image.shape == (48, 64) and f.error is None for f in frames)
    imu = read_imu(rec)
    assert imu.gyro.shape == (10, 3) and imu.orientation is None and imu.noise["gyroscope_noise_density"] == 1e-4
    wheel = read_ticks(rec)
    assert wheel.left.tolist() == [2147483600, -2147483600] and wheel.config.wheel_base == 0.3
    assert read_twist(rec).wz[0] == 0.2 and read_range(rec).distance[1] == 0.11
    gt = rec.groundtruth()
    assert gt.xyyaw[0] == pytest.approx([1.0, 2.0, 0.5])


def test_frames_are_decoded_lazily(tmp_path, monkeypatch):
    rec = Recording(make_recording(tmp_path / "seq", n_frames=3))
    calls = []
    real = cv2.imdecode
    monkeypatch.setattr(cv2, "imdecode", lambda *a, **k: calls.append(a[0]) or real(*a, **k))
    it = rec.frames()
    next(it)
    assert len(calls) == 1


def test_colour_and_16_bit_frames_become_grey(tmp_path):
    root = make_recording(tmp_path / "seq", n_frames=2)
    names = sorted((root / "cam0" / "data").iterdir())
    cv2.imwrite(str(names[0]), np.full((48, 64, 3), (10, 200, 30), np.uint8))
    cv2.imwrite(str(names[1]), np.full((48, 64), 40000, np.uint16))
    f0, f1 = list(Recording(root).frames())
    assert f0.image.ndim == 2 and f0.image.dtype == np.uint8
    assert f1.image.dtype == np.uint16 and f1.image[0, 0] == 40000


def test_bad_frames_are_reported_not_raised(tmp_path):
    root = make_recording(tmp_path / "seq", n_frames=3)
    names = sorted((root / "cam0" / "data").iterdir())
    names[0].write_bytes(b"not a png")
    cv2.imwrite(str(names[1]), np.zeros((10, 10), np.uint8))
    names[2].unlink()
    errs = [f.error for f in Recording(root).frames()]
    assert "corrupt" in errs[0] and "line 2" in errs[0]
    assert "10x10" in errs[1] and "64x48" in errs[1]
    assert "missing" in errs[2]


@pytest.mark.parametrize(
    "rel, content, message, line",
    [
        ("imu0/data.csv", "#h\n1,0,0,0,0,0,9.8\n2,0,0,nan,0,0,9.8\n", "NaN", 3),
        ("imu0/data.csv", "#h\n1,0,0,0,0,0,9.8\n1,0,0,0,0,0,9.8\n", "duplicate timestamp", 3),
        ("imu0/data.csv", "#h\n5,0,0,0,0,0,9.8\n3,0,0,0,0,0,9.8\n", "decreasing timestamp", 3),
        ("imu0/data.csv", "#h\n1,0,0,0,0,0,9.8\n2,0,0,0,0,0\n", "found 6 fields", 3),
        ("imu0/data.csv", "#h\n1,0,0,abc,0,0,9.8\n", "'abc' is not a number", 2),
        ("imu0/data.csv", "#h\n99999999999999999999,0,0,0,0,0,9.8\n", "outside the range", 2),
        ("cam0/data.csv", "#h\n-5,a.png\n", "outside the range", 2),
        ("wheel0/data.csv", "#h\n1,10,12\n2,1.5,12\n", "integers", 3),
        ("cam0/data.csv", "#h\n1,a.png\n1,b.png\n", "duplicate timestamp", 3),
        ("state_groundtruth_estimate0/data.csv", "#h\n1,0,0,0,2,0,0,0\n", "norm", 2),
    ],
)
def test_malformed_rows_name_file_and_line(tmp_path, rel, content, message, line):
    root = make_recording(tmp_path / "seq")
    (root / rel).write_text(content)
    rec = Recording(root)
    reader = {"imu0": lambda: read_imu(rec), "wheel0": lambda: read_ticks(rec), "cam0": lambda: rec.frame_times,
              "state_groundtruth_estimate0": rec.groundtruth}[rel.split("/")[0]]
    with pytest.raises(InputError) as err:
        reader()
    assert message in str(err.value)
    assert err.value.line == line and err.value.path.name == "data.csv"


def test_missing_calibration_key(tmp_path):
    root = make_recording(tmp_path / "seq")
    (root / "wheel0" / "sensor.yaml").write_text("ticks_per_revolution: 4096\nwheel_base: 0.3\n")
    with pytest.raises(InputError, match="missing key 'wheel_radius_left'"):
        read_ticks(Recording(root))
    (root / "cam0" / "sensor.yaml").write_text("resolution: [64, 48]\n")
    with pytest.raises(InputError, match="missing key 'intrinsics'"):
        Recording(root).camera


def test_a_stream_of_any_folder_is_read_with_the_checks_every_stream_gets(tmp_path):
    """A registered sensor's own folder (``compass0/``) is listed and read through ``Recording.table``: its rows get
    the checks of the built-in streams, each a one-line error naming the file and the line."""
    root = make_recording(tmp_path / "seq")
    rec = Recording(root)
    assert not rec.has("compass0") and "compass0" not in rec.streams()
    with pytest.raises(InputError, match="this recording has no compass stream") as info:
        rec.table("compass0", 1, "compass", "heading")
    assert info.value.path == root
    (root / "compass0").mkdir()
    data = root / "compass0" / "data.csv"
    data.write_text(f"#timestamp [ns],yaw [rad]\n{T0},0.1\n{T0 + 10**8},0.2\n")
    tab, path = Recording(root).table("compass0", 1, "compass", "heading")
    assert path == data and np.allclose(tab.values[:, 0], [0.1, 0.2]) and np.allclose(np.diff(tab.t), 0.1)
    assert "compass0" in Recording(root).streams()
    for rows, message, line in ((f"{T0},0.1\n{T0},0.2\n", "duplicate timestamp", 3),
                                (f"{T0},0.1\n{T0 + 1},nan\n", "NaN", 3),
                                (f"{T0},0.1,7\n", "1 heading, found 3 fields", 2)):
        data.write_text("#h\n" + rows)
        with pytest.raises(InputError, match=message) as info:
            Recording(root).table("compass0", 1, "compass", "heading")
        assert (info.value.path, info.value.line) == (data, line)
    data.write_text(f"#h\n{T0},0.1\n")
    with pytest.raises(InputError, match="compass") as info:
        Recording(root).table("compass0", 1, "compass", "heading", min_rows=2)
    assert info.value.path == data


def test_missing_stream_is_a_clear_error(tmp_path):
    root = make_recording(tmp_path / "seq")
    (root / "imu0" / "data.csv").unlink()
    with pytest.raises(InputError, match="file not found") as info:  # imu0/ is there: a broken stream
        read_imu(Recording(root))
    assert info.value.path == root / "imu0" / "data.csv"
    assert "imu0" in Recording(root).streams()
    (root / "imu0" / "sensor.yaml").unlink()
    (root / "imu0").rmdir()
    with pytest.raises(InputError, match="no IMU stream"):
        read_imu(Recording(root))
    assert "imu0" not in Recording(root).streams()


def test_tum_round_trip(tmp_path):
    t = np.array([0.0, 0.05, 0.1])
    poses = np.array([[0, 0, 0], [0.1, 0.02, 3.0], [0.2, -0.1, -3.1]])
    write_tum(tmp_path / "a.tum", t, poses)
    back = read_tum(tmp_path / "a.tum")
    assert np.allclose(back.timestamps, t) and np.allclose(back.positions_xyz[:, :2], poses[:, :2])
    assert np.allclose(back.positions_xyz[:, 2], 0.0) and np.allclose(yaw_of(back), poses[:, 2])


def test_cli_errors_are_one_line_with_status_2(tmp_path, capsys):
    root = make_recording(tmp_path / "seq")
    (root / "cam0" / "data.csv").write_text("#h\n5,a.png\n3,b.png\n")
    assert main(["run", str(root), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "cam0/data.csv:3" in err and "decreasing" in err
    assert main(["run", str(tmp_path / "nope"), "--out", str(tmp_path / "out")]) == 2
    assert "recording folder not found" in capsys.readouterr().err
    cfg = tmp_path / "c.yaml"
    cfg.write_text("frontend: sift\n")
    assert main(["run", str(root), "--out", str(tmp_path / "out"), "--config", str(cfg)]) == 2
    assert "c.yaml" in capsys.readouterr().err
    assert main(["run", str(root), "--out", str(tmp_path / "out"), "--sensors", "camera,lidar"]) == 2
    assert "sensors[1]: expected one of 'camera', 'wheel', 'imu', 'odom', 'range' or 'gps', got 'lidar'" in capsys.readouterr().err
    (tmp_path / "afile").write_text("")
    assert main(["run", str(root), "--out", str(tmp_path / "afile")]) == 2
    assert "must be a folder" in capsys.readouterr().err


def test_video_instead_of_png_frames(tmp_path):
    root = make_recording(tmp_path / "seq", n_frames=5)
    pngs = sorted((root / "cam0" / "data").iterdir())
    images = [cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in pngs]
    writer = cv2.VideoWriter(str(root / "cam0" / "video.avi"), cv2.VideoWriter_fourcc(*"FFV1"), 20, (64, 48), False)
    if not writer.isOpened():
        pytest.skip("this OpenCV build has no lossless video encoder")
    for img in images:
        writer.write(img)
    writer.release()
    for p in pngs:
        p.unlink()
    (root / "cam0" / "data").rmdir()
    frames = list(Recording(root).frames())
    assert len(frames) == 5 and all(f.error is None for f in frames)
    assert all(np.array_equal(f.image, img) for f, img in zip(frames, images))
    lines = (root / "cam0" / "data.csv").read_text().splitlines()
    (root / "cam0" / "data.csv").write_text("\n".join(lines + [f"{T0 + 10**9},extra.png"]) + "\n")
    with pytest.raises(InputError, match="video ends after 5 frames"):
        list(Recording(root).frames())
