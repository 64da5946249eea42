"""One configuration schema: pydantic models, and models derived from the configuration dataclasses.

Every option is defined once, where it is used. The frontends' settings (``KltConfig``, ``FeatureConfig``,
``DirectConfig``) are pydantic models themselves (:mod:`frontends.config`): each field carries its default,
range, unit and description. The other stages' options are fields of dataclasses (``OdometryConfig``,
``FusionConfig`` and its noise models, ``SimulationOptions``), with the default in the field, the description
and unit in the class's numpy-style ``Attributes`` docstring and the ranges of number fields in a ``RANGES``
table (:class:`Range`, checked by :func:`check_ranges`); this module turns such a dataclass into a pydantic
model (:func:`model_of`) — a new field needs no change here. Either kind is used to

* validate a mapping read from YAML and build the configuration (:func:`build`), with errors that name the
  file, the key path and the expected type (:func:`frontends.config.describe_error`)::

      run.yaml: fusion.ekf.accel_sigma: expected a number, got 'abc'
      run.yaml: klt: lk_iterations must be at least 1, not 0

* print every option with its default and description as YAML (:func:`commented_yaml`), and
* give the JSON schema for editors (:func:`json_schema`).

The checks of a dataclass that involve several fields stay in its ``__post_init__``; their messages are
reported at the key path of the section.
"""

from __future__ import annotations

import dataclasses
import inspect
import math
import numbers
import re
import types
import typing
from collections.abc import Mapping
from typing import Annotated, Any

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, create_model
from pydantic.json_schema import GenerateJsonSchema

from frontends.config import INTEGER, NUMBER, location, number_text, one_line, shown
from fusion_vo.errors import InputError

_UNIT = re.compile(r"\[([^\[\]]{1,32})\]")


@dataclasses.dataclass(frozen=True)
class Range:
    """The values a number field of a configuration dataclass can take: from ``low`` to ``high`` (either end
    open or left out).

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
                return "positive" if self.low == 0 else f"greater than {number_text(self.low)}"
            return f"at least {number_text(self.low)}"
        if self.low is None:
            return f"below {number_text(self.high)}" if self.open_high else f"at most {number_text(self.high)}"
        return (f"in {'(' if self.open_low else '['}{number_text(self.low)}, {number_text(self.high)}"
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


#: the ranges most fields need
AT_LEAST_0 = Range(0)
AT_LEAST_1 = Range(1)
POSITIVE = Range(0, open_low=True)
FRACTION = Range(0, 1)
ANY = Range()


def check_ranges(config: Any, ranges: Mapping[str, Range]) -> None:
    """Raise ``ValueError`` for the first field of the dataclass ``config`` that cannot work.

    A field listed in ``ranges`` must lie in its range (``None`` passes: it selects a default); any other
    number field must be finite. The message names the field: ``threads must be in [1, 256], not 0``.
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


def field_docs(cls: type) -> dict[str, str]:
    """Field name -> description, from the ``Attributes`` (or ``Parameters``) section of a docstring.

    A line ``name : type`` (or ``a, b : type``) at the section's indentation starts an entry; the
    indented lines below it are its description, joined into one line.
    """
    doc = inspect.cleandoc(cls.__doc__ or "")
    lines = doc.splitlines()
    docs: dict[str, str] = {}
    in_section = False
    names: list[str] = []
    text: list[str] = []

    def flush() -> None:
        if names:
            for name in names:
                docs[name] = " ".join(text).strip()

    for i, line in enumerate(lines):
        if line.strip() in ("Attributes", "Parameters") and i + 1 < len(lines) and set(lines[i + 1].strip()) == {"-"}:
            in_section = True
            continue
        if not in_section or set(line.strip()) == {"-"}:
            continue
        if line and not line[0].isspace():
            flush()
            names, text = [], []
            if " : " in line or line.rstrip().endswith(":"):
                head = line.split(" : ", 1)[0] if " : " in line else line.rstrip(": ")
                names = [n.strip() for n in head.split(",") if n.strip().isidentifier()]
            else:  # the next section of the docstring
                in_section = False
        elif names:
            text.append(line.strip())
    flush()
    return docs


#: a docstring's statement of the default: ``(default X)`` as a whole, or ``; default X`` within parentheses
_DEFAULT_WHOLE = re.compile(r"\s*\(default\b[^()]*(?:\([^()]*\)[^()]*)*\)")
_DEFAULT_PART = re.compile(r";\s*default\b[^;()]*(?=\))")


def without_default(description: str) -> str:
    """``description`` without what it says of the default (``(default 0.01, ...)``, ``(...; default 0)``): for a
    section whose defaults differ from its class's, whose docstring states the class's."""
    return _DEFAULT_PART.sub("", _DEFAULT_WHOLE.sub("", description)).strip()


#: a bracketed interval of numbers (``[0, 1]``), which states a range, not a unit
_INTERVAL = re.compile(r"\s*[-+]?[\d.]+\s*,\s*[-+]?[\d.]+\s*")


def _unit(description: str) -> str | None:
    """The unit in square brackets that follows the field's name at the start of its description (``Node rate
    [Hz] where ...``) in its first clause (outside parentheses, before a semicolon or full stop); none where the brackets list one unit per
    field of a docstring entry that documents several fields (``a, b : float ... [m], [rad]``)."""
    head = re.sub(r"\([^()]*\)", "", description or "")  # the unit follows the field's name, not an aside
    head = re.split(r";|\. ", head, maxsplit=1)[0]
    for match in _UNIT.finditer(head):
        if _INTERVAL.fullmatch(match.group(1)):
            continue
        if re.match(r",\s*\[", head[match.end():]):
            return None
        return match.group(1)
    return None


class _JsonSchema(GenerateJsonSchema):
    """JSON schema generation that describes a field of a type JSON schema cannot express (an array, a
    callable) as "any value" instead of failing."""

    def handle_invalid_for_json_schema(self, schema, error_info):
        return {}

    def encode_default(self, dft):
        return super().encode_default(plain(dft))


def json_schema(model: type[BaseModel]) -> dict:
    """The JSON schema of a model (for editors); a property whose description states a unit in square brackets
    also has it as ``unit``."""
    out = model.model_json_schema(schema_generator=_JsonSchema)
    for definition in [out, *out.get("$defs", {}).values()]:
        for prop in definition.get("properties", {}).values():
            unit = _unit(prop.get("description", ""))
            if unit and "unit" not in prop:
                prop["unit"] = unit
    return out


def _first_sentence(text: str, limit: int = 110) -> str:
    text = text.replace("``", "").replace("i.e.", "i\u2024e\u2024").replace("e.g.", "e\u2024g\u2024")
    sentence = re.split(r"(?<=[a-z0-9\)\]])\. ", text, maxsplit=1)[0].rstrip(".")
    sentence = sentence.replace("\u2024", ".")
    return sentence if len(sentence) <= limit else sentence[: limit - 3].rstrip() + "..."


def _defaults_key(instance) -> tuple:
    return tuple((f.name, repr(getattr(instance, f.name))) for f in dataclasses.fields(instance))


_MODELS: dict[tuple, type[BaseModel]] = {}


def model_of(cls: type, exclude: tuple[str, ...] = (), defaults: Any = None) -> type[BaseModel]:
    """The pydantic model of a configuration dataclass (cached).

    Parameters
    ----------
    cls : type
        A dataclass whose fields all have defaults, or a pydantic model (returned as it is).
    exclude : tuple of str
        Fields left out of the model.
    defaults : instance of ``cls``, optional
        Take the defaults from this instance instead of the fields (a nested section whose default
        differs from the class's, e.g. the odometry twist's noise).

    Returns
    -------
    type of BaseModel
        Unknown keys are rejected; nested dataclasses become nested models; each field carries the
        description from the dataclass's docstring and its range from the dataclass's ``RANGES``.
    """
    if issubclass(cls, BaseModel):  # a pydantic model already: it is its own schema
        if exclude or defaults is not None:
            raise TypeError(f"{cls.__name__} is a pydantic model: its fields and defaults are its own")
        return cls
    key = (cls, exclude, None if defaults is None else _defaults_key(defaults))
    if key in _MODELS:
        return _MODELS[key]
    try:
        hints = typing.get_type_hints(cls)
    except (NameError, TypeError):  # an annotation that cannot be resolved: such fields accept any value
        hints = {f.name: f.type for f in dataclasses.fields(cls) if not isinstance(f.type, str)}
    docs = field_docs(cls)
    ranges = getattr(cls, "RANGES", {})  # Range of number fields
    fields: dict[str, Any] = {}
    own = cls() if defaults is not None else None  # the class's defaults, which its docstring states
    for f in dataclasses.fields(cls):
        if f.name in exclude or not f.init:
            continue
        if defaults is not None:
            default = getattr(defaults, f.name)
        elif f.default is not dataclasses.MISSING:
            default = f.default
        elif f.default_factory is not dataclasses.MISSING:
            default = f.default_factory()
        else:
            raise TypeError(f"{cls.__name__}.{f.name} has no default")
        description = docs.get(f.name)
        if own is not None and description and default != getattr(own, f.name, default):
            description = without_default(description)  # the docstring's default is the class's, not this one
        # the dataclass's table of ranges (checked by its __post_init__), for editors
        extra = ranges[f.name].json_schema() if f.name in ranges else None
        if dataclasses.is_dataclass(default):
            nested = model_of(type(default), defaults=default)
            fields[f.name] = (nested, Field(default_factory=nested, description=description))
        else:
            annotation = _no_bool_for_numbers(hints.get(f.name, Any))
            fields[f.name] = (annotation, Field(default=default, description=description, json_schema_extra=extra))
    summary = inspect.cleandoc(cls.__doc__ or "").split("\n\n", 1)[0].replace("\n", " ")
    model = create_model(cls.__name__, __config__=ConfigDict(extra="forbid", arbitrary_types_allowed=True,
                                                             title=cls.__name__), __doc__=summary, **fields)
    _MODELS[key] = model
    return model


def _no_bool_for_numbers(annotation):
    """A number field (``int``, ``float``, optionally ``None``) that rejects ``true``/``false`` (pydantic's
    lax mode would read them as 1 and 0)."""
    args = set(typing.get_args(annotation)) if typing.get_origin(annotation) in (typing.Union, types.UnionType) \
        else {annotation}
    kinds = args - {type(None)}
    if kinds == {int}:
        return Annotated[annotation, INTEGER]
    if kinds and kinds <= {int, float}:
        return Annotated[annotation, NUMBER]
    return annotation


def config_error(exc: ValidationError, model: type[BaseModel], path=None, prefix: tuple = ()) -> InputError:
    """The first error of a validation as an :class:`InputError` naming the file and the key path."""
    return InputError(one_line(exc, model, prefix), path)


def validate(model: type[BaseModel], data: Any, path=None, prefix: tuple = ()) -> BaseModel:
    """Validate a mapping against a model; raise :class:`InputError` naming the file and key path."""
    if data is None:
        data = {}
    if not isinstance(data, dict):
        where = location(prefix) or "the file"
        raise InputError(f"{where}: expected a mapping of key: value, got {shown(data)}", path)
    try:
        return model.model_validate(_drop_empty_sections(model, data))
    except ValidationError as exc:
        raise config_error(exc, model, path, prefix) from None


def _drop_empty_sections(model: type[BaseModel], data: dict) -> dict:
    """A section left empty in YAML (``fusion:`` with every line below commented out) reads as null: it
    keeps its defaults, like a section left out."""
    out = {}
    for key, value in data.items():
        field = model.model_fields.get(key) if isinstance(key, str) else None
        sub = getattr(field, "annotation", None)
        if inspect.isclass(sub) and issubclass(sub, BaseModel):
            if value is None:
                continue
            if isinstance(value, dict):
                value = _drop_empty_sections(sub, value)
        out[key] = value
    return out


def to_dataclass(cls: type, values: BaseModel, path=None, prefix: tuple = ()):
    """Build the dataclass from validated values; its own checks (``__post_init__``) name the section.

    When ``cls`` is a pydantic model, ``values`` is already an instance of it (checked when it was validated)
    and is returned as it is.
    """
    if isinstance(values, cls) and issubclass(cls, BaseModel):
        return values
    kwargs = {}
    for name in type(values).model_fields:
        value = getattr(values, name)
        if isinstance(value, BaseModel):
            sub_cls = next(type(f.default) if f.default is not dataclasses.MISSING else type(f.default_factory())
                           for f in dataclasses.fields(cls) if f.name == name)
            value = to_dataclass(sub_cls, value, path, prefix + (name,))
        kwargs[name] = value
    try:
        return cls(**kwargs)
    except InputError as exc:
        raise InputError(f"{location(prefix)}: {exc.message}" if prefix else exc.message, path) from None
    except (ValueError, TypeError) as exc:
        raise InputError(f"{location(prefix)}: {exc}" if prefix else str(exc), path) from None


def build(cls: type, data: Any, path=None, prefix: tuple = (), exclude: tuple[str, ...] = ()):
    """Validate a mapping (e.g. a YAML section) and build the configuration ``cls`` (a dataclass or a pydantic
    model) from it.

    Raises
    ------
    InputError
        For an unknown key, a value of the wrong type or a combination the dataclass rejects; the
        message names ``path`` and the key path (``prefix`` is the section's own path).
    """
    model = model_of(cls, exclude)
    return to_dataclass(cls, validate(model, data, path, prefix), path, prefix)


def plain(value):
    """Validated values as plain YAML-safe Python (tuples become lists, models mappings)."""
    if isinstance(value, BaseModel):
        return {k: plain(getattr(value, k)) for k in type(value).model_fields}
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    if hasattr(value, "tolist") and callable(value.tolist):  # numpy arrays and scalars
        return value.tolist()
    return value


def _scalar(value) -> str:
    text = yaml.safe_dump(plain(value), default_flow_style=True, width=10_000).strip()
    return text.removesuffix("\n...").removesuffix("...").strip()


def commented_yaml(model: type[BaseModel], values: BaseModel | None = None, indent: int = 0) -> list[str]:
    """Lines of YAML with every field of ``model`` (its value in ``values``, else its default) and a
    comment with the first sentence of its description."""
    values = values if values is not None else model()
    lines = []
    pad = " " * indent
    for name, field in model.model_fields.items():
        value = getattr(values, name)
        comment = f"  # {_first_sentence(field.description)}" if field.description else ""
        if isinstance(value, BaseModel):
            lines.append(f"{pad}{name}:{comment}")
            lines.extend(commented_yaml(type(value), value, indent + 2))
        else:
            lines.append(f"{pad}{name}: {_scalar(value)}{comment}")
    return lines


# --------------------------------------------------------------------------- the reference as Markdown
_ROLE = re.compile(r":\w+:`~?([^`]+)`")  # a reST role (:class:`~a.b.C`) -> its target


def _markdown_text(text: str | None) -> str:
    """A docstring description as one line of a Markdown table cell."""
    text = _ROLE.sub(r"``\1``", " ".join((text or "").split()))
    return text.replace("``", "`").replace("|", "\\|")


def _range_text(extra: dict | None) -> str:
    """The JSON-schema bounds of a field (``minimum``, ``exclusiveMaximum`` ...) as ``≥ 1``, ``(0, 1]``."""
    extra = extra or {}
    low = ("(", extra["exclusiveMinimum"]) if "exclusiveMinimum" in extra else \
        ("[", extra["minimum"]) if "minimum" in extra else None
    high = (")", extra["exclusiveMaximum"]) if "exclusiveMaximum" in extra else \
        ("]", extra["maximum"]) if "maximum" in extra else None
    if low and high:
        return f"{low[0]}{number_text(low[1])}, {number_text(high[1])}{high[0]}"
    if low:
        return f"{'>' if low[0] == '(' else '≥'} {number_text(low[1])}"
    if high:
        return f"{'<' if high[0] == ')' else '≤'} {number_text(high[1])}"
    return ""


#: the constraints of a pydantic field (``Field(ge=1, le=99)``) -> their JSON-schema keywords
_BOUND_KEYWORDS = {"ge": "minimum", "gt": "exclusiveMinimum", "le": "maximum", "lt": "exclusiveMaximum"}


def _bounds(extra: Any, constraints: typing.Iterable[Any]) -> dict:
    """A range as JSON-schema keywords: those a configuration dataclass's ``RANGES`` put in a field's
    ``json_schema_extra`` (:func:`model_of`), and the constraints of a pydantic field (``Field(gt=0, le=1)``:
    ``annotated_types`` objects in the field's ``metadata``, or a ``FieldInfo`` within an ``Annotated`` type)."""
    out = dict(extra) if isinstance(extra, dict) else {}
    for constraint in constraints:
        if hasattr(constraint, "metadata"):  # a FieldInfo inside Annotated[...]
            out.update(_bounds(None, constraint.metadata))
            continue
        for name, keyword in _BOUND_KEYWORDS.items():
            value = getattr(constraint, name, None)
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                out[keyword] = value
    return out


def _values_text(annotation, extra: dict | None) -> str:
    """What a field accepts: its choices, its type and its range, in a few words."""
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if origin is Annotated:  # its own range, if any, beside the field's
        return _values_text(args[0], _bounds(extra, args[1:]))
    if origin in (typing.Union, types.UnionType):
        parts = [_values_text(a, extra) for a in args if a is not type(None)]
        return " or ".join(p for p in parts if p) + (", or null" if type(None) in args else "")
    if origin is typing.Literal:
        return ("one of " if len(args) > 1 else "") + ", ".join(f"`{a}`" for a in args)
    if origin in (list, tuple) or annotation in (list, tuple):
        inner = _values_text(args[0], None) if args else ""
        return f"a list ({inner})" if inner else "a list"
    bounds = _range_text(extra)
    if annotation is bool:
        return "true or false"
    if annotation is int:
        return f"integer {bounds}".strip()
    if annotation is float:
        return f"number {bounds}".strip()
    if annotation is str:
        return "text"
    return bounds


def markdown_reference(model: type[BaseModel], title: str, intro: str = "", command: str = "") -> str:
    """The reference of a configuration model as Markdown: one table per section.

    Parameters
    ----------
    model : type of BaseModel
        The configuration (e.g. :func:`fusion_vo.config.run_model`); nested models are its sections.
    title, intro : str
        The page's heading and the paragraph below it.
    command : str
        The command that prints this page (named in a comment at its top, for whoever edits it by hand).

    Returns
    -------
    str
        A heading, then for the top-level options and for every section (``odometry``, ``fusion.ekf`` ...)
        a table with one row per option: key, default (YAML), accepted values (choices, type and the
        range the schema carries), unit and the full description. Sections follow the model's field
        order, depth first, so the page changes only where the configuration does.
    """
    lines = [f"# {title}", ""]
    if command:
        lines += [f"<!-- generated by `{command}`: edit the configuration's docstrings, not this file -->", ""]
    if intro:
        lines += [" ".join(intro.split()), ""]

    def table(name: str, description: str, section: type[BaseModel], defaults: BaseModel) -> None:
        lines.extend([f"## `{name}`" if name else "## Top level", ""])
        if description:
            lines.extend([_markdown_text(description), ""])
        lines.extend(["| option | default | values | unit | description |", "|---|---|---|---|---|"])
        children = []
        for key, field in section.model_fields.items():
            value = getattr(defaults, key)
            path = f"{name}.{key}" if name else key
            if isinstance(value, BaseModel):
                children.append((path, field.description or "", value))
                lines.append(f"| `{key}` | (section) | see [`{path}`](#{path.replace('.', '')}) | | "
                             f"{_markdown_text(field.description)} |")
                continue
            extra = _bounds(field.json_schema_extra, field.metadata)
            lines.append(f"| `{key}` | `{_scalar(value)}` | {_values_text(field.annotation, extra)} | "
                         f"{_markdown_text(_unit(field.description) or '')} | {_markdown_text(field.description)} |")
        lines.append("")
        for path, text, value in children:  # depth first: a section's own sections follow it
            table(path, text, type(value), value)

    table("", "", model, model())
    return "\n".join(lines).rstrip("\n") + "\n"
