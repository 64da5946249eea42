"""Generated recordings: a differential-drive robot with a downward camera over a photographed floor.

:func:`simulate` writes a complete recording (camera frames, wheel encoders, IMU, optional range finder
and odometry, ground truth) in the layout of ``datasets/README.md``; :mod:`.standard` names the set of
recordings the tests, examples and benchmarks use (``datasets/generated.md``).
"""

from fusion_vo.simulation.generate import SimulationOptions, simulate
from fusion_vo.simulation.robot import PROFILES

__all__ = ["PROFILES", "SimulationOptions", "simulate"]
