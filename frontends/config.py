"""Shared helpers for the frontends' configuration dataclasses."""

from __future__ import annotations

import dataclasses
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
