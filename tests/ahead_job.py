"""The values a test module names in ``AHEAD``, made in the session's second process (tests/background.py).

``python tests/ahead_job.py MODULE FOLDER`` imports the test module at the path MODULE and writes, for each entry
``NAME -> make`` of its ``AHEAD`` dict, ``make()``'s value pickled to ``FOLDER/NAME.pickle``. A test of that module
takes the value through the ``made_ahead`` fixture (tests/conftest.py): from the file once the job has made it, or by
calling ``make()`` itself when the session did not start the job. ``make`` takes no argument and uses fixed seeds,
so both give the same value.

A module opts in with the pair :func:`ahead_jobs` returns, as ``BACKGROUND_COMMANDS, BACKGROUND_JOBS``.
"""

from __future__ import annotations

import importlib.util
import pickle
import sys
from pathlib import Path

TESTS = Path(__file__).resolve().parent


def ahead_key(module_path: str | Path) -> str:
    """The background job key of the test module at ``module_path``: ``python:ahead_<its name>``."""
    return f"python:ahead_{Path(module_path).stem}"


def ahead_jobs(module_path: str | Path) -> tuple[dict[str, list[str]], dict[str, list[str]]]:
    """``BACKGROUND_COMMANDS, BACKGROUND_JOBS`` of a test module (``__file__``) whose every test may wait for the
    values of its ``AHEAD``."""
    key = ahead_key(module_path)
    return {key: ["{repo}/tests/ahead_job.py", str(Path(module_path).resolve()), "{out}"]}, {"*": [key]}


def load_module(module_path: Path):
    """The test module at ``module_path``, imported as pytest does (its folder and tests/ on the path)."""
    for folder in (str(module_path.parent), str(TESTS)):
        if folder not in sys.path:
            sys.path.insert(0, folder)
    spec = importlib.util.spec_from_file_location(f"ahead_{module_path.stem}", module_path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def main(module_path: Path, out: Path) -> None:
    module = load_module(module_path)
    out.mkdir(parents=True, exist_ok=True)
    for name, make in module.AHEAD.items():
        (out / f"{name}.pickle").write_bytes(pickle.dumps(make(), protocol=pickle.HIGHEST_PROTOCOL))


if __name__ == "__main__":
    # run as a script, tests/ comes first on the path, and its folders are named as the project's packages
    # (tests/frontends): the packages are imported first, from where they are installed
    sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != TESTS]
    importlib.import_module("frontends")
    importlib.import_module("fusion_vo")
    main(Path(sys.argv[1]).resolve(), Path(sys.argv[2]))
