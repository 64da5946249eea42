"""Configuration models: pydantic models whose fields carry their default, range, unit and description.

Every settings class of the frontends derives from :class:`Settings`, and each of its options is one
field, defined once::

    class Example(Settings):
        window: Int = Field(13, ge=5, le=101, description="Tracking window side [px].")

The unit is written in square brackets in the description. Checks that involve several fields (or
one field beyond a range) are ``model_validator`` methods raising ``ValueError`` with a sentence that
names the field. A model

* is immutable (``frozen``), so one configuration can be shared by threads and frontends;
* rejects unknown keys, non-finite numbers and ``true``/``false`` where a number belongs, and checks
  its own defaults;
* raises :class:`ConfigError` (a ``ValueError``) in one line naming the key when a value cannot work::

      KltConfig: lk_iterations must be at least 1, not 0
      KltConfig: max_tracks: expected an integer, got 'many'

:func:`describe_error` words a pydantic error this way for any model, also when the model is a
section of a larger one (the location is then its key path: ``klt: lk_iterations must be ...``).
"""

from __future__ import annotations

import inspect
from collections.abc import Mapping
from types import UnionType
from typing import Annotated, Any, Self, Union, get_args, get_origin

from pydantic import BaseModel, BeforeValidator, ConfigDict, ValidationError
from pydantic_core import ErrorDetails, PydanticCustomError

#: pydantic error types -> the expected kind of value, in words
EXPECTED = {
    "float_parsing": "a number", "float_type": "a number",
    "int_parsing": "an integer", "int_type": "an integer", "int_from_float": "an integer",
    "bool_parsing": "true or false", "bool_type": "true or false",
    "string_type": "a string", "list_type": "a list", "tuple_type": "a list", "set_type": "a list",
    "dict_type": "a mapping of key: value", "model_type": "a mapping of key: value",
    "model_attributes_type": "a mapping of key: value", "dataclass_type": "a mapping of key: value",
}


class ConfigError(ValueError):
    """A configuration value that cannot work; the message is one line naming the key."""


def not_a_bool(error_type: str) -> BeforeValidator:
    """A validator refusing ``true``/``false`` where a number belongs (pydantic's lax mode reads them as 1
    and 0); ``error_type`` is the pydantic error type reported (``"int_type"`` or ``"float_type"``)."""

    def check(value: Any) -> Any:
        if isinstance(value, bool):
            raise PydanticCustomError(error_type, "Input should be a number, not true or false")
        return value

    return BeforeValidator(check)


#: the validators of an integer and of a number option; a range given in the same ``Annotated`` goes before
#: them (``Annotated[float, Field(gt=0), NUMBER]``), so that the JSON schema states it
INTEGER = not_a_bool("int_type")
NUMBER = not_a_bool("float_type")
#: an integer option (not ``true``/``false``), its range given by its ``Field``
Int = Annotated[int, INTEGER]
#: a number option (not ``true``/``false``; finite, as every float of a :class:`Settings` model)
Float = Annotated[float, NUMBER]


class _OneLineErrors(type(BaseModel)):
    """Building a model directly (``Model(**values)``) raises :class:`ConfigError` in one line instead of
    pydantic's ``ValidationError``. (Not ``__init__``: pydantic also calls an overridden ``__init__`` when the
    model is a section of a larger one, whose errors must keep their key path.)"""

    def __call__(cls, *args: Any, **kwargs: Any) -> Any:
        try:
            return super().__call__(*args, **kwargs)
        except ValidationError as exc:
            raise ConfigError(f"{cls.__name__}: {one_line(exc, cls)}") from None


class Settings(BaseModel, metaclass=_OneLineErrors):
    """Base of a configuration model (see the module description).

    ``Settings(**values)`` and :meth:`from_dict` raise :class:`ConfigError` for a value that cannot
    work; a model nested in a larger one reports its errors there, at their key path.
    """

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False, validate_default=True)

    @classmethod
    def from_dict(cls, values: Mapping[str, Any] | None) -> Self:
        """The configuration from a plain mapping (e.g. a YAML section); keys left out keep their defaults.

        Raises
        ------
        ConfigError
            For an unknown key, a value of the wrong type (the message names the key and the expected
            type) or a value out of its range.
        """
        if values is not None and not isinstance(values, Mapping):
            raise ConfigError(f"{cls.__name__}: expected a mapping of key: value, got {shown(values)}")
        try:
            return cls.model_validate(dict(values or {}))
        except ValidationError as exc:
            raise ConfigError(f"{cls.__name__}: {one_line(exc, cls)}") from None

    def to_dict(self) -> dict[str, Any]:
        """The configuration as a plain mapping (round-trips through :meth:`from_dict`)."""
        return self.model_dump()


def location(loc: tuple) -> str:
    """A key path as written in messages: ``fusion.ekf.accel_sigma``, ``sensors[1]``."""
    text = ""
    for part in loc:
        text += f"[{part}]" if isinstance(part, int) else (f".{part}" if text else str(part))
    return text


def shown(value: Any) -> str:
    """A value as quoted in a message (its ``repr``, cut to 40 characters)."""
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def number_text(value: float) -> str:
    """A bound as written in a message: ``1`` rather than ``1.0``, ``0.1``."""
    return str(int(value)) if float(value).is_integer() else str(value)


def _bound(kind: str, ctx: dict) -> str | None:
    """The range a range error was checking, in words (``None``: not a range error)."""
    if kind == "greater_than_equal":
        return f"at least {number_text(ctx['ge'])}"
    if kind == "greater_than":
        return "positive" if ctx["gt"] == 0 else f"greater than {number_text(ctx['gt'])}"
    if kind == "less_than_equal":
        return f"at most {number_text(ctx['le'])}"
    if kind == "less_than":
        return f"below {number_text(ctx['lt'])}"
    if kind == "finite_number":
        return "a finite number"
    return None


def _known_keys(model: type[BaseModel] | None, loc: tuple) -> list[str]:
    """The keys of the (nested) model at ``loc`` (empty when ``loc`` is not a model; a section that may be null
    is its model)."""
    for part in loc:
        field = model.model_fields.get(part) if model is not None and isinstance(part, str) else None
        sub = getattr(field, "annotation", None) if field else None
        if get_origin(sub) in (Union, UnionType):
            sub = next((a for a in get_args(sub) if inspect.isclass(a) and issubclass(a, BaseModel)), None)
        if not (inspect.isclass(sub) and issubclass(sub, BaseModel)):
            return []
        model = sub
    return [] if model is None else list(model.model_fields)


def describe_error(error: ErrorDetails | dict, model: type[BaseModel] | None = None, prefix: tuple = ()) -> str:
    """One line for one pydantic error of ``model`` (whose own key path is ``prefix``).

    ``key.path: unknown key (known: ...)``, ``key.path: expected an integer, got 'many'``,
    ``section: key must be at least 1, not 0`` (a value out of its range, or a field validator's message that
    starts with "must"), ``section: <the message of a model validator>``.
    """
    loc = tuple(error.get("loc", ()))
    where = location(prefix + loc)
    kind = error.get("type", "")
    value = error.get("input")
    bound = _bound(kind, error.get("ctx") or {})
    if bound is not None:
        number = isinstance(value, (int, float)) and not isinstance(value, bool)
        text = f"must be {bound}, not {value if number else shown(value)}"
        if loc and isinstance(loc[-1], str):  # a field: named in the sentence, after its section
            parent = location(prefix + loc[:-1])
            return f"{parent}: {loc[-1]} {text}" if parent else f"{loc[-1]} {text}"
    elif kind == "extra_forbidden":
        known = _known_keys(model, loc[:-1])
        text = "unknown key" + (f" (known: {', '.join(known)})" if known else "")
    elif kind in EXPECTED:
        text = f"expected {EXPECTED[kind]}, got {shown(value)}"
    elif kind == "literal_error":
        text = f"expected one of {error['ctx']['expected']}, got {shown(value)}"
    elif kind == "missing":
        return f"missing key '{where}'"
    else:
        text = str(error.get("msg", "invalid value")).removeprefix("Value error, ").removeprefix("Assertion failed, ")
        if text.startswith("must ") and loc and isinstance(loc[-1], str):  # a field's own check: named like a range
            parent = location(prefix + loc[:-1])
            return f"{parent}: {loc[-1]} {text}" if parent else f"{loc[-1]} {text}"
    return f"{where}: {text}" if where else text


def one_line(exc: ValidationError, model: type[BaseModel] | None = None, prefix: tuple = ()) -> str:
    """The first error of a validation in one line (:func:`describe_error`), and how many more there are."""
    errors = exc.errors()
    message = describe_error(errors[0], model, prefix)
    return message + (f" (and {len(errors) - 1} more)" if len(errors) > 1 else "")
