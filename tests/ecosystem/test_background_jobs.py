"""The suite's background queue (tests/background.py): a test that needs a job the queue has not started runs it
itself, after the jobs it reads, instead of waiting behind the queue; a job forked from the server that imported the
heavy libraries runs as a new interpreter would."""

import json
import pickle
import subprocess
import sys
import time

import pytest

from background import REPO, BackgroundJobs

SLOW = ["-c", "import time; time.sleep(30)"]
WRITE = ["-c", "import pathlib, sys; p = pathlib.Path(sys.argv[1]); p.mkdir(parents=True); (p / 'v').write_text('7')",
         "{out}"]
READ = ["-c", "import pathlib, sys; print(pathlib.Path(sys.argv[1], 'v').read_text())", "{python:write}"]


def test_a_job_not_started_is_run_by_the_test_that_waits_for_it_after_the_jobs_it_reads():
    jobs = BackgroundJobs(["python:slow", "python:write", "python:read"],
                          {"python:slow": SLOW, "python:write": WRITE, "python:read": READ})
    try:
        start = time.monotonic()
        assert jobs.result("python:read").stdout.strip() == "7"  # 'write' ran first: 'read' found its file
        assert time.monotonic() - start < 15.0  # not behind the 30 s job the queue runs
        assert not jobs.jobs["python:slow"].done.is_set()
        assert jobs.jobs["python:write"].done.is_set()
    finally:
        jobs.stop()
    assert not jobs.root.exists()


def test_while_the_queue_runs_the_job_a_test_waits_for_the_test_runs_the_next():
    stamp = ["-c", "import sys, time; time.sleep(float(sys.argv[1])); print(time.time())"]
    jobs = BackgroundJobs(["python:slow", "python:next"], {"python:slow": stamp + ["4"], "python:next": stamp + ["0"]})
    try:
        while not jobs.jobs["python:slow"].taken:  # the queue's thread has started it
            time.sleep(0.01)
        slow_end = float(jobs.result("python:slow").stdout)
        assert jobs.jobs["python:next"].done.is_set()
        assert float(jobs.result("python:next").stdout) < slow_end  # made while the test waited, not after
    finally:
        jobs.stop()


def test_a_module_made_ahead_imports_the_project_not_the_test_folders_named_as_it(tmp_path):
    """``tests/ahead_job.py`` run as a script has tests/ first on its path, where ``tests/frontends`` is a folder
    named as the ``frontends`` package: the values of ``AHEAD`` must see the package (a replay imports it)."""
    module = tmp_path / "test_probe.py"
    module.write_text("import importlib\n"
                      "AHEAD = {'where': lambda: importlib.import_module('frontends').make_frontend.__module__}\n")
    done = subprocess.run([sys.executable, str(REPO / "tests" / "ahead_job.py"), str(module), str(tmp_path / "out")],
                          cwd=REPO, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert pickle.loads((tmp_path / "out" / "where.pickle").read_bytes()).startswith("frontends")


def test_a_forked_job_runs_as_a_new_interpreter_would():
    """A job forked from the server (tests/job_runner.py) sees a new interpreter's ``sys.argv``, ``__name__``,
    working folder and ``sys.path`` (no folder of the test session on it), and its exit status and standard error
    come back to the test."""
    probe = ["-c", "import json, os, sys; print(json.dumps([sys.argv, __name__, os.getcwd(), sys.path]));"
                   "print('said', file=sys.stderr); sys.exit(int(sys.argv[1]))"]
    fresh = json.loads(subprocess.check_output([sys.executable, *probe, "0"], cwd=REPO, text=True))
    jobs = BackgroundJobs(["python:ok", "python:fails"], {"python:ok": probe + ["0"], "python:fails": probe + ["3"]})
    try:
        ok = jobs.result("python:ok")
        assert json.loads(ok.stdout) == fresh
        assert str(REPO / "tests") not in fresh[3]
        assert ok.stderr == "said\n"
        with pytest.raises(AssertionError, match="python:fails failed:\nsaid"):
            jobs.result("python:fails")
        assert jobs.jobs["python:fails"].returncode == 3
    finally:
        jobs.stop()
