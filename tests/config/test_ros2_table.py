"""docs/ros2.md's table of node parameters is the node's settings model: every field once, with its default."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from fusion_vo.ros2.settings import ROS_PARAMETERS, NodeConfig

PAGE = Path(__file__).resolve().parents[2] / "docs" / "ros2.md"
#: how the table writes a default that is not a number
WORDS = {"none": None, "empty": "", "false": False, "true": True}


def table() -> dict[str, str]:
    """``parameter -> default`` as the table writes it (a row naming two parameters ``a`` / ``b`` with defaults
    ``x`` / ``y``, or several with one default, gives each its own)."""
    text = PAGE.read_text()
    rows = text[text.index("| parameter (`ros2:` key) |"):].split("\n\n")[0].splitlines()[2:]
    out = {}
    for row in rows:
        names_cell, default_cell = (c.strip() for c in row.strip("|").split("|")[:2])
        names = re.findall(r"`([a-z_]+)`", names_cell)
        defaults = [d.strip().strip("`") for d in default_cell.split(" / ")]
        if len(defaults) == 1:
            defaults *= len(names)
        assert len(defaults) == len(names), row
        out.update(zip(names, defaults))
    return out


def _value(written: str):
    if written in WORDS:
        return WORDS[written]
    try:
        return float(written)
    except ValueError:
        return written


def test_the_pages_table_names_every_node_setting_with_its_default():
    written = table()
    fields = NodeConfig.model_fields
    assert set(written) - set(ROS_PARAMETERS) == set(fields), sorted(set(written) ^ set(fields))
    for name, field in fields.items():
        default, value = field.default, _value(written[name])
        if name in ("calibration", "trajectory_file"):  # a path: none unless given
            assert value in (None, "") and not default, (name, written[name], default)
        elif isinstance(default, (int, float)) and not isinstance(default, bool):
            assert value == pytest.approx(float(default)), (name, written[name], default)
        else:
            assert value == default, (name, written[name], default)
