"""Shared helpers for configuration dataclasses: ``from_dict``/``to_dict`` and the ranges of number fields."""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, TypeVar

T = TypeVar("T", bound="ConfigMixin")


class ConfigMixin:
    """Adds :meth:`from_dict` and :meth:`to_dict` to a configuration dataclass."""

    @classmethod
    def from_dict(cls: type[T], values: dict[str, Any] | None) -> T:
        """Build the configuration from a plain mapping (e.g. a YAML section) through the package's one
        configuration schema (:func:`fusion_vo.schema.build`), which also serves ``fusion-vo run``.

        Raises
        ------
        ValueError
            For a key that is not a field, a value of the wrong type (the message names the key and the
            expected type) or a value the configuration rejects.
        """
        from fusion_vo import schema  # the frontends themselves need nothing else of fusion_vo
        from fusion_vo.errors import InputError

        try:
            return schema.build(cls, values or {})
        except InputError as exc:
            raise ValueError(f"{cls.__name__}: {exc.message}") from None

    def to_dict(self) -> dict[str, Any]:
        """The configuration as a plain mapping (round-trips through :meth:`from_dict`)."""
        return dataclasses.asdict(self)  # type: ignore[call-overload]


@dataclass(frozen=True)
class Range:
    """The values a number field can take: from ``low`` to ``high`` (either end open or left out).

    A configuration dataclass lists its fields' ranges in a class-level table (``RANGES``, field name ->
    :class:`Range`) that its ``__post_init__`` checks with :func:`check_ranges`, so that a value that
    cannot work is an error naming the key rather than a silently wrong result.

    Attributes
    ----------
    low, high : float or None
        Smallest and largest value (``None``: no bound).
    open_low, open_high : bool
        Whether ``low`` (``high``) itself is excluded.
    """

    low: float | None = None
    high: float | None = None
    open_low: bool = False
    open_high: bool = False

    def contains(self, value: float) -> bool:
        """Whether ``value`` (a finite number) lies in the range."""
        if self.low is not None and (value <= self.low if self.open_low else value < self.low):
            return False
        return self.high is None or (value < self.high if self.open_high else value <= self.high)

    def describe(self) -> str:
        """The range in words: ``at least 1``, ``positive``, ``in [0, 1]`` ..."""
        if self.high is None:
            if self.low is None:
                return "a finite number"
            if self.open_low:
                return "positive" if self.low == 0 else f"greater than {_number(self.low)}"
            return f"at least {_number(self.low)}"
        if self.low is None:
            return f"below {_number(self.high)}" if self.open_high else f"at most {_number(self.high)}"
        return (f"in {'(' if self.open_low else '['}{_number(self.low)}, {_number(self.high)}"
                f"{')' if self.open_high else ']'}")

    def json_schema(self) -> dict[str, float]:
        """The range as JSON-schema keywords (``minimum``, ``exclusiveMaximum`` ...)."""
        out = {}
        if self.low is not None:
            out["exclusiveMinimum" if self.open_low else "minimum"] = self.low
        if self.high is not None:
            out["exclusiveMaximum" if self.open_high else "maximum"] = self.high
        return out

    def error(self, key: str, value: Any) -> str | None:
        """The one-line complaint about ``value`` of ``key``, or ``None`` when the value is fine."""
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            wanted = "a finite number" if self == ANY else f"a number {self.describe()}"
            return f"{key} must be {wanted}, not {value!r}"
        if not math.isfinite(value):
            return f"{key} must be a finite number, not {value}"
        if not self.contains(value):
            return f"{key} must be {self.describe()}, not {value}"
        return None


def _number(value: float) -> str:
    return str(int(value)) if float(value).is_integer() else str(value)


#: the ranges most fields need
AT_LEAST_0 = Range(0)
AT_LEAST_1 = Range(1)
AT_LEAST_2 = Range(2)
POSITIVE = Range(0, open_low=True)
FRACTION = Range(0, 1)
PROBABILITY = Range(0, 1, open_low=True, open_high=True)
ANY = Range()


def check_ranges(config: Any, ranges: Mapping[str, Range]) -> None:
    """Raise ``ValueError`` for the first field of the dataclass ``config`` that cannot work.

    A field listed in ``ranges`` must lie in its range (``None`` passes: it selects a default); any other
    number field must be finite. The message names the field: ``lk_iterations must be at least 1, not 0``.
    """
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        if value is None:
            continue
        if f.name in ranges:
            message = ranges[f.name].error(f.name, value)
        elif isinstance(value, numbers.Real) and not isinstance(value, bool):
            message = ANY.error(f.name, value)
        else:
            continue
        if message:
            raise ValueError(message)


def shared_ranges(ranges: Mapping[str, Range], *names: str) -> dict[str, Range]:
    """The entries ``names`` of another dataclass's table (fields that two configurations share)."""
    return {name: ranges[name] for name in names}
