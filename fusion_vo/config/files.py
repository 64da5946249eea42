"""YAML files: loading (a key given twice is an error), writing, and validation that names the file and key.

Every YAML file the library reads (a run configuration, a ``sensor.yaml``, a sweep's grid, a simulation's
options) goes through :func:`load_yaml`; a mapping read from one is checked against its model with
:func:`validate`, whose :class:`~fusion_vo.errors.InputError` names the file and the key path::

    run.yaml: fusion.ekf.accel_sigma: expected a number, got 'abc'
    cam0/sensor.yaml: height_sigma must be at most 1000, not 1e+300
"""

from __future__ import annotations

import inspect
from pathlib import Path
from typing import Any, TypeVar

import yaml
from pydantic import BaseModel, ValidationError

from frontends.config import location, one_line, shown
from fusion_vo.errors import InputError, check_file
from fusion_vo.outputs import make_folder, write_atomic

M = TypeVar("M", bound=BaseModel)


class _UniqueKeyLoader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):
    """PyYAML's safe loader (its libyaml parser where PyYAML has it: a run's ``run.yaml`` loads in about a
    third of the pure-Python parser's time), but a key given twice in one mapping is an error (PyYAML keeps
    the last one: a section written twice in a configuration would silently lose the first one's values),
    and so is an integer too long to convert."""


def _unique_mapping(loader: _UniqueKeyLoader, node: yaml.MappingNode, deep: bool = False):
    seen: dict = {}
    for key_node, _ in node.value:
        if key_node.tag == "tag:yaml.org,2002:merge":
            continue
        key = loader.construct_object(key_node, deep=True)
        try:
            first = seen.setdefault(key, key_node.start_mark.line)
        except TypeError:  # an unhashable key: PyYAML's own error follows
            continue
        if first != key_node.start_mark.line:
            raise yaml.constructor.ConstructorError(
                None, None, f"key '{key}' given twice (first on line {first + 1})", key_node.start_mark)
    return loader.construct_mapping(node, deep=deep)


def _bounded_int(loader: _UniqueKeyLoader, node: yaml.ScalarNode) -> int:
    """A YAML integer; one beyond Python's limit on converting digits (4300) is an error at its line, not an
    exception from deep inside the loader."""
    try:
        return loader.construct_yaml_int(node)
    except ValueError:
        raise yaml.constructor.ConstructorError(
            None, None, f"an integer of {len(str(node.value))} characters is no setting", node.start_mark) from None


_UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _unique_mapping)
_UniqueKeyLoader.add_constructor("tag:yaml.org,2002:int", _bounded_int)


def load_yaml_text(text: str) -> Any:
    """Load YAML text with the loader of :func:`load_yaml` (a key given twice and an integer too long to
    convert are :class:`yaml.YAMLError`)."""
    return yaml.load(text, Loader=_UniqueKeyLoader)  # noqa: S506 (a SafeLoader)


def load_yaml(path: str | Path) -> dict:
    """Load a YAML mapping (an empty file is an empty one).

    Raises
    ------
    InputError
        For a missing or unreadable file, YAML that does not parse (with its line), a key given twice in one
        mapping, or a document that is not a mapping.
    """
    path = check_file(path)
    try:
        with open(path, encoding="utf-8") as f:
            text = f.read()
        # EuRoC files start with a '%YAML:1.0' directive that PyYAML does not accept
        if text.startswith("%YAML:"):
            text = text.split("\n", 1)[1] if "\n" in text else ""
        data = load_yaml_text(text)
    except yaml.YAMLError as exc:
        line = getattr(getattr(exc, "problem_mark", None), "line", None)
        raise InputError(f"not valid YAML ({getattr(exc, 'problem', exc)})", path,
                         None if line is None else line + 1) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read file ({exc})", path) from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise InputError("expected a YAML mapping of keys to values", path)
    return data


def write_yaml_atomic(path: str | Path, data: dict) -> None:
    """Write a YAML file under a temporary name, then rename it into place (mode from the umask)."""
    path = Path(path)
    make_folder(path.parent)
    write_atomic(path, yaml.safe_dump(data, sort_keys=False, default_flow_style=None))


def validate(model: type[M], data: Any, path: str | Path | None = None, prefix: tuple = ()) -> M:
    """Check a mapping read from a file against ``model`` and build it.

    A section left empty (``fusion:`` with every line below it commented out, which YAML reads as null) keeps
    its defaults, like a section left out.

    Parameters
    ----------
    model : type of BaseModel
        The configuration (a :class:`~fusion_vo.config.base.Section`).
    data : mapping or None
        The values; None is an empty mapping.
    path : str or Path, optional
        The file they were read from (named in the error).
    prefix : tuple of str
        The key path of ``data`` in that file (``("fusion",)`` for its ``fusion`` section).

    Raises
    ------
    InputError
        For an unknown key, a value of the wrong type or out of its range, or a combination the model rejects:
        one line naming ``path``, the key path and what was expected (:func:`frontends.config.describe_error`).
    """
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise InputError(f"{location(prefix) or 'the file'}: expected a mapping of key: value, got {shown(data)}", path)
    try:
        return model.model_validate(drop_empty_sections(model, data))
    except ValidationError as exc:
        raise InputError(one_line(exc, model, prefix), path) from None


def drop_empty_sections(model: type[BaseModel], data: dict) -> dict:
    """``data`` without the keys of ``model``'s sections (fields that are models) whose value is None, at
    every depth."""
    out = {}
    for key, value in data.items():
        field = model.model_fields.get(key) if isinstance(key, str) else None
        sub = getattr(field, "annotation", None)
        if inspect.isclass(sub) and issubclass(sub, BaseModel):
            if value is None:
                continue
            if isinstance(value, dict):
                value = drop_empty_sections(sub, value)
        out[key] = value
    return out
