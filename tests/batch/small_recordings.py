"""The small generated recordings the batch tests run (tests/batch/conftest.py's ``recordings``)."""

from fusion_vo.simulation import simulate

#: 4 s random drives on 320 x 180 frames (seeds whose robot moves)
SEEDS = (3, 4, 6)


def small_recording(path, seed):
    """The 4 s random drive of ``seed`` at ``path``."""
    return simulate(path, profile="random", seed=seed, duration=4.0, width=320, height=180, cu=160.0, cv=90.0)
