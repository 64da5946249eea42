"""Deterministic work made ahead in a second process while the suite runs (tests/conftest.py starts it).

A test module may name, in ``BACKGROUND_JOBS`` (test name, or ``*`` for every test of the module -> job keys), the
work its tests will wait for:

``standard:NAME``  the standard generated recording NAME, made by :func:`fusion_vo.simulation.standard.make_standard`
                   (the function the ``standard_recording`` fixture calls in-process otherwise)
``example:NAME``   ``python examples/NAME.py --quick --seed 1 --out DIR``, the example script as a user runs it
``fusion-vo:LABEL`` the command ``fusion-vo ARGS...`` of the module's ``BACKGROUND_COMMANDS[LABEL]`` (its output
                   folder is named as LABEL's last part: ``a/out`` writes a folder ``out``), in which an
                   argument starting ``{out}`` is this job's output folder, ``{data}`` the folder tests/data, ``{KEY}`` the
                   output of the job KEY (named before it in the same test's list, so it runs first)
``python:LABEL``   ``python ARGS...`` of the module's ``BACKGROUND_COMMANDS["python:LABEL"]``, placed likewise
                   (``{repo}``: the repository; a script of the repository run as a user runs it)

Once the session has collected its tests, one thread runs the jobs those tests name, one subprocess at a time, in
the order the tests come. A test that needs a job's result runs it itself when the thread has not started it yet
(after the jobs it reads), and while it waits for the thread to finish it, runs the next jobs the thread has not
started: the test would only wait, so the second core stays busy. The jobs use fixed seeds, so making them early
changes none of their numbers: only when they run. The suite's other work goes on in this process, so on two cores
both are busy. A job that fails is reported by the test that waits for it, with its standard error.

Each job is forked from a server process that has imported the heavy libraries once (tests/job_runner.py), and
runs its command line there as a new interpreter would: about 2 s of CPU less per job than a new interpreter.

Every job runs at a lower priority than the suite (``nice -n 5``). The DDS tests (``tests/ros2``, whose timing a
busy machine can upset) run first (tests/conftest.py), each node inside :meth:`BackgroundJobs.lowest`: meanwhile the
jobs run at the lowest priority (``nice -n 19``; on Linux the running one is lowered too), so they take only the time
the node leaves. The tests that run beside a job and measure time hold lower bounds (the replay's pace) or bounds of
10 s on work of about 5 s (the batch commands' refusals), which a second busy core does not reach.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import threading
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import job_runner

REPO = Path(__file__).resolve().parents[1]
#: seconds one job may take (the longest, the 60 s drive random60 or the thesis_square example, takes 10-15 s of
#: CPU on an idle core)
TIMEOUT_S = 300.0

#: the jobs run 5 steps nicer than the suite: on an idle core at full speed, on a busy machine the tests come first
NICE = 5
#: within :meth:`BackgroundJobs.lowest`: the lowest priority there is
LOWEST = 19
HAS_NICE = shutil.which("nice") is not None


def renice(pid: int, niceness: int) -> None:
    """Give every thread of process ``pid`` and of its descendants ``niceness`` where allowed (Linux's /proc;
    elsewhere, for a process that has ended meanwhile and for a raise the user may not make, nothing)."""
    pids = [pid]
    while pids:
        for task in Path(f"/proc/{pids.pop()}/task").glob("*"):
            try:
                os.setpriority(os.PRIO_PROCESS, int(task.name), niceness)
                pids += [int(child) for child in (task / "children").read_text().split()]
            except (OSError, ValueError):
                continue


_MAKE_STANDARD = "import sys\nfrom fusion_vo.simulation.standard import make_standard\nmake_standard(sys.argv[1], sys.argv[2])"


@dataclass
class Job:
    """One job: its command line and output folder; once ``done`` is set, its exit status and output."""

    key: str
    argv: list[str]
    out: Path
    needs: list[str] = field(default_factory=list)  # the jobs whose output it reads
    taken: bool = False  # started (or skipped) by the thread or by a test waiting for it
    done: threading.Event = field(default_factory=threading.Event)
    returncode: int | None = None
    stdout: str = ""
    stderr: str = ""


def command(key: str, out: Path, commands: dict[str, list[str]], outs: dict[str, Path]) -> list[str]:
    """The command line of job ``key`` writing into ``out`` (``commands``: the ``fusion-vo:`` jobs' arguments,
    ``outs``: the output folders of the jobs before it)."""
    kind, _, name = key.partition(":")
    if kind == "standard":
        return [sys.executable, "-c", _MAKE_STANDARD, name, str(out)]
    if kind == "example":
        return [sys.executable, str(REPO / "examples" / f"{name}.py"), "--quick", "--seed", "1", "--out", str(out)]
    if kind in ("fusion-vo", "python"):
        places = {"out": str(out), "data": str(REPO / "tests" / "data"), "repo": str(REPO),
                  **{k: str(v) for k, v in outs.items()}}
        return [sys.executable, *(["-m", "fusion_vo.cli.main"] if kind == "fusion-vo" else []),
                *(placed(arg, places) for arg in commands[key])]
    raise ValueError(f"unknown background job {key!r} (standard:NAME, example:NAME, fusion-vo:LABEL or python:LABEL)")


def placeholder(arg: str) -> str | None:
    """The NAME of ``arg``'s leading ``{NAME}`` (None: it has none)."""
    return arg[1:].partition("}")[0] if arg.startswith("{") else None


def placed(arg: str, places: dict[str, str]) -> str:
    """``arg`` with a leading ``{NAME}`` replaced by ``places[NAME]`` (``{data}/x.bag`` -> ``.../tests/data/x.bag``)."""
    name = placeholder(arg)
    return arg if name is None else places[name] + arg[len(name) + 2:]


class JobProcess:
    """A started job: a subprocess or a process forked by the server (tests/job_runner.py), and the files its
    standard output and error go to."""

    def __init__(self, process, files: dict[str, Path]):
        self.process, self.files = process, files

    @property
    def pid(self) -> int:
        return self.process.pid

    def wait(self, timeout: float | None = None) -> int:
        """The exit status (raises ``subprocess.TimeoutExpired`` after ``timeout`` seconds)."""
        if isinstance(self.process, subprocess.Popen):
            return self.process.wait(timeout)
        self.process.join(timeout)
        if self.process.exitcode is None:
            raise subprocess.TimeoutExpired(self.process.name, timeout)
        return self.process.exitcode

    def kill(self) -> None:
        """End it if it still runs."""
        try:
            self.process.kill()
        except (OSError, ValueError):  # (ended, or its handle closed)
            pass

    def output(self, name: str) -> str:
        """What it wrote to its standard ``name`` ("stdout" or "stderr")."""
        return self.files[name].read_text(errors="replace")


class BackgroundJobs:
    """Runs the jobs ``keys`` one after another in a thread, each in a process of its own (:meth:`_start`)."""

    def __init__(self, keys: list[str], commands: dict[str, list[str]]):
        self.root = Path(tempfile.mkdtemp(prefix="fusion-vo-tests-"))
        self.jobs = {}
        for i, key in enumerate(keys):
            out = self.root / f"{i:02d}_{key.replace(':', '_').replace('/', '_')}" / Path(key.partition(":")[2]).name
            argv = command(key, out, commands, {k: j.out for k, j in self.jobs.items()})
            needs = [name for arg in commands.get(key, []) if (name := placeholder(arg)) in self.jobs]
            self.jobs[key] = Job(key, argv, out, needs)
        self.stopped = False
        self.processes: set[JobProcess] = set()
        self._forks = job_runner.context()
        self._path = job_runner.interpreter_path() if self._forks is not None else []
        self._lock = threading.Lock()  # guards taking a job, starting a process, stopping, lowest()
        self._held = 0  # lowest() callers: while one holds it, the jobs run at the lowest priority
        self.thread = threading.Thread(target=self._run_all, name="tests-background", daemon=True)
        self.thread.start()

    @contextmanager
    def lowest(self):
        """Within this block the jobs run at the lowest priority: the running ones are lowered (every thread of
        the job and of its children, on Linux; elsewhere they go on as they are) and the next ones start at it.
        After it the running ones are raised back where the user may do so."""
        with self._lock:
            self._held += 1
            for process in self.processes:
                renice(process.pid, LOWEST)
        try:
            yield
        finally:
            with self._lock:
                self._held -= 1
                for process in self.processes if not self._held else ():
                    renice(process.pid, NICE)

    def _take(self, job: Job) -> bool:
        """Mark ``job`` started, unless it was taken already (False)."""
        with self._lock:
            if job.taken:
                return False
            job.taken = True
            return True

    def _next(self) -> Job | None:
        """The first job not yet taken whose inputs are made (None: none)."""
        return next((job for job in self.jobs.values()
                     if not job.taken and all(self.jobs[k].done.is_set() for k in job.needs)), None)

    def _run_all(self) -> None:
        for job in self.jobs.values():
            for key in job.needs:  # (started by a test that waits for it: the thread waits for it too)
                self.jobs[key].done.wait()
            if self._take(job):
                self._run(job)

    def _run(self, job: Job) -> None:
        """Run the taken ``job`` in this thread and announce its end."""
        try:
            job.out.parent.mkdir(parents=True, exist_ok=True)
            with self._lock:  # started and registered in one step, so that stop() kills it or it is never started
                if self.stopped:
                    job.stderr = "not run: the session ended first"
                    return
                process = self._start(job, LOWEST if self._held else NICE)
                self.processes.add(process)
            try:
                job.returncode = process.wait(TIMEOUT_S)
            except subprocess.TimeoutExpired:
                process.kill()
                job.returncode = process.wait()
                job.stderr += f"\n(killed after {TIMEOUT_S:.0f} s)"
            finally:
                self.processes.discard(process)
                job.stdout = process.output("stdout") + job.stdout
                job.stderr = process.output("stderr") + job.stderr
        except Exception as exc:  # noqa: BLE001 -- reported by the test that waits for this job
            job.stderr = f"could not run {job.key}: {exc!r}"
        finally:
            job.done.set()

    def _start(self, job: Job, niceness: int) -> JobProcess:
        """Start ``job`` at ``niceness``: forked from the server with the heavy libraries imported
        (tests/job_runner.py), or where there is none, as a new interpreter."""
        files = {name: job.out.parent / f"{name}.txt" for name in ("stdout", "stderr")}
        if self._forks is None:
            with open(files["stdout"], "w") as out, open(files["stderr"], "w") as err:
                nice = ["nice", "-n", str(niceness)] if HAS_NICE else []
                return JobProcess(subprocess.Popen(nice + job.argv, stdout=out, stderr=err, cwd=REPO), files)
        process = self._forks.Process(target=job_runner.run_command, name=job.key,
                                      args=(job.argv[1:], str(REPO), str(files["stdout"]), str(files["stderr"]),
                                            niceness, self._path))
        process.start()
        return JobProcess(process, files)

    def __contains__(self, key: str) -> bool:
        return key in self.jobs

    def result(self, key: str) -> Job:
        """Wait for job ``key`` and return it, after checking that it exited with status 0; a job the thread has not
        started yet is run here, after the jobs it reads, and while the thread runs it, the jobs after it are (the
        caller would only wait)."""
        job = self.jobs[key]
        for need in job.needs:
            if not self.jobs[need].done.is_set():
                self.result(need)
        if self._take(job):
            self._run(job)
        while not job.done.is_set():  # the thread runs it: meanwhile run the next jobs here
            following = self._next()
            if following is None:
                break
            if self._take(following):
                self._run(following)
        assert job.done.wait(TIMEOUT_S * len(self.jobs) + 60.0), f"{key} did not finish"
        assert job.returncode == 0, f"{key} failed:\n{job.stderr[-3000:]}"
        return job

    def stop(self) -> None:
        """End the running jobs (if any), skip the rest and remove every output."""
        with self._lock:
            self.stopped = True
            running = list(self.processes)
        for process in running:
            process.kill()
        self.thread.join(timeout=30.0)
        shutil.rmtree(self.root, ignore_errors=True)


def jobs_of(items) -> tuple[list[str], dict[str, list[str]]]:
    """The job keys the collected test ``items`` name, in the order of their first test, and the arguments of
    their ``fusion-vo:`` jobs."""
    keys, commands = [], {}
    for item in items:
        module = getattr(item, "module", None)
        named = getattr(module, "BACKGROUND_JOBS", {})
        keys += named.get(item.originalname, named.get("*", []))
        for label, args in getattr(module, "BACKGROUND_COMMANDS", {}).items():
            commands[label if label.startswith("python:") else f"fusion-vo:{label}"] = args
    return list(dict.fromkeys(keys)), commands
