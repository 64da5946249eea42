"""Frames: any path the OS accepts, 12-bit data in 16-bit PNGs, and a camera that gives no motion at all."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import pytest
import numpy as np

from fault_tools import assert_error, cli
from fusion_vo.recording import Recording


def _statuses(run: Path) -> dict[str, int]:
    rows = (run / "velocities.csv").read_text().splitlines()[1:]
    out: dict[str, int] = {}
    for r in rows:
        s = r.split(",")[4]
        out[s] = out.get(s, 0) + 1
    return out


def test_a_recording_path_that_is_not_utf8_is_read(pristine, tmp_path):
    """OpenCV's imread crashes the process on such a path; frames are decoded from bytes instead."""
    root = os.fsencode(tmp_path) + b"/rec-\xff\xfe"
    shutil.copytree(pristine, os.fsdecode(root))
    out = os.fsencode(tmp_path) + b"/out-\xff"
    proc = subprocess.run([sys.executable, "-m", "fusion_vo.cli.main", "run", root, "--out", out,
                           "--backend", "none", "--no-evaluate"], capture_output=True, timeout=300)
    assert proc.returncode == 0, proc.stderr.decode(errors="replace")
    assert b"Traceback" not in proc.stderr
    statuses = _statuses(Path(os.fsdecode(out)))
    assert statuses.get("ok", 0) >= 20  # the frames were decoded and tracked


def test_12_bit_data_in_16_bit_pngs_is_tracked_like_8_bit(pristine, tmp_path, capsys):
    status, _, err = cli(capsys, "run", pristine, "--out", tmp_path / "run8", "--sensors", "camera",
                         "--backend", "none", "--no-evaluate")
    assert status == 0, err
    rec = Path(shutil.copytree(pristine, tmp_path / "rec12"))
    for png in (rec / "cam0" / "data").iterdir():
        img = cv2.imread(str(png), cv2.IMREAD_UNCHANGED)
        cv2.imwrite(str(png), (img.astype(np.uint16) << 4) | 0x7)  # 12 significant bits
    frame, original = next(Recording(rec).frames()), next(Recording(pristine).frames())
    assert frame.image.dtype == np.uint16  # scaled to the full 16-bit range: the top byte is the 8-bit frame
    assert np.abs((frame.image >> 8).astype(int) - original.image.astype(int)).max() == 0
    status, _, err = cli(capsys, "run", rec, "--out", tmp_path / "run12", "--sensors", "camera",
                         "--backend", "none", "--no-evaluate")
    assert status == 0, err
    ok8, ok12 = _statuses(tmp_path / "run8").get("ok", 0), _statuses(tmp_path / "run12").get("ok", 0)
    assert ok8 >= 20 and abs(ok12 - ok8) <= 1


def test_a_camera_that_gives_no_motion_is_an_error_when_it_is_the_only_sensor(recording, tmp_path, capsys):
    for png in (recording / "cam0" / "data").iterdir():
        png.write_bytes(np.full(5000, 128, np.uint8).tobytes())  # not an image
    status, _, err = cli(capsys, "run", recording, "--out", tmp_path / "out", "--sensors", "camera")
    assert_error(status, err, "cam0")
    assert not (tmp_path / "out").exists()


def test_a_textureless_camera_with_wheels_says_so(recording, tmp_path, capsys):
    for png in (recording / "cam0" / "data").iterdir():
        cv2.imwrite(str(png), np.full((120, 160), 90, np.uint8))  # readable, but nothing to track
    status, out, err = cli(capsys, "run", recording, "--out", tmp_path / "out", "--backend", "ekf",
                           "--no-evaluate")
    assert status == 0, err
    assert "the camera gave no motion estimate in any of its 33 frames" in out
    assert "the other sensors carried" not in out or "wheel" in out
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert "vo" not in summary["trajectories"] and "ekf" in summary["trajectories"]


def test_camera_alone_never_claims_other_sensors(recording, tmp_path, capsys):
    pngs = sorted((recording / "cam0" / "data").iterdir())
    for png in pngs[10:20]:
        cv2.imwrite(str(png), np.full((120, 160), 90, np.uint8))
    status, out, err = cli(capsys, "run", recording, "--out", tmp_path / "out", "--sensors", "camera",
                           "--backend", "ekf", "--no-evaluate")
    assert status == 0, err
    assert "the other sensors carried the estimate" not in out


def test_some_unreadable_frames_are_skipped_and_counted(recording, tmp_path, capsys):
    pngs = sorted((recording / "cam0" / "data").iterdir())
    pngs[12].write_bytes(b"broken")
    pngs[20].unlink()
    status, out, err = cli(capsys, "run", recording, "--out", tmp_path / "out", "--backend", "ekf",
                           "--no-evaluate")
    assert status == 0, err
    assert "2 frames could not be read and were skipped" in out
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["skipped_frames"] == 2


def test_frames_of_the_wrong_size_stop_the_run_naming_the_frame(recording, tmp_path, capsys):
    for png in (recording / "cam0" / "data").iterdir():
        cv2.imwrite(str(png), np.full((60, 80), 90, np.uint8))
    status, _, err = cli(capsys, "run", recording, "--out", tmp_path / "out", "--backend", "ekf")
    assert_error(status, err, "cam0/data/", "80x60", "160x120")
    assert not (tmp_path / "out").exists()


def _png_claiming(width: int, height: int) -> bytes:
    """A PNG file whose header states ``width`` x ``height`` pixels and whose data is far too short."""
    import struct
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"\0" * 100)) + chunk(b"IEND", b""))


def test_a_frame_whose_header_claims_100000_by_100000_pixels_is_skipped_and_counted(recording, tmp_path, capsys,
                                                                                     caplog):
    """OpenCV stops at its pixel limit with an exception: the whole run died with an internal error."""
    frame = sorted((recording / "cam0" / "data").iterdir())[12]
    frame.write_bytes(_png_claiming(100_000, 100_000))
    status, out, err = cli(capsys, "run", recording, "--out", tmp_path / "out", "--backend", "ekf",
                           "--no-evaluate")
    assert status == 0, err
    assert "1 frame could not be read and was skipped" in out
    assert f"{frame.name}: frame is 100000x100000 (its PNG header)" in caplog.text
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["skipped_frames"] == 1


def test_an_image_beyond_opencvs_pixel_limit_is_unreadable_not_an_exception(tmp_path):
    from fusion_vo.errors import InputError
    from fusion_vo.recording.reader import decode_image, read_image
    from fusion_vo.calibration.chessboard import read_image as read_board_image

    p = tmp_path / "big.png"
    p.write_bytes(_png_claiming(100_000, 100_000))
    assert decode_image(p.read_bytes()) is None
    assert read_image(p, None) == (None, "unreadable or corrupt image")
    with pytest.raises(InputError, match="not a readable image"):
        read_board_image(p)


def test_a_run_whose_every_frame_failed_for_one_reason_names_it(recording, tmp_path, capsys, monkeypatch):
    """(klt: {max_tracks: 1e11} made OpenCV refuse every frame; the run said only that no frame gave a motion)"""
    def refuse(*args, **kwargs):
        raise cv2.error("integer won't fit into a C int")

    monkeypatch.setattr(cv2, "goodFeaturesToTrack", refuse)
    status, out, err = cli(capsys, "run", recording, "--out", tmp_path / "out", "--backend", "ekf", "--no-evaluate")
    assert status == 0, err
    reason = "every one: OpenCV error: integer won't fit into a C int"
    assert f"the camera gave no motion estimate in any of its 33 frames (33 bad_frame; {reason})" in out
    assert any(reason in note for note in json.loads((tmp_path / "out" / "summary.json").read_text())["notes"])
    status, _, err = cli(capsys, "run", recording, "--out", tmp_path / "alone", "--sensors", "camera")
    assert_error(status, err, "cam0/data.csv", f"no frame gave a motion estimate (33 frames: 33 bad_frame; {reason})")
