"""Every test carries the marker of its layer, from the folder it lives in (``pytest -m unit`` runs the first).

unit         one module or class on small inputs made in the test: frontends, geometry, sensors (the
             measurement models), configuration, recording reader, evaluation metrics
integration  several stages together on a generated drive or a real bag: backends, consistency checks,
             calibration, simulation, export
end_to_end   the commands and scripts as a user runs them: end_to_end, faults, batch, ros2, examples,
             benchmarks, ecosystem (install, licences, documentation)
"""

from __future__ import annotations

import json
import pickle
from pathlib import Path

import pytest
import job_runner
from ahead_job import ahead_key
from background import BackgroundJobs, jobs_of, placed

from fusion_vo.cli.main import main
from fusion_vo.simulation.standard import make_standard

LAYERS = {
    "unit": ("frontends", "geometry", "sensors", "config", "recording", "evaluation"),
    "integration": ("backends", "consistency", "calibration", "simulation", "export"),
    "end_to_end": ("end_to_end", "faults", "batch", "ros2", "examples", "benchmarks", "ecosystem"),
}
FOLDER_LAYER = {folder: layer for layer, folders in LAYERS.items() for folder in folders}
TESTS = Path(__file__).resolve().parent
ROBOT_LOGS = TESTS / "data" / "robot_localization"
#: base_link -> imu_link of robot_localization's test_ekf_localization_node_bag1.test (the Husky's IMU lies on its side)
HUSKY_IMU_TF = "0 -0.3 0.52 -1.570796327 0 1.570796327 base_link imu_link"


#: folders run first, in this order: the DDS tests, which wait for a node most of their time, while the session's
#: second process runs the other tests' jobs at the lowest priority beside them (tests/ros2/conftest.py)
FIRST = ("ros2",)


def pytest_collection_modifyitems(config, items) -> None:
    """Mark each test with its folder's layer (a test folder that no layer names is an error) and order them: the
    folders of :data:`FIRST` first, then the modules that do not wait for the second process's work
    (``BACKGROUND_JOBS``, tests/background.py) before those that do, so that it has their time to get ahead."""
    folders = {}
    for item in items:
        folder = folders[item.nodeid] = Path(item.fspath).resolve().relative_to(TESTS).parts[0]
        if folder not in FOLDER_LAYER:
            raise pytest.UsageError(f"tests/{folder}: no layer in tests/conftest.py's LAYERS names this folder")
        item.add_marker(getattr(pytest.mark, FOLDER_LAYER[folder]))

    def place(item) -> tuple[int, bool]:
        folder = folders[item.nodeid]
        return FIRST.index(folder) if folder in FIRST else len(FIRST), bool(getattr(item.module, "BACKGROUND_JOBS", None))

    items.sort(key=place)


_background: BackgroundJobs | None = None


def pytest_sessionstart(session) -> None:
    """Start the server the background jobs are forked from (tests/job_runner.py): it imports the heavy libraries
    on the second core while this process collects the tests."""
    if not session.config.option.collectonly:
        job_runner.start_server()


def pytest_collection_finish(session) -> None:
    """Start the work the collected tests name in their modules' ``BACKGROUND_JOBS`` (tests/background.py)."""
    global _background
    keys, commands = jobs_of(session.items)
    if keys and not session.config.option.collectonly:
        _background = BackgroundJobs(keys, {**SHARED_COMMANDS, **commands})


def pytest_sessionfinish(session) -> None:
    if _background is not None:
        _background.stop()


@pytest.fixture(scope="session")
def background() -> BackgroundJobs | None:
    """The jobs started in the background for this session (None: the collected tests name none)."""
    return _background


# ------------------------------------------------------------------ inputs made once per session, shared by folders
# Each is made the first time a test asks for it and never modified afterwards: a test that breaks one copies it.


@pytest.fixture(scope="session")
def standard_recording(tmp_path_factory, ahead):
    """``standard_recording(name)`` -> path of that standard generated recording (never modify it): made by the
    background job ``standard:NAME`` when a collected test names it, else here."""
    made = {}

    def get(name):
        if name not in made:
            made[name] = ahead(f"standard:{name}", lambda: make_standard(name, tmp_path_factory.mktemp("rec") / name))
        return made[name]

    return get


@pytest.fixture(scope="session")
def ahead(background):
    """``ahead(key, make)`` -> the output folder of the background job ``key`` if the session started it (waiting
    for it), else ``make()``, the same work done here."""

    def get(key: str, make) -> Path:
        if background is not None and key in background:
            return background.result(key).out
        return make()

    return get


@pytest.fixture(scope="session")
def ahead_json(background):
    """``ahead_json(key, make)`` -> the JSON object the ``python:`` job ``key`` printed last if the session started
    it (waiting for it), else ``make()``, the same figures computed here."""

    def get(key: str, make) -> dict:
        if background is not None and key in background:
            return json.loads(background.result(key).stdout.strip().splitlines()[-1])
        return make()

    return get


@pytest.fixture
def made_ahead(request, background):
    """``made_ahead(name)`` -> the value of ``AHEAD[name]()`` of the test's module: made by the module's background
    job (tests/ahead_job.py) if the session started it (waiting for it), else computed here."""
    module = request.module
    key = ahead_key(module.__file__)

    def get(name: str):
        if background is not None and key in background:
            return pickle.loads((background.result(key).out / f"{name}.pickle").read_bytes())
        return module.AHEAD[name]()

    return get


#: robot_localization's bags imported as a user would (``fusion-vo import-bag``), as background jobs
#: ``fusion-vo:jackal_log`` and ``fusion-vo:husky_log`` (tests/background.py) or in the fixtures below
JACKAL_IMPORT = ["-q", "import-bag", "{data}/robot_localization/test2.bag", "{out}", "--imu-topic", "/imu/data",
                 "--odom-topic", "/jackal_velocity_controller/odom"]
HUSKY_IMPORT = ["-q", "import-bag", "{data}/robot_localization/test1.bag", "{out}", "--static-tf", HUSKY_IMU_TF]
SHARED_COMMANDS = {"fusion-vo:jackal_log": JACKAL_IMPORT, "fusion-vo:husky_log": HUSKY_IMPORT}


def _cli_here(args: list[str], out: Path) -> Path:
    """``fusion-vo ARGS`` run in this process with ``{out}`` and ``{data}`` in place; returns ``out``."""
    places = {"out": str(out), "data": str(TESTS / "data")}
    assert main([placed(arg, places) for arg in args]) == 0
    return out


@pytest.fixture(scope="session")
def jackal_log(ahead, tmp_path_factory) -> Path:
    """robot_localization's test2.bag (Jackal) imported with its IMU and wheel odometry topics into a folder named
    ``jackal_log`` (never modify it)."""
    return ahead("fusion-vo:jackal_log",
                 lambda: _cli_here(JACKAL_IMPORT, tmp_path_factory.mktemp("jackal") / "jackal_log"))


@pytest.fixture(scope="session")
def husky_log(ahead, tmp_path_factory) -> Path:
    """robot_localization's test1.bag (Husky, 395 s) imported with its launch file's IMU transform (never modify
    it)."""
    return ahead("fusion-vo:husky_log", lambda: _cli_here(HUSKY_IMPORT, tmp_path_factory.mktemp("husky") / "husky_log"))
