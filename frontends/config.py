"""Shared helpers for the frontends' configuration dataclasses."""

from __future__ import annotations

import dataclasses
from typing import Any, TypeVar

T = TypeVar("T", bound="ConfigMixin")


class ConfigMixin:
    """Adds :meth:`from_dict` and :meth:`to_dict` to a configuration dataclass."""

    @classmethod
    def from_dict(cls: type[T], values: dict[str, Any] | None) -> T:
        """Build the configuration from a plain mapping (e.g. a YAML section).

        Raises
        ------
        ValueError
            For a key that is not a field (the message names it) or a value a field rejects.
        """
        values = dict(values or {})
        names = {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
        for key in values:
            if key not in names:
                raise ValueError(f"unknown {cls.__name__} key {key!r} (known: {', '.join(sorted(names))})")
        return cls(**values)

    def to_dict(self) -> dict[str, Any]:
        """The configuration as a plain mapping (round-trips through :meth:`from_dict`)."""
        return dataclasses.asdict(self)  # type: ignore[call-overload]
