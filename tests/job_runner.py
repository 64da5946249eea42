"""Run a background job's command line in a process forked from one that has imported the heavy libraries.

Each job of tests/background.py is a command line, ``python -c CODE ARGS``, ``python -m MODULE ARGS`` or ``python
SCRIPT ARGS``. Started as a new interpreter, each job spends about 2 s of CPU importing NumPy, SciPy, OpenCV, GTSAM,
Matplotlib, filterpy and the library (evo, pandas, Dask and rosbags too, for some) before its own work.
tests/background.py instead forks it from a server process (multiprocessing's ``forkserver``, :func:`context`) that
imported them once (:data:`PRELOAD`); :func:`run_command` then runs the command line as the
interpreter would: ``sys.argv`` and the interpreter's own ``sys.path`` (without the test session's folders), the
working folder, the standard output and error into files, ``__main__`` as the module's name, the exit status from
``SystemExit``. The modules it imports are the installed ones, as in a new interpreter.

A job that needs an interpreter of its own (one that blocks an import, for instance) starts its own subprocess, as
``tests/ecosystem/without_evo_job.py`` does.
"""

from __future__ import annotations

import json
import multiprocessing
import multiprocessing.forkserver
import os
import runpy
import subprocess
import sys
from pathlib import Path

#: imported once by the server process; a forked job finds them imported
PRELOAD = ["numpy", "scipy.linalg", "scipy.optimize", "scipy.stats", "cv2", "gtsam", "matplotlib", "PIL.Image",
           "filterpy.kalman", "pydantic", "yaml", "fusion_vo.cli.main", "fusion_vo.pipeline",
           "fusion_vo.backends.streaming", "fusion_vo.evaluation.run_report", "fusion_vo.evaluation.evaluate",
           "fusion_vo.simulation.standard", "rosbags.highlevel", "rosbags.typesys", "pandas", "distributed"]


def interpreter_path() -> list[str]:
    """A new interpreter's ``sys.path`` after its first entry (the script's folder, or the working one)."""
    return json.loads(subprocess.check_output([sys.executable, "-c", "import json, sys; print(json.dumps(sys.path[1:]))"],
                                              text=True))


def context():
    """The forkserver context whose server imports :data:`PRELOAD` (None where there is no forkserver)."""
    if "forkserver" not in multiprocessing.get_all_start_methods():
        return None
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload([__name__, *PRELOAD])
    return ctx


def start_server() -> None:
    """Start the server process now (else the first job starts it), where there is one."""
    if context() is not None:
        multiprocessing.forkserver.ensure_running()


def run_command(argv: list[str], cwd: str, stdout: str, stderr: str, niceness: int,
                interpreter_path: list[str]) -> None:
    """Run ``python ARGV`` (``argv`` without the interpreter) in this process, as a new interpreter would, with
    ``niceness``, in ``cwd``, writing its standard output and error to the files ``stdout`` and ``stderr``."""
    os.setpriority(os.PRIO_PROCESS, 0, niceness)
    for fd, path in ((1, stdout), (2, stderr)):
        file = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.dup2(file, fd)
        os.close(file)
    os.chdir(cwd)
    first, rest = argv[0], argv[1:]
    if first == "-c":
        sys.argv = ["-c", *rest[1:]]
        sys.path[:] = ["", *interpreter_path]
        code = compile(rest[0], "<string>", "exec")
        exec(code, {"__name__": "__main__", "__builtins__": __builtins__})  # noqa: S102 -- the job's own code
    elif first == "-m":
        sys.argv = [rest[0], *rest[1:]]
        sys.path[:] = [cwd, *interpreter_path]
        sys.modules.pop(rest[0], None)  # (preloaded: run afresh as __main__, as a new interpreter does)
        runpy.run_module(rest[0], run_name="__main__", alter_sys=True)
    else:
        sys.argv = argv
        sys.path[:] = [str(Path(first).resolve().parent), *interpreter_path]
        runpy.run_path(first, run_name="__main__")
