"""The base of every configuration section and the ranges they share.

A section is a :class:`Section`, the frontends' :class:`frontends.config.Settings`: a frozen pydantic model that
rejects unknown keys, non-finite numbers and ``true``/``false`` where a number belongs, and checks its defaults.
Each option is one field with its default, range, unit and description::

    class EkfConfig(Section):
        accel_sigma: Sigma = Field(0.5, description="Forward acceleration noise [m/s²·√s].")

``EkfConfig(accel_sigma=0)`` and ``EkfConfig.from_dict({"accel_sigma": 0})`` raise :class:`ConfigError` (a
``ValueError``) in one line naming the key: ``EkfConfig: accel_sigma must be positive, not 0``. Read from a file
(:func:`fusion_vo.config.files.validate`), the same error names the file and the key path instead.

The ranges below are those most options need. Every number has an upper end: a standard deviation, a noise
density or a random walk at most :data:`MAX_SIGMA` (its square is a variance: ``1e300`` overflowed), any other
number at most :data:`MAX_NUMBER` unless its field states a tighter bound (the options that set how much work
a run does: node rates, iterations, windows).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Annotated, Any, Self

from pydantic import Field, model_validator

from frontends.config import INTEGER, NUMBER, ConfigError, Float, Int, Settings

__all__ = ["INTEGER", "MAX_SIGMA", "MAX_NUMBER", "NUMBER", "ConfigError", "Count", "Float", "Fraction", "Int",
           "NonNegative", "Positive", "Section", "Sigma", "Walk", "merge"]

#: the largest standard deviation, noise density or random walk an option may state
MAX_SIGMA = 1e3
#: the largest value of any other number without a tighter bound, in whatever unit it has (m, s, Hz, a factor,
#: a count): beyond it a value is a typo, not a setting
MAX_NUMBER = 1e6

#: a standard deviation: positive (a zero one claims a perfect sensor), at most :data:`MAX_SIGMA`
Sigma = Annotated[float, Field(gt=0, le=MAX_SIGMA), NUMBER]
#: a noise density or random walk that may be 0 (none), at most :data:`MAX_SIGMA`
Walk = Annotated[float, Field(ge=0, le=MAX_SIGMA), NUMBER]
#: a positive number, at most :data:`MAX_NUMBER`
Positive = Annotated[float, Field(gt=0, le=MAX_NUMBER), NUMBER]
#: a number that may be 0, at most :data:`MAX_NUMBER`
NonNegative = Annotated[float, Field(ge=0, le=MAX_NUMBER), NUMBER]
#: a fraction in [0, 1]
Fraction = Annotated[float, Field(ge=0, le=1), NUMBER]
#: a count of at least 1, at most :data:`MAX_NUMBER`
Count = Annotated[int, Field(ge=1, le=int(MAX_NUMBER)), INTEGER]


class Section(Settings):
    """Base of fusion_vo's configuration sections (module docstring).

    Besides what :class:`~frontends.config.Settings` gives (``Model(**values)``, :meth:`from_dict`,
    :meth:`to_dict`, immutability), :meth:`merged` makes a checked copy with some values changed. A section
    whose default differs from its class's (``FusionConfig.odom``, a ``WheelNoise`` with an odometry twist's
    defaults) given in part keeps the field's defaults for the keys left out, not the class's.
    """

    @model_validator(mode="before")
    @classmethod
    def _partial_sections(cls, data: Any) -> Any:
        if not isinstance(data, Mapping):
            return data
        for name, default in _own_defaults(cls).items():
            value = data.get(name)
            if isinstance(value, Mapping):
                data = {**data, name: {**default, **value}}
        return data

    def merged(self, changes: Mapping[str, Any]) -> Self:
        """A copy with ``changes`` applied and checked like any value: a nested mapping changes only the keys
        it names of a section (``{"ekf": {"accel_sigma": 2}}`` keeps the section's other values).

        Raises
        ------
        ConfigError
            For an unknown key or a value that cannot work, naming its key path.
        """
        return type(self).from_dict(merge(self.model_dump(), changes))


_OWN_DEFAULTS: dict[type, dict[str, dict]] = {}


def _own_defaults(cls: type[Section]) -> dict[str, dict]:
    """The values of the sections of ``cls`` whose default differs from their class's, by field name."""
    if cls not in _OWN_DEFAULTS:
        out = {}
        for name, field in cls.model_fields.items():
            sub = field.annotation
            if field.default_factory is None or not (isinstance(sub, type) and issubclass(sub, Settings)):
                continue
            default = field.default_factory()
            if isinstance(default, sub) and default != sub():
                out[name] = default.model_dump()
        _OWN_DEFAULTS[cls] = out
    return _OWN_DEFAULTS[cls]


def merge(base: Mapping[str, Any], changes: Mapping[str, Any]) -> dict[str, Any]:
    """``base`` with ``changes`` applied; where both hold a mapping under one key, merged key by key."""
    out = dict(base)
    for key, value in changes.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = merge(out[key], value)
        else:
            out[key] = value
    return out
