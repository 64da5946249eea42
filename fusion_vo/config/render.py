"""A configuration's models as text: commented YAML, JSON schema and a Markdown reference.

Everything printed comes from the models' fields: the default (or the value in effect), the range, the unit (in
square brackets in the description, :func:`unit`) and the description. A configuration whose sections depend on
what is registered (the run configuration's ``fusion`` holds the registered sensors' sections) is printed
through a *view* (:func:`view`): a model with the same fields whose defaults are the values to show and which has
a field for each such section.

* :func:`commented_yaml`: every option and its value, with the first sentence of its description
  (``--print-config``);
* :func:`json_schema`: the JSON schema, each property with its ``unit`` (``--print-schema``, for editors);
* :func:`markdown_reference`: one table per section (``--print-reference``).
"""

from __future__ import annotations

import inspect
import re
from typing import Annotated, Any

import yaml
from pydantic import BaseModel, ConfigDict, Field, create_model
from pydantic.json_schema import GenerateJsonSchema

from fusion_vo.config.base import Section

_UNIT = re.compile(r"\[([^\[\]]{1,32})\]")
_ROLE = re.compile(r":\w+:`~?([^`]+)`")  # a reST role (:class:`~a.b.C`) -> its target
#: a bracketed interval of numbers (``[0, 1]``), which states a range, not a unit
_INTERVAL = re.compile(r"\s*[-+]?[\d.]+\s*,\s*[-+]?[\d.]+\s*")


def section_model(field) -> type[BaseModel] | None:
    """The model of a field that is a section (its annotation a model), else None."""
    sub = getattr(field, "annotation", None)
    return sub if inspect.isclass(sub) and issubclass(sub, BaseModel) else None


def unit(description: str | None) -> str | None:
    """The unit in square brackets that follows the option's name at the start of its description (``Node rate
    [Hz] where ...``), in its first clause (outside parentheses, before a semicolon or full stop); none where the
    brackets hold an interval (``[0, 1]``) or list one unit per item (``[m], [rad]``)."""
    head = re.sub(r"\([^()]*\)", "", description or "")  # the unit follows the option's name, not an aside
    head = re.split(r";|\. ", head, maxsplit=1)[0]
    for match in _UNIT.finditer(head):
        if _INTERVAL.fullmatch(match.group(1)):
            continue
        if re.match(r",\s*\[", head[match.end():]):
            return None
        return match.group(1)
    return None


def view(model: type[BaseModel], values: dict, models: dict[str, type[BaseModel]] | None = None,
         annotations: dict[str, Any] | None = None, path: str = "", names: set | None = None) -> type[BaseModel]:
    """A model to print ``values`` of ``model`` with: the same fields, each with its value in ``values`` as its
    default, sections as views of their own.

    Parameters
    ----------
    model : type of BaseModel
        The configuration.
    values : dict
        Its values (``model_dump(mode="json")``), which may hold sections that are no field of ``model``.
    models : dict, optional
        The model of each such section by its key path (``fusion.compass``); a mapping in ``values`` at a key
        path that has none is a section whose keys are those of the mapping (``fusion.states``).
    annotations : dict, optional
        Replacement annotations by key path (``sensors``: the registered names as its choices).
    path : str
        The key path of ``model`` (for ``models`` and ``annotations``).
    names : set, optional
        The names of the views made so far for this one (a second view of a class is named after its key too,
        ``WheelNoise_odom``, so that the JSON schema holds both).
    """
    models, annotations = models or {}, annotations or {}
    names = set() if names is None else names
    fields: dict[str, Any] = {}
    for name, field in model.model_fields.items():
        key = f"{path}{name}"
        sub = section_model(field)
        if sub is not None:
            fields[name] = (view(sub, values.get(name) or {}, models, annotations, key + ".", names),
                            Field(default_factory=dict, description=field.description))
            continue
        annotation = annotations.get(key, Annotated[(field.annotation, *field.metadata)] if field.metadata
                                     else field.annotation)
        fields[name] = (annotation, Field(values.get(name), description=field.description,
                                          json_schema_extra=field.json_schema_extra))
    for name, value in values.items():  # sections of the values that are no field (the registered sensors')
        key = f"{path}{name}"
        if name in fields or not isinstance(value, dict) or (
                key not in models and not all(f"{key}.{k}" in models for k in value)):
            continue
        if key in models:
            sub = view(models[key], value, models, annotations, key + ".", names)
            description = (models[key].__doc__ or "").strip().split("\n\n")[0].replace("\n", " ")
        else:
            sub = create_model(name.title(), __config__=ConfigDict(extra="forbid", title=name.title()),
                               **{k: (view(models[f"{key}.{k}"], v, models, annotations, f"{key}.{k}.", names),
                                      Field(default_factory=dict,
                                            description=f"{k}: its prior (initial, sigma) and random walk"))
                                  for k, v in value.items()})
            description = ("Prior and random walk of the state variables registered sensors add, by state name "
                           "(``initial``, ``sigma``, ``random_walk``: ``fusion_vo.sensors.registry.StatePrior``; "
                           "default: as each sensor registers it).")
        fields[name] = (sub, Field(default_factory=dict, description=description))
    title = model.model_config.get("title") or model.__name__
    name = model.__name__ if model.__name__ not in names else f"{model.__name__}_{path.rstrip('.').split('.')[-1]}"
    names.add(name)
    return create_model(name, __config__=ConfigDict(extra="forbid", title=title, arbitrary_types_allowed=True),
                        __doc__=model.__doc__, **fields)


class _JsonSchema(GenerateJsonSchema):
    """JSON schema generation that describes a field of a type JSON schema cannot express (a callable) as "any
    value" instead of failing."""

    def handle_invalid_for_json_schema(self, schema, error_info):
        return {}


def json_schema(model: type[BaseModel]) -> dict:
    """The JSON schema of a model (for editors); a property whose description states a unit in square brackets
    also has it as ``unit``."""
    out = model.model_json_schema(schema_generator=_JsonSchema)
    for definition in [out, *out.get("$defs", {}).values()]:
        for prop in definition.get("properties", {}).values():
            found = unit(prop.get("description", ""))
            if found and "unit" not in prop:
                prop["unit"] = found
    return out


def _first_sentence(text: str, limit: int = 110) -> str:
    text = _ROLE.sub(r"\1", text).replace("``", "").replace("i.e.", "i\u2024e\u2024").replace("e.g.", "e\u2024g\u2024")
    sentence = re.split(r"(?<=[a-z0-9\)\]])\. ", text, maxsplit=1)[0].rstrip(".")
    sentence = sentence.replace("\u2024", ".")
    return sentence if len(sentence) <= limit else sentence[: limit - 3].rstrip() + "..."


def _scalar(value) -> str:
    text = yaml.safe_dump(value, default_flow_style=True, width=10_000).strip()
    return text.removesuffix("\n...").removesuffix("...").strip()


def commented_yaml(model: type[BaseModel], values: dict, indent: int = 0) -> list[str]:
    """Lines of YAML with every field of ``model`` (a :func:`view`) at its value in ``values`` and a comment with
    the first sentence of its description."""
    lines = []
    pad = " " * indent
    for name, field in model.model_fields.items():
        comment = f"  # {_first_sentence(field.description)}" if field.description else ""
        sub = section_model(field)
        if sub is not None:
            lines.append(f"{pad}{name}:{comment}")
            lines.extend(commented_yaml(sub, values.get(name) or {}, indent + 2))
        else:
            lines.append(f"{pad}{name}: {_scalar(values.get(name))}{comment}")
    return lines


# --------------------------------------------------------------------------- the reference as Markdown


def _markdown_text(text: str | None) -> str:
    """A description as one line of a Markdown table cell."""
    text = _ROLE.sub(r"``\1``", " ".join((text or "").split()))
    return text.replace("``", "`").replace("|", "\\|")


def _number(value: float) -> str:
    return f"{value:g}"


def _range_text(prop: dict) -> str:
    """The bounds of a JSON-schema number (``minimum``, ``exclusiveMaximum`` ...) as ``≥ 1``, ``(0, 1]``."""
    low = ("(", prop["exclusiveMinimum"]) if "exclusiveMinimum" in prop else \
        ("[", prop["minimum"]) if "minimum" in prop else None
    high = (")", prop["exclusiveMaximum"]) if "exclusiveMaximum" in prop else \
        ("]", prop["maximum"]) if "maximum" in prop else None
    if low and high:
        return f"{low[0]}{_number(low[1])}, {_number(high[1])}{high[0]}"
    if low:
        return f"{'>' if low[0] == '(' else '≥'} {_number(low[1])}"
    if high:
        return f"{'<' if high[0] == ')' else '≤'} {_number(high[1])}"
    return ""


def values_text(prop: dict) -> str:
    """What a JSON-schema property accepts: its choices, its type and its range, in a few words."""
    if "enum" in prop or "const" in prop:
        choices = prop.get("enum", [prop.get("const")])
        return ("one of " if len(choices) > 1 else "") + ", ".join(f"`{c}`" for c in choices)
    if "anyOf" in prop:
        parts = [values_text(p) for p in prop["anyOf"] if p.get("type") != "null"]
        nullable = any(p.get("type") == "null" for p in prop["anyOf"])
        return " or ".join(p for p in parts if p) + (", or null" if nullable else "")
    kind = prop.get("type")
    if kind == "boolean":
        return "true or false"
    if kind in ("integer", "number"):
        return f"{kind} {_range_text(prop)}".strip()
    if kind == "string":
        return "text"
    if kind == "array":
        items = prop.get("prefixItems") or ([prop["items"]] if isinstance(prop.get("items"), dict) else [])
        inner = [values_text(p) for p in items]
        if len(set(inner)) == 1 and "prefixItems" in prop:
            inner = [f"{len(items)} × {inner[0]}"]
        inner = [p for p in inner if p]
        return f"a list ({'; '.join(inner)})" if inner else "a list"
    return ""


def markdown_reference(model: type[BaseModel], values: dict, title: str, intro: str = "", command: str = "") -> str:
    """The reference of a configuration as Markdown: one table per section.

    Parameters
    ----------
    model : type of BaseModel
        The configuration's :func:`view` (e.g. :func:`fusion_vo.config.run.run_model`); nested models are its
        sections.
    values : dict
        The values shown as defaults.
    title, intro : str
        The page's heading and the paragraph below it.
    command : str
        The command that prints this page (named in a comment at its top, for whoever edits it by hand).

    Returns
    -------
    str
        A heading, then for the top-level options and for every section (``odometry``, ``fusion.ekf`` ...) a
        table with one row per option: key, default (YAML), accepted values (choices, type and range), unit and
        the full description. Sections follow the model's field order, depth first, so the page changes only
        where the configuration does.
    """
    lines = [f"# {title}", ""]
    if command:
        lines += [f"<!-- generated by `{command}`: edit the descriptions of the configuration's fields, not this "
                  "file -->", ""]
    if intro:
        lines += [" ".join(intro.split()), ""]

    def table(name: str, description: str, section: type[BaseModel], section_values: dict) -> None:
        lines.extend([f"## `{name}`" if name else "## Top level", ""])
        if description:
            lines.extend([_markdown_text(description), ""])
        lines.extend(["| option | default | values | unit | description |", "|---|---|---|---|---|"])
        props = section.model_json_schema(schema_generator=_JsonSchema).get("properties", {})
        children = []
        for key, field in section.model_fields.items():
            path = f"{name}.{key}" if name else key
            sub = section_model(field)
            if sub is not None:
                children.append((path, field.description or "", sub, section_values.get(key) or {}))
                lines.append(f"| `{key}` | (section) | see [`{path}`](#{path.replace('.', '')}) | | "
                             f"{_markdown_text(field.description)} |")
                continue
            lines.append(f"| `{key}` | `{_scalar(section_values.get(key))}` | {values_text(props.get(key, {}))} | "
                         f"{_markdown_text(unit(field.description) or '')} | {_markdown_text(field.description)} |")
        lines.append("")
        for path, text, sub, sub_values in children:  # depth first: a section's own sections follow it
            table(path, text, sub, sub_values)

    table("", "", model, values)
    return "\n".join(lines).rstrip("\n") + "\n"


def section_view(model: type[Section]) -> type[BaseModel]:
    """The :func:`view` of a configuration at its defaults (a model without sections that depend on what is
    registered, e.g. ``SimulationOptions``)."""
    return view(model, model().model_dump(mode="json"))
