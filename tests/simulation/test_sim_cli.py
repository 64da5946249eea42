"""``fusion-vo simulate``: a small run, and one-line errors with exit status 2 for bad options."""

from __future__ import annotations

import pytest
import yaml

from fusion_vo.cli.main import main

SMALL = ["--profile", "standstill", "--duration", "0.5", "-O", "width=32", "-O", "height=24", "-O", "fu=24",
         "-O", "fv=24", "-O", "cu=15.5", "-O", "cv=11.5", "-O", "supersample=1"]


def test_simulate_writes_a_recording(tmp_path, capsys):
    out = tmp_path / "rec"
    assert main(["-q", "simulate", str(out), "--seed", "3", *SMALL]) == 0
    printed = capsys.readouterr().out.strip().splitlines()
    assert len(printed) == 1 and printed[0].startswith("11 frames, 0.5 s")
    info = yaml.safe_load((out / "simulation.yaml").read_text())
    assert info["profile"] == "standstill" and info["seed"] == 3 and info["options"]["width"] == 32
    assert len((out / "cam0/data.csv").read_text().splitlines()) == 12


@pytest.mark.parametrize("option, message", [
    ("no_such_option=1", "no_such_option: unknown key (known: duration, "),
    ("camera_height=.nan", "camera_height must be a finite number, not nan"),
    ("distortion=[0.1, .nan, 0, 0]", "distortion[1]: must be a finite number, not nan"),
    ("noise=loud", "noise: expected a number, got 'loud'"),
    ("dropped_frames=1.5", "dropped_frames must be below 1, not 1.5"),
    ("texture=carpet", "texture: expected one of 'gravel', 'grass' or 'brick', got 'carpet'"),
    ("camera_height=1.0e+300", "camera_height must be at most 100, not 1e+300"),
    ("distortion=[0.1, 0, 0]", "distortion: radial-tangential takes 4 or 5 coefficients, not 3"),
])
def test_bad_option_is_one_line_and_status_2(tmp_path, capsys, option, message):
    out = tmp_path / "rec"
    assert main(["simulate", str(out), *SMALL, "-O", option]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("fusion-vo: error: ") and message in err[0]
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_bad_config_file_is_named(tmp_path, capsys):
    config = tmp_path / "options.yaml"
    config.write_text("camera_height: 0.1\nexposure: 3\n")
    assert main(["simulate", str(tmp_path / "rec"), *SMALL, "--config", str(config)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(config) in err[0] and "exposure: unknown key" in err[0]


def test_unknown_flag_exits_2(tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        main(["simulate", str(tmp_path / "rec"), "--bogus"])
    assert stop.value.code == 2
    assert "unrecognized arguments: --bogus" in capsys.readouterr().err.strip().splitlines()[-1]
