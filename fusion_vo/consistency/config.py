"""Options of the pre-fusion consistency checks (``fusion: {consistency: {...}}``)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class ConsistencyConfig:
    """When the consistency checks (:mod:`fusion_vo.consistency`) call a stated configuration contradicted.

    Attributes
    ----------
    check : bool
        Run the checks before fusion (default True; false fuses every stream as stated).
    mounting_tolerance_deg : float
        The IMU's stated z axis (the body's up in the IMU frame, third row of ``imu0/sensor.yaml``'s ``T_BS``)
        is contradicted when an estimate from the data (gyro axes against the other yaw rates; gravity) is
        further from it than this [deg] (default 15: a gyro tilted that far measures 3.4 % less turn).
    mounting_agreement_deg : float
        The estimates from the gyro and from gravity agree when they are within this of each other [deg]
        (default 10); only agreeing estimates replace a contradicted mounting.
    mounting_min_fit : float
        Least fraction of the reference yaw rate's variance the gyro's best axis must explain for its
        estimate to count (default 0.5).
    min_turn : float
        Least total turn [rad] of the drive for an estimate from yaw rates (the IMU's axis, an encoder's
        sign, a clock offset; default 1.0).
    scale_sigmas : float
        The camera's and the wheels' distance ratio contradicts their priors when its logarithm is more than
        this many times the combined prior standard deviation from 0 (default 5) ...
    scale_min_ratio : float
        ... and more than this fraction from 1 (default 0.1: a scale error of a few percent is the backends'
        self-calibration's to share out).
    released_scale_sigma : float
        Prior standard deviation (relative) given to the scale of the sensor found wrong, after its
        distances were corrected by the measured ratio (default 0.3: uninformative beside any stated prior,
        so that the other sensor sets the scale).
    """

    check: bool = True
    mounting_tolerance_deg: float = 15.0
    mounting_agreement_deg: float = 10.0
    mounting_min_fit: float = 0.5
    min_turn: float = 1.0
    scale_sigmas: float = 5.0
    scale_min_ratio: float = 0.1
    released_scale_sigma: float = 0.3
