"""``fusion-vo simulate`` and ``import-bag`` never delete what fusion-vo did not write."""

from __future__ import annotations

import pytest

from fault_tools import assert_error, cli, snapshot

from fusion_vo.cli.main import main

TINY = ("--profile", "straight", "-O", "length=0.01", "-O", "width=32", "-O", "height=24", "-O", "fu=40",
        "-O", "fv=40", "-O", "cu=15.5", "-O", "cv=11.5", "-O", "supersample=1")


@pytest.mark.parametrize("target", [".", "..", "../..", "./"])
def test_simulate_never_replaces_the_current_folder_or_its_parents(target, tmp_path, capsys, monkeypatch):
    work = tmp_path / "a" / "b"
    work.mkdir(parents=True)
    (tmp_path / "a" / "keep.txt").write_text("mine")
    (work / "keep.txt").write_text("mine too")
    monkeypatch.chdir(work)
    before = snapshot(tmp_path)
    for force in ((), ("--force",)):
        status, _, err = cli(capsys, "simulate", target, *TINY, *force)
        assert_error(status, err, "refusing to replace the current folder")
        assert snapshot(tmp_path) == before


def test_simulate_refuses_a_folder_that_is_not_its_recording(tmp_path, capsys):
    out = tmp_path / "photos"
    out.mkdir()
    (out / "holiday.jpg").write_bytes(b"\xff\xd8")
    before = snapshot(tmp_path)
    status, _, err = cli(capsys, "simulate", out, *TINY)
    assert_error(status, err, "photos", "not empty", "--force")
    assert snapshot(tmp_path) == before
    status, _, err = cli(capsys, "simulate", out, *TINY, "--force")
    assert status == 0, err
    assert not (out / "holiday.jpg").exists() and (out / ".fusion-vo-recording").is_file()


def test_simulate_replaces_its_own_recording_and_an_empty_folder(tmp_path, capsys):
    out = tmp_path / "rec"
    out.mkdir()
    status, _, err = cli(capsys, "simulate", out, *TINY)
    assert status == 0, err
    (out / "cam0" / "extra.png").write_bytes(b"")
    status, _, err = cli(capsys, "simulate", out, *TINY, "--seed", "3")
    assert status == 0, err
    assert not (out / "cam0" / "extra.png").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec"]


def test_import_bag_refuses_a_folder_it_did_not_write(tmp_path, capsys):
    out = tmp_path / "thesis"
    out.mkdir()
    (out / "main.tex").write_text("precious")
    before = snapshot(tmp_path)
    status, _, err = cli(capsys, "import-bag", tmp_path / "missing.bag", out)
    assert_error(status, err, "thesis", "not empty")
    assert snapshot(tmp_path) == before


@pytest.mark.parametrize("command", ["simulate", "demo"])
def test_a_negative_seed_is_a_usage_error_naming_the_option(command, tmp_path, capsys):
    argv = [command, str(tmp_path / "rec"), "--seed", "-1"] if command == "simulate" else [command, "--seed", "-1"]
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--seed" in err and "Traceback" not in err
    assert not (tmp_path / "rec").exists()


@pytest.mark.parametrize("profile, duration", [("random", "1e-9"), ("standstill", "0.001")])
def test_simulate_a_drive_shorter_than_two_frames_is_an_error(profile, duration, tmp_path, capsys):
    """--duration 1e-9 was an internal error (IndexError); 0.001 s wrote a one-frame recording nothing can run on."""
    before = snapshot(tmp_path)
    status, _, err = cli(capsys, "simulate", tmp_path / "rec", *TINY[4:], "--profile", profile, "--duration", duration)
    assert_error(status, err, f"'{profile}' drive lasts", "too short for two camera frames", "duration")
    assert snapshot(tmp_path) == before


@pytest.mark.parametrize("where", ["out_is_a_file", "run_is_not_ours", "recording_is_not_ours"])
def test_demo_checks_its_folders_before_generating_and_offers_no_force(where, tmp_path, capsys, monkeypatch):
    """demo generated its recording (a minute) before finding run/ was someone else's, then told the user to
    give --force, which demo does not have; an --out that is a file gave 'File exists'."""
    out = tmp_path / "demo"
    if where == "out_is_a_file":
        out.write_text("mine")
        named, fragment = out, "must be a folder, but a file of that name exists"
    else:
        folder = out / ("run" if where == "run_is_not_ours" else "recording")
        folder.mkdir(parents=True)
        (folder / "notes.txt").write_text("mine")
        named, fragment = folder, "was not written by fusion-vo; give another --out"

    def no_generation(*args, **kwargs):
        raise AssertionError("the demo recording was generated before the folders were checked")

    monkeypatch.setattr("fusion_vo.simulation.simulate", no_generation)
    before = snapshot(tmp_path)
    status, _, err = cli(capsys, "demo", "--out", out)
    assert_error(status, err, str(named), fragment)
    assert "--force" not in err
    assert snapshot(tmp_path) == before


@pytest.mark.parametrize("option, named", [(("--duration", "5"), "--duration"), (("-O", "side=2"), "-O side"),
                                           (("-O", "radius = 0.2"), "-O radius")])
def test_simulate_a_shape_option_the_profile_ignores_is_an_error(option, named, tmp_path, capsys):
    """'--profile straight --duration 5' silently drove the default 1 m instead (the option only shapes random
    and standstill drives)."""
    before = snapshot(tmp_path)
    status, _, err = cli(capsys, "simulate", tmp_path / "rec", *TINY, *option)
    assert_error(status, err, f"{named}: not used by the 'straight' profile", "(only by ")
    assert snapshot(tmp_path) == before


@pytest.mark.parametrize("option, fragment", [
    ("start_time_ns=-5", "start_time_ns must be at least 0, not -5"),
    ("start_time_ns=9223372036854775807", "would run past 2^63 ns"),  # the stamps wrapped round to negative
    ("featureless_time=[2, 1]", "featureless_time: a time span [t0, t1] needs t0 <= t1, not [2.0, 1.0]"),
    # finite but absurd, or work without end: each number option has a range
    ("fu=1e-9", "focal lengths fu, fv 1e-09, 40 px are not a camera's for a 32x24 image"),
    ("camera_height=1.0e+300", "camera_height must be at most 100, not 1e+300"),
    ("length=1.0e+300", "length must be at most 1000, not 1e+300"),
    ("supersample=1000", "supersample must be at most 16, not 1000"),
    ("camera_rate=1.0e+9", "camera_rate must be at most 10000"),
    ("gyro_bias=[0, 0, 1.0e+300]", "gyro_bias[2]: must be at most 100, not 1e+300"),
    ("width=" + "9" * 5001, "--option width: '99999"),
    ("length=999", "drive lasts"),  # within the range, but a drive of more than an hour
])
def test_simulate_options_that_would_write_an_unreadable_recording_are_errors(option, fragment, tmp_path, capsys):
    """Negative or wrapped-round timestamps were written (and refused by every command reading them)."""
    before = snapshot(tmp_path)
    status, _, err = cli(capsys, "simulate", tmp_path / "rec", *TINY, "-O", option)
    assert_error(status, err, fragment)
    assert snapshot(tmp_path) == before


@pytest.mark.parametrize("item", ["width", "=3", " =3"])
def test_simulate_an_option_without_a_key_names_the_option(item, tmp_path, capsys):
    """'-O =3' was reported as '(top level): unknown key' followed by every option's name."""
    status, _, err = cli(capsys, "simulate", tmp_path / "rec", *TINY, "-O", item)
    assert_error(status, err, f"--option needs KEY=VALUE, got '{item}'")
    assert not (tmp_path / "rec").exists()
