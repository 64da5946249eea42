"""The output folder of ``fusion-vo run`` belongs to one run: replaced as a whole, locked while written,
left untouched by a failed or interrupted run, never a folder fusion-vo did not write; outputs follow the
umask."""

from __future__ import annotations

import fcntl
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from fault_tools import assert_error, cli, snapshot
from fusion_vo.outputs import STAGING_PREFIX

QUICK = ("--backend", "ekf", "--no-evaluate")


def test_a_later_run_replaces_the_folder_as_a_whole(recording, tmp_path, capsys):
    out = tmp_path / "out"
    status, _, err = cli(capsys, "run", recording, "--out", out, *QUICK)
    assert status == 0, err
    assert (out / "vo.tum").is_file() and (out / ".fusion-vo-run").is_file()
    (out / "notes.txt").write_text("mine")  # a file the user put there goes with the folder it is in
    status, _, err = cli(capsys, "run", recording, "--out", out, "--sensors", "wheel,imu", *QUICK)
    assert status == 0, err
    assert not (out / "vo.tum").exists() and not (out / "velocities.csv").exists()  # no stale camera output
    assert not (out / "notes.txt").exists()
    assert (out / "ekf.tum").is_file() and (out / "wheel.tum").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "rec"]  # no staging folder, no lock file


def test_a_folder_fusion_vo_did_not_write_is_refused_unless_forced(recording, tmp_path, capsys):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "thesis.tex").write_text("precious")
    before = snapshot(tmp_path)
    status, _, err = cli(capsys, "run", recording, "--out", out, *QUICK)
    assert_error(status, err, "mine", "not empty", "--force")
    assert snapshot(tmp_path) == before
    status, _, err = cli(capsys, "run", recording, "--out", out, "--force", *QUICK)
    assert status == 0, err
    assert not (out / "thesis.tex").exists() and (out / "ekf.tum").is_file()


@pytest.mark.parametrize("where", ["cwd", "parent_of_cwd", "holds_the_recording", "is_the_recording",
                                   "inside_the_recording"])
def test_never_the_current_folder_its_parents_or_the_input(where, recording, tmp_path, capsys, monkeypatch):
    work = tmp_path / "work" / "sub"
    work.mkdir(parents=True)
    if where in ("cwd", "parent_of_cwd"):
        monkeypatch.chdir(work)
    out = {"cwd": ".", "parent_of_cwd": "..", "holds_the_recording": str(tmp_path),
           "is_the_recording": str(recording), "inside_the_recording": str(recording / "cam0")}[where]
    before = snapshot(tmp_path)
    status, _, err = cli(capsys, "run", recording, "--out", out, "--force", *QUICK)
    expected = {"cwd": "refusing", "parent_of_cwd": "refusing", "inside_the_recording": "part of an input"}
    assert_error(status, err, expected.get(where, "holds an input"))
    assert snapshot(tmp_path) == before


def test_a_second_run_into_a_folder_being_written_fails_cleanly(recording, tmp_path, capsys):
    out = tmp_path / "out"
    lock = tmp_path / ".out.lock"
    fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o666)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)  # as a run in progress holds it
        status, _, err = cli(capsys, "run", recording, "--out", out, *QUICK)
        assert_error(status, err, "another fusion-vo command is writing")
        assert not out.exists()
    finally:
        os.close(fd)


def test_a_failure_in_the_evaluation_leaves_the_previous_run_untouched(recording, tmp_path, capsys, monkeypatch):
    out = tmp_path / "out"
    status, _, err = cli(capsys, "run", recording, "--out", out, "--backend", "ekf")
    assert status == 0, err
    before = snapshot(tmp_path)

    def broken(run_dir, *args, **kwargs):
        (Path(run_dir) / "metrics.json").write_text("{}")
        raise OSError(28, "No space left on device", str(Path(run_dir) / "trajectories.png"))

    monkeypatch.setattr("fusion_vo.evaluation.run_report.build_report", broken)
    status, _, err = cli(capsys, "run", recording, "--out", out, "--backend", "ekf")
    assert_error(status, err, "No space left on device", str(out / "trajectories.png"))
    assert STAGING_PREFIX not in err
    assert snapshot(tmp_path) == before


def test_an_internal_error_is_one_line_with_status_1_and_cleans_up(recording, tmp_path, capsys, monkeypatch):
    def bug(*args, **kwargs):
        raise RuntimeError("Indeterminant linear system detected while working near variable 7")

    monkeypatch.setattr("fusion_vo.pipeline._run_backends", bug)
    status, _, err = cli(capsys, "run", recording, "--out", tmp_path / "out", *QUICK)
    assert status == 1 and err.count("\n") == 1 and "internal error: RuntimeError" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec"]


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_an_interrupted_run_leaves_nothing(sig, recording, tmp_path):
    """The run is stopped by a signal while visual odometry runs: the KLT frontend (the default) is slowed
    down, and marks its first frame and waits there until the test has seen the mark, so the signal arrives
    inside visual odometry, with the staging folder in place, however loaded the machine is."""
    inside = tmp_path / "inside-vo"
    script = (
        "import signal, sys, time\n"
        # Ctrl-C as from an interactive shell, even when the tests were started in the background (which
        # starts them with SIGINT ignored, and the child would inherit that)
        "signal.signal(signal.SIGINT, signal.default_int_handler)\n"
        "import frontends.klt as o\n"
        "real = o.KltFrontend.process\n"
        "import os\n"
        "def slow(self, *a, **k):\n"
        f"    inside = {str(inside)!r}\n"
        "    if not hasattr(slow, 'seen'):\n"  # the first frame: mark it, then wait for the test to see it
        "        slow.seen = open(inside, 'w').close()\n"
        "        start = time.monotonic()\n"
        "        while os.path.exists(inside) and time.monotonic() < start + 60:\n"
        "            time.sleep(0.02)\n"
        "    time.sleep(0.2)\n"
        "    return real(self, *a, **k)\n"
        "o.KltFrontend.process = slow\n"
        "from fusion_vo.cli.main import main\n"
        "sys.exit(main(sys.argv[1:]))\n"
    )
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-c", script, "run", str(recording), "--out", str(out), *QUICK],
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not inside.exists():
        assert proc.poll() is None and time.monotonic() < deadline, "the run ended before it was interrupted"
        time.sleep(0.05)
    inside.unlink()
    assert any(p.name.startswith(STAGING_PREFIX) for p in tmp_path.iterdir())
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + sig, err
    assert "Traceback" not in err and "nothing was left half-written" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec"]


@pytest.mark.parametrize("umask", [0o022, 0o077])
def test_every_output_follows_the_umask(umask, recording, tmp_path, capsys):
    old = os.umask(umask)
    try:
        status, _, err = cli(capsys, "run", recording, "--out", tmp_path / "out", "--backend", "ekf")
        assert status == 0, err
        status, _, err = cli(capsys, "simulate", tmp_path / "sim", "--profile", "straight", "-O", "length=0.01",
                             "-O", "width=32", "-O", "height=24", "-O", "fu=40", "-O", "fv=40", "-O", "cu=15.5",
                             "-O", "cv=11.5", "-O", "supersample=1")
        assert status == 0, err
    finally:
        os.umask(old)
    for root in (tmp_path / "out", tmp_path / "sim"):
        paths = [root, *root.rglob("*")]
        assert len(paths) > 10
        for p in paths:
            want = (0o777 if p.is_dir() else 0o666) & ~umask
            assert p.stat().st_mode & 0o777 == want, f"{p}: {oct(p.stat().st_mode & 0o777)} != {oct(want)}"


def test_calibrate_out_follows_the_umask(pristine, tmp_path, capsys):
    target = tmp_path / "cam0" / "sensor.yaml"
    target.parent.mkdir()
    target.write_text("old: 1\n")
    os.chmod(target, 0o644)
    old = os.umask(0o022)
    try:
        status, out, err = cli(capsys, "calibrate", "height", pristine, "--distance", "0.05", "--allow-failed",
                               "--out", target)
    finally:
        os.umask(old)
    assert status == 0, err
    assert target.stat().st_mode & 0o777 == 0o644 and "intrinsics" in target.read_text()
    assert sorted(p.name for p in target.parent.iterdir()) == ["sensor.yaml"]  # no temporary file left


def test_a_staging_folder_left_by_a_killed_run_is_removed_by_the_next(recording, tmp_path, capsys):
    stale = tmp_path / f"{STAGING_PREFIX}dead" / "out"
    stale.mkdir(parents=True)
    (stale / "vo.tum").write_text("half")
    other = tmp_path / f"{STAGING_PREFIX}other" / "another_name"  # not this target's: left alone
    other.mkdir(parents=True)
    status, _, err = cli(capsys, "run", recording, "--out", tmp_path / "out", *QUICK)
    assert status == 0, err
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([f"{STAGING_PREFIX}other", "out", "rec"])


def test_a_full_disk_names_the_file_not_a_temporary_name(recording, tmp_path, capsys, monkeypatch):
    import fusion_vo.outputs as outputs

    real = os.fdopen

    class Full:
        def __init__(self, fd, mode):
            self.handle = real(fd, mode)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.handle.close()

        def write(self, data):
            raise OSError(28, "No space left on device")

    monkeypatch.setattr(outputs.os, "fdopen", Full)
    status, _, err = cli(capsys, "run", recording, "--out", tmp_path / "out", *QUICK)
    assert_error(status, err, "No space left on device", str(tmp_path / "out") + "/")
    assert ".tmp-" not in err and STAGING_PREFIX not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec"]


def test_a_failed_evaluate_leaves_the_earlier_results_intact(recording, tmp_path, capsys, monkeypatch):
    out = tmp_path / "out"
    status, _, err = cli(capsys, "run", recording, "--out", out, "--backend", "ekf")
    assert status == 0, err
    assert (out / "metrics.json").is_file() and (out / "report.html").is_file()
    before = snapshot(tmp_path)
    from fusion_vo.evaluation import plots

    def full_disk(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(plots, "plot_heading", full_disk)  # after metrics.json and two figures were written
    status, _, err = cli(capsys, "evaluate", out)
    assert_error(status, err, "No space left on device")
    after = snapshot(tmp_path)
    after.pop("out"), before.pop("out")  # the folder's own time changes: a staging folder was made and removed in it
    assert after == before  # metrics, figures and report as they were; no staging folder, no lock
    monkeypatch.undo()
    (out / "gps.png").write_bytes(b"an earlier evaluation's figure")
    (out / "notes.txt").write_text("mine")
    status, _, err = cli(capsys, "evaluate", out)
    assert status == 0, err
    assert not (out / "gps.png").exists()  # an output of an earlier evaluation that this one does not write
    assert (out / "notes.txt").read_text() == "mine"  # anything else stays
    assert (out / "metrics.json").stat().st_mtime_ns > before["out/metrics.json"][2]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "rec"]
    assert not [p for p in out.iterdir() if p.name.startswith(STAGING_PREFIX)]


def test_evaluate_fails_at_once_while_a_run_writes_the_folder(recording, tmp_path, capsys):
    out = tmp_path / "out"
    status, _, err = cli(capsys, "run", recording, "--out", out, *QUICK)
    assert status == 0, err
    fd = os.open(tmp_path / ".out.lock", os.O_RDWR | os.O_CREAT)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        status, _, err = cli(capsys, "evaluate", out)
        assert_error(status, err, "another fusion-vo command is writing this run folder", str(out))
    finally:
        os.close(fd)
    assert not (out / "metrics.json").exists()


def _killed_at_rename(function: str, call: int, body: str) -> subprocess.CompletedProcess:
    """Run ``body`` in a fresh interpreter whose ``os.<function>`` kills the process (SIGKILL: no clean-up
    runs) right after its ``call``-th call."""
    script = f"""
import os, signal
from pathlib import Path
from fusion_vo import outputs
real, calls = os.{function}, []
def dying(*args, **kwargs):
    real(*args, **kwargs)
    calls.append(args)
    if len(calls) == {call}:
        os.kill(os.getpid(), signal.SIGKILL)
os.{function} = dying
{body}
"""
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert proc.returncode == -signal.SIGKILL, proc.stderr
    return proc


def test_files_half_moved_in_by_a_killed_command_are_finished_by_the_next(tmp_path):
    from fusion_vo.outputs import COMMIT_JOURNAL, StagedFiles

    folder = tmp_path / "run"
    folder.mkdir()
    for name in ("metrics.json", "report.html", "a.png", "old.png", "vo.tum"):
        (folder / name).write_text("old")
    body = f"""
with outputs.StagedFiles(Path({str(folder)!r}), replaces=("metrics.json", "report.html", "*.png")) as staged:
    for name in ("a.png", "metrics.json", "report.html"):
        (staged.path / name).write_text("new")
    staged.commit()
"""
    _killed_at_rename("replace", 2, body)  # the journal's own rename, then a.png: the rest not yet moved
    assert (folder / "a.png").read_text() == "new" and (folder / "metrics.json").read_text() == "old"
    assert (folder / COMMIT_JOURNAL).is_file()  # what says the folder is mid-way
    with StagedFiles(folder, replaces=("metrics.json",)) as staged:  # the next writer finishes it first
        assert {p.name: p.read_text() for p in folder.iterdir() if not p.name.startswith(".")} == {
            "metrics.json": "new", "report.html": "new", "a.png": "new", "vo.tum": "old"}  # old.png replaced
        (staged.path / "metrics.json").write_text("newest")
        staged.commit()
    assert (folder / "metrics.json").read_text() == "newest" and (folder / "report.html").read_text() == "new"
    assert sorted(p.name for p in folder.iterdir()) == ["a.png", "metrics.json", "report.html", "vo.tum"]


def test_a_folder_swap_cut_by_a_kill_is_finished_by_the_next_command(tmp_path):
    from fusion_vo.outputs import OutputFolder

    target = tmp_path / "out"
    target.mkdir()
    (target / ".fusion-vo-run").write_text("written by fusion-vo\n")
    (target / "vo.tum").write_text("old")
    body = f"""
with outputs.OutputFolder(Path({str(target)!r}), ".fusion-vo-run") as folder:
    (folder.path / "vo.tum").write_text("new")
    folder.commit()
"""
    _killed_at_rename("rename", 1, body)  # the previous folder moved aside, the new one not yet in place
    assert not target.exists()
    with pytest.raises(RuntimeError):
        with OutputFolder(target, ".fusion-vo-run"):  # the next command: the swap is finished on entry
            assert (target / "vo.tum").read_text() == "new"
            raise RuntimeError("this command fails; the finished swap stays")
    assert (target / "vo.tum").read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # the hidden folders and the lock are gone


@pytest.mark.parametrize("refused_at", ["lock", "staging"])
def test_a_folder_it_may_not_write_is_a_one_line_error(recording, tmp_path, capsys, monkeypatch, refused_at):
    """The machine runs these tests as root, whom permissions do not stop; the refusal is simulated where
    the operating system would give it: creating the lock file or the hidden staging folder beside the
    target. The error names the target, never those hidden names."""
    import fusion_vo.outputs as outputs

    real_mkdir, real_open = os.mkdir, os.open

    def mkdir(path, *args, **kwargs):
        if refused_at == "staging" and Path(path).name.startswith(STAGING_PREFIX):
            raise PermissionError(13, "Permission denied", str(path))
        return real_mkdir(path, *args, **kwargs)

    def open_(path, flags, *args, **kwargs):
        if refused_at == "lock" and str(path).endswith(".lock"):
            raise PermissionError(13, "Permission denied", str(path))
        return real_open(path, flags, *args, **kwargs)

    monkeypatch.setattr(outputs.os, "mkdir", mkdir)
    monkeypatch.setattr(outputs.os, "open", open_)
    before = snapshot(tmp_path)
    status, _, err = cli(capsys, "run", recording, "--out", tmp_path / "out", *QUICK)
    assert_error(status, err, f"{tmp_path / 'out'}: Permission denied")
    assert STAGING_PREFIX not in err and ".lock" not in err and "Traceback" not in err
    assert snapshot(tmp_path) == before  # nothing made, no lock file left
