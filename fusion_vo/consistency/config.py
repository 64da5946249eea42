"""Options of the pre-fusion consistency checks (``fusion: {consistency: {...}}``)."""

from __future__ import annotations

from pydantic import Field

from fusion_vo.config.base import Float, Fraction, NonNegative, Section, Sigma


class ConsistencyConfig(Section):
    """When the consistency checks (:mod:`fusion_vo.consistency`) call a stated configuration contradicted."""

    check: bool = Field(True, description="Run the checks before fusion (false fuses every stream as stated).")
    mounting_tolerance_deg: Float = Field(15.0, ge=0, le=90, description=(
        "The IMU's stated z axis (the body's up in the IMU frame, third row of ``imu0/sensor.yaml``'s ``T_BS``) is "
        "contradicted when an estimate from the data (gyro axes against the other yaw rates; gravity) is further "
        "from it than this [deg] (15: a gyro tilted that far measures 3.4 % less turn)."))
    mounting_agreement_deg: Float = Field(10.0, ge=0, le=90, description=(
        "The estimates from the gyro and from gravity agree when they are within this of each other [deg]; only "
        "agreeing estimates replace a contradicted mounting."))
    mounting_min_fit: Fraction = Field(0.5, description=(
        "Least fraction of the reference yaw rate's variance the gyro's best axis must explain for its estimate to "
        "count."))
    min_turn: NonNegative = Field(1.0, description=(
        "Least total turn [rad] of the drive for an estimate from yaw rates (the IMU's axis, an encoder's sign, a "
        "clock offset)."))
    scale_sigmas: Sigma = Field(5.0, description=(
        "The camera's and the wheels' distance ratio contradicts their priors when its logarithm is more than this "
        "many times the combined prior standard deviation from 0 ..."))
    scale_min_ratio: NonNegative = Field(0.1, description=(
        "... and more than this fraction from 1 (0.1: a scale error of a few percent is the backends' "
        "self-calibration's to share out)."))
    released_scale_sigma: Sigma = Field(0.3, description=(
        "Prior standard deviation (relative) given to the scale of the sensor found wrong, after its distances "
        "were corrected by the measured ratio (0.3: uninformative beside any stated prior, so that the other "
        "sensor sets the scale)."))
