"""Parameter sweeps: which configuration keys to vary and the values to try (``GRID.yaml``).

A grid file names configuration keys as dotted paths into the run configuration
(``fusion-vo run --print-config`` lists them), and either every combination of values::

    grid:
      features.detector: [harris, shi_tomasi]
      features.harris_k: [0.04, 0.08]

or ``random: N`` samples from ranges (a mapping ``{low, high}``, with ``log: true`` for a log-uniform
draw; integers when both bounds are integers) or from a list of choices::

    random: 20
    seed: 0
    ranges:
      features.harris_k: {low: 0.01, high: 0.2, log: true}
      features.max_corners: {low: 50, high: 400}
      features.detector: [harris, shi_tomasi, fast]

An optional ``fixed:`` mapping sets keys to one value in every parameter set (e.g.
``fixed: {frontend: features}``). Every key and every parameter set is checked against the
configuration schema (:class:`fusion_vo.config.RunConfig`) before anything runs. A grid file gives at
most :data:`MAX_SETS` parameter sets.

A swept key of a frontend's section (``klt.*``, ``features.*``, ``direct.*``) must be one the runs use:
sweeping ``features.ratio`` while every run uses the KLT frontend would only run the same set again, so
it is an error naming the key and the frontend the runs use. When the grid also varies ``frontend``, a
set whose frontend does not use the key gets no value of it (empty in ``results.csv``; the set's
configuration keeps the base's), and the sets that then coincide run once: only the sets whose frontend
uses the key differ in it.

A swept value may be a list (``fusion.initial_pose: [[0, 0, 0], [1, 0, 0]]``): ``results.csv``, the
report and the ranking show it as its canonical JSON text (:func:`cell_value`). A mapping is no value to
sweep (``klt: [{max_tracks: 60}]`` would replace the whole section, losing the base's other keys of it):
it is an error naming the key, and its keys are swept one by one instead (``klt.max_tracks: [60]``).
"""

from __future__ import annotations

import itertools
import json
import logging
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from fusion_vo.config import FRONTENDS
from fusion_vo.config.files import load_yaml, load_yaml_text
from fusion_vo.config.run import RunConfig, default_config_text, validate_config
from fusion_vo.errors import InputError

log = logging.getLogger(__name__)

#: the sections of a grid file
GRID_SECTIONS = ("grid", "random", "seed", "ranges", "fixed")

#: most parameter sets a grid file may give (``random: N``, the combinations of ``grid:``, ``--trials``):
#: each set is made and checked before anything runs (some 7 ms each) and runs on every recording
MAX_SETS = 10000


@dataclass(frozen=True)
class ParameterSet:
    """One point of a sweep.

    Attributes
    ----------
    name : str
        Short identifier (``p000``, ``p001``, ...), also the name of its run folders.
    values : dict
        Dotted configuration key -> value (the swept keys only).
    """

    name: str
    values: dict


def _schema() -> dict:
    """The full default configuration as a nested mapping (the known keys)."""
    return load_yaml_text(default_config_text())


def check_key(key: str, path: Path | None, schema: dict | None = None) -> None:
    """Raise :class:`InputError` unless ``key`` is a dotted path into the run configuration.

    A key inside a section whose default is an empty mapping (``fusion``: options passed to the
    backends) is accepted here and checked when the configuration is built.
    """
    schema = _schema() if schema is None else schema
    if not isinstance(key, str) or not key or any(not part for part in key.split(".")):
        raise InputError(f"'{key}' is not a configuration key (use dotted paths such as features.harris_k)", path)
    node = schema
    walked = []
    for part in key.split("."):
        if isinstance(node, dict) and not node and walked:  # an open section
            return
        if not isinstance(node, dict) or part not in node:
            where = ".".join(walked) or "the configuration"
            known = ", ".join(sorted(node)) if isinstance(node, dict) else "none: it is a value"
            raise InputError(f"unknown configuration key '{key}' ('{part}' is not in {where}; known: {known})", path)
        node = node[part]
        walked.append(part)


def config_data(config: RunConfig) -> dict:
    """The full configuration as plain data (what a task carries and the cache key hashes)."""
    return config.to_dict()


def build_config(data: dict, path: Path | None = None) -> RunConfig:
    """A validated :class:`RunConfig` from plain data (the inverse of :func:`config_data`): every section, the
    frontend that is not selected included, is checked."""
    return validate_config(data, path)


def _set_dotted(config: dict, key: str, value) -> None:
    node = config
    parts = key.split(".")
    for part in parts[:-1]:
        if node.get(part) is None:
            node[part] = {}
        node = node[part]
    node[parts[-1]] = value


def apply_values(base: RunConfig, values: dict, path: Path | None = None) -> RunConfig:
    """A copy of ``base`` with the dotted keys of ``values`` set, validated by the configuration schema.

    Raises
    ------
    InputError
        Naming ``path`` and the key, for an unknown key or a value the configuration rejects.
    """
    data = config_data(base)
    for key, value in values.items():
        _set_dotted(data, key, value)
    keys = describe(values)
    try:
        config = build_config(data, path)
    except InputError as exc:
        raise InputError(f"{exc.message} (parameter set {keys})", path) from None
    except (TypeError, ValueError) as exc:
        raise InputError(f"{str(exc).splitlines()[0]} (parameter set {keys})", path) from None
    return config


def describe(values: dict) -> str:
    """``key=value, ...`` of a parameter set."""
    return ", ".join(f"{k}={cell_value(v)}" for k, v in values.items())


def check_value(key: str, value, path: Path | None, line: int | None = None) -> None:
    """Raise :class:`InputError` naming ``key`` for a swept value that is a mapping (module docstring)."""
    if isinstance(value, dict):
        inner = f"{key}.{next(iter(value))}" if value else f"{key}.KEY"
        raise InputError(f"grid key '{key}': the value {value!r} is a mapping, which would replace the whole "
                         f"section; sweep the keys inside it one by one (e.g. '{inner}')", path, line)


def cell_value(value):
    """A swept value as a table cell: a list as its canonical JSON text (hashable, one column), else as is."""
    if isinstance(value, (list, tuple)):
        return json.dumps(_plain_tree(value), sort_keys=True)
    return _plain(value)


def _plain_tree(value):
    if isinstance(value, (list, tuple)):
        return [_plain_tree(v) for v in value]
    return _plain(value)


def _as_list(key: str, values, path: Path | None) -> list:
    if isinstance(values, (list, tuple)):
        if not values:
            raise InputError(f"grid key '{key}' has no values to try", path)
        firsts: dict[str, int] = {}
        for i, value in enumerate(values):
            check_value(key, value, path, _item_line(path, "grid", key, i))
            first = firsts.setdefault(yaml.safe_dump(_plain(value), sort_keys=True), i)
            if first != i:  # every combination would be run twice, or silently once
                raise InputError(f"grid key '{key}': value {value!r} given twice (values {first + 1} and {i + 1})",
                                 path, _item_line(path, "grid", key, i))
        return list(values)
    check_value(key, values, path)
    return [values]


def _item_line(path: Path | None, section: str, key: str, index: int) -> int | None:
    """The line (1-based) of item ``index`` of ``section: {key: [...]}`` in the YAML file ``path``, if found."""
    try:
        root = yaml.compose(Path(path).read_text(encoding="utf-8")) if path is not None else None
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return None
    for node in (section, key):
        if not isinstance(root, yaml.MappingNode):
            return None
        root = next((v for k, v in root.value if isinstance(k, yaml.ScalarNode) and k.value == node), None)
    if not isinstance(root, yaml.SequenceNode) or index >= len(root.value):
        return None
    return root.value[index].start_mark.line + 1


def _draw(key: str, spec, rng: np.random.Generator, path: Path | None):
    if isinstance(spec, (list, tuple)):
        if not spec:
            raise InputError(f"range '{key}' has no choices", path)
        for i, choice in enumerate(spec):
            check_value(key, choice, path, _item_line(path, "ranges", key, i))
        return spec[int(rng.integers(len(spec)))]
    if isinstance(spec, dict):
        unknown = sorted(set(spec) - {"low", "high", "log"})
        if unknown or "low" not in spec or "high" not in spec:
            raise InputError(f"range '{key}' must be {{low: A, high: B}} (optionally log: true) or a list of choices", path)
        low, high, use_log = spec["low"], spec["high"], bool(spec.get("log", False))
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in (low, high)):
            raise InputError(f"range '{key}': low and high must be finite numbers", path)
        if low > high or (use_log and low <= 0):
            raise InputError(f"range '{key}': needs low <= high (and low > 0 with log: true)", path)
        if isinstance(low, int) and isinstance(high, int):
            if use_log:
                return int(round(math.exp(rng.uniform(math.log(low), math.log(high)))))
            return int(rng.integers(low, high + 1))
        if use_log:
            return float(math.exp(rng.uniform(math.log(low), math.log(high))))
        return float(rng.uniform(low, high))
    raise InputError(f"range '{key}' must be {{low: A, high: B}} or a list of choices", path)


def _section_of(key: str) -> str | None:
    """The frontend whose section the dotted ``key`` is in (``features.ratio`` -> ``features``), or None."""
    section = key.split(".", 1)[0]
    return section if section in FRONTENDS and "." in key else None


def check_frontend_keys(keys, frontends, path: Path | None) -> None:
    """Raise :class:`InputError` for a swept key of a frontend section none of ``frontends`` (the frontends
    the runs use) reads: every value of it would run the same parameter set."""
    used = sorted(set(frontends), key=FRONTENDS.index)
    for key in keys:
        section = _section_of(key)
        if section is not None and section not in used:
            runs = f"the {used[0]} frontend" if len(used) == 1 else f"the {' and '.join(used)} frontends"
            hint = (f"set 'frontend: {section}' under fixed:, or sweep frontend too" if len(used) == 1
                    else f"add {section} to the frontends swept")
            raise InputError(f"grid key '{key}' is an option of the {section} frontend, but the runs use {runs}: "
                             f"its values would run the same parameter set ({hint})", path)


def _without_unused(combos: list[dict], fixed: dict, base: RunConfig, path: Path | None) -> list[tuple[dict, set]]:
    """Each combination with the set of its keys that its frontend does not read (module docstring); raises
    :class:`InputError` for a frontend key no run reads."""
    keys = list(combos[0]) if combos else []
    frontends = [values.get("frontend", fixed.get("frontend", base.frontend)) for values in combos]
    if not all(isinstance(f, str) and f in FRONTENDS for f in frontends):
        return [(values, set()) for values in combos]  # a frontend the configuration rejects: apply_values says so
    check_frontend_keys(keys, frontends, path)
    return [(values, {k for k in keys if _section_of(k) not in (None, frontend)})
            for values, frontend in zip(combos, frontends)]


def _plain(value):
    """NumPy scalars as Python values (for YAML, JSON and the configuration)."""
    return value.item() if isinstance(value, np.generic) else value


@dataclass
class Grid:
    """A parsed grid file: the parameter sets to run, each already validated.

    Attributes
    ----------
    keys : list of str
        The swept keys, in file order (the extra columns of ``results.csv``).
    sets : list of ParameterSet
    configs : list of RunConfig
        The full configuration of each parameter set.
    path : Path or None
        The grid file (for messages).
    drawn : int
        Parameter sets drawn by ``random: N`` before repeated draws were merged (0 for ``grid:``).
    """

    keys: list[str]
    sets: list[ParameterSet]
    configs: list[RunConfig]
    path: Path | None = None
    drawn: int = 0


def parse_grid(data: dict, base: RunConfig, path: Path | None = None) -> Grid:
    """Expand and validate a grid mapping (the contents of ``GRID.yaml``) on top of ``base``."""
    unknown = sorted(set(data) - set(GRID_SECTIONS))
    if unknown:
        raise InputError(f"unknown grid section '{unknown[0]}' (known: {', '.join(GRID_SECTIONS)})", path)
    has_grid, has_random = data.get("grid") is not None, data.get("random") is not None
    if has_grid == has_random:
        raise InputError("a grid file needs exactly one of 'grid:' (every combination) or 'random: N' with 'ranges:'", path)
    schema = _schema()
    fixed = data.get("fixed") or {}
    if not isinstance(fixed, dict):
        raise InputError("'fixed' must be a mapping of key: value", path)
    for key in fixed:
        check_key(key, path, schema)
    if has_grid:
        grid = data["grid"]
        if not isinstance(grid, dict) or not grid:
            raise InputError("the grid is empty: 'grid:' must map configuration keys to lists of values", path)
        for key in grid:
            check_key(key, path, schema)
        keys = list(grid)
        lists = [_as_list(k, grid[k], path) for k in keys]
        count = math.prod(len(values) for values in lists)
        if count > MAX_SETS:
            raise InputError(f"'grid' gives {count} parameter sets (the product of its keys' numbers of values), "
                             f"more than {MAX_SETS}: try fewer values, or 'random: N' samples", path)
        combos = [dict(zip(keys, combo)) for combo in itertools.product(*lists)]
    else:
        n = data["random"]
        if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_SETS:
            raise InputError(f"'random' must be a number of samples from 1 to {MAX_SETS}, not {n!r}",
                             path)
        ranges = data.get("ranges")
        if not isinstance(ranges, dict) or not ranges:
            raise InputError("the grid is empty: 'random: N' needs 'ranges:' mapping configuration keys to ranges", path)
        for key in ranges:
            check_key(key, path, schema)
        seed = data.get("seed", 0)
        if isinstance(seed, bool) or not isinstance(seed, int):
            raise InputError(f"'seed' must be an integer, not {seed!r}", path)
        rng = np.random.default_rng(seed)
        keys = list(ranges)
        combos = [{k: _plain(_draw(k, ranges[k], rng, path)) for k in keys} for _ in range(n)]
    overlap = sorted(set(fixed) & set(keys))
    if overlap:
        raise InputError(f"key '{overlap[0]}' is both fixed and swept", path)
    sets, configs, seen = [], [], set()
    width = max(3, len(str(len(combos) - 1)))
    for values, unused in _without_unused(combos, fixed, base, path):
        shown = {k: (None if k in unused else v) for k, v in values.items()}
        marker = yaml.safe_dump(shown, sort_keys=True)
        if marker in seen:  # random draws of choices can repeat, and so can sets without their unused keys
            continue
        seen.add(marker)
        configs.append(apply_values(base, {**fixed, **{k: v for k, v in values.items() if k not in unused}}, path))
        sets.append(ParameterSet(f"p{len(sets):0{width}d}", shown))
    log.info("%d parameter sets over %s", len(sets), ", ".join(keys))
    return Grid(keys=keys, sets=sets, configs=configs, path=path, drawn=0 if has_grid else len(combos))


def load_grid(path: str | Path, base: RunConfig) -> Grid:
    """Read and expand ``GRID.yaml``; errors name the file and the key."""
    path = Path(path)
    return parse_grid(load_yaml(path), base, path)
