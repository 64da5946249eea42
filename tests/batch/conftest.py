"""Small generated recordings and a local Dask cluster of 2 worker processes, shared by the batch tests."""

import logging
import os
import shutil

import pytest

pytest.importorskip("distributed", reason="the batch extra (dask[distributed]) is not installed")

from small_recordings import SEEDS, small_recording  # noqa: E402

_ENVIRONMENT_BEFORE = dict(os.environ)  # before any cluster of the session started


@pytest.fixture(scope="session")
def recordings(tmp_path_factory):
    """Three good recordings and one whose IMU file has a NaN (``broken``)."""
    root = tmp_path_factory.mktemp("recordings")
    good = [small_recording(root / f"drive{seed}", seed) for seed in SEEDS]
    broken = root / "broken"
    shutil.copytree(good[0], broken)
    lines = (broken / "imu0" / "data.csv").read_text().splitlines()
    lines[20] = lines[20].split(",")[0] + ",nan,0,0,0,0,9.8"
    (broken / "imu0" / "data.csv").write_text("\n".join(lines) + "\n")
    return good, broken


@pytest.fixture(scope="session")
def environment_before() -> dict[str, str]:
    """This process's environment as it was before any cluster of the session started."""
    return _ENVIRONMENT_BEFORE


@pytest.fixture(scope="session")
def client():
    """The LocalCluster a batch starts (:func:`fusion_vo.batch.cluster.open_client`), with 2 workers."""
    from fusion_vo.batch.cluster import open_client

    handlers = logging.getLogger("distributed").handlers
    levels = {handler: handler.level for handler in handlers}
    with open_client(workers=2, dashboard=False) as c:
        # Dask's LocalCluster lowers every stream handler of the "distributed" logger to ERROR while it runs, and
        # under pytest those are pytest's own capture handlers too: left so for the rest of the session, every later
        # test's caplog would miss its warnings. The levels come back here; Dask sets the same ones when it closes.
        for handler, level in levels.items():
            handler.setLevel(level)
        yield c
