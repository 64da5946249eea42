"""Smoke test of the example scripts: each runs in its ``--quick`` mode and prints tables with sane numbers.

The scripts are run as a user runs them (``python examples/NAME.py --quick --seed 1 --out DIR``, started in the
background from the session's start by ``conftest.py``); their printed tables are read back and checked against
loose accuracy bounds, so a script that runs but reports nonsense (NaN, a frontend that fails every frame, errors
of tens of percent) fails the test.
"""

import math
import re
from pathlib import Path

import pytest

#: each test's example script, run from the session's start in the background (tests/background.py)
BACKGROUND_JOBS = {"test_table_5_1": ["example:thesis_table_5_1"], "test_square": ["example:thesis_square"],
                   "test_heading": ["example:thesis_heading"], "test_klt_zero_motion": ["example:klt_zero_motion"],
                   "test_fusion_comparison": ["example:fusion_comparison"]}

def table(text: str, title_start: str) -> list[dict[str, str]]:
    """Rows of the printed table whose title line starts with ``title_start`` (header -> cell)."""
    lines = text.splitlines()
    starts = [i for i, s in enumerate(lines) if s.startswith(title_start)]
    assert starts, f"no table titled {title_start!r} in:\n{text}"
    i = starts[0]
    headers = re.split(r"\s{2,}", lines[i + 1].strip())
    assert set(lines[i + 2].replace(" ", "")) == {"-"}, lines[i + 2]
    rows = []
    for line in lines[i + 3:]:
        if not line.strip():
            break
        cells = re.split(r"\s{2,}", line.strip())
        assert len(cells) == len(headers), (headers, line)
        rows.append(dict(zip(headers, cells)))
    assert rows, f"table {title_start!r} has no rows"
    return rows


def is_png(path: Path) -> bool:
    """Whether ``path`` is a PNG file of a real figure (not an empty canvas)."""
    return path.is_file() and path.stat().st_size > 10_000 and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def number(cell: str) -> float:
    value = float(cell)
    assert math.isfinite(value), cell
    return value


@pytest.mark.slow
def test_table_5_1(example):
    text, _ = example("thesis_table_5_1")
    rows = table(text, "Table 5.1")
    assert {r["lighting"] for r in rows} == {"good light", "spotlights", "dark"}
    assert {r["frontend"] for r in rows} == {"klt", "features", "plain script"}
    for r in rows:
        if r["frontend"] == "plain script":  # the baseline, scored the same way (it loses the fast quick circle)
            assert number(r["error %"]) >= 0.0, r
            continue
        frames, failed = int(r["frames"]), int(r["failed"])
        assert frames > 20 and failed <= frames // 4, r
        assert 0.0 <= number(r["error %"]) < 10.0, r
        assert number(r["variance %"]) >= 0.0, r
    good = [number(r["error %"]) for r in rows if r["lighting"] == "good light" and r["frontend"] != "plain script"]
    assert max(good) < 3.0


@pytest.mark.slow
def test_square(example):
    text, out = example("thesis_square")
    legs = table(text, "Table 5.2")
    assert len(legs) == 4
    for leg in legs:
        assert number(leg["actual cm"]) > 10.0
        for frontend in ("klt", "features"):
            assert number(leg[f"{frontend} err %"]) < 2.0, leg
        assert number(leg["thesis err %"]) > 1.0
    whole = table(text, "Whole square")
    assert [r["frontend"] for r in whole] == ["klt", "features"]
    assert all(number(r["end %"]) < 1.0 for r in whole), whole
    assert is_png(out / "square.png")


@pytest.mark.slow
def test_heading(example):
    text, out = example("thesis_heading")
    rows = table(text, "Heading after one full circle")
    assert [r["frontend"] for r in rows] == ["klt", "features"]
    for r in rows:
        assert number(r["turned deg"]) > 350.0
        assert number(r["error deg"]) < 1.0, r
        assert abs(number(r["error %"]) - 100 * number(r["error deg"]) / number(r["turned deg"])) < 1e-3
    assert is_png(out / "heading.png")


@pytest.mark.slow
def test_klt_zero_motion(example):
    text, out = example("klt_zero_motion")
    corners = {r["lighting"]: r for r in table(text, "Figures 3.3-3.5")}
    assert set(corners) == {"good light", "spotlights", "dark"}
    for r in corners.values():
        assert int(r["tracked to end"]) >= 10, r
        assert number(r["max step px"]) < 1.0, r
    assert number(corners["good light"]["max step px"]) < 0.1
    rows = table(text, "Estimated motion per frame")
    assert len(rows) == 6
    for r in rows:
        assert int(r["failed"]) == 0, r
        assert number(r["max mm/frame"]) < 0.1, r
        assert r["< 0.1 mm"] == "yes"
    assert is_png(out / "klt_zero_motion.png")


@pytest.mark.slow
def test_fusion_comparison(example):
    text, out = example("fusion_comparison")
    rows = table(text, "Fusion comparison")
    by_name = {r["trajectory"]: r for r in rows}
    assert set(by_name) == {"vo", "wheel", "ekf", "ekf_smoothed", "gtsam", "gtsam_online"}
    for r in rows:
        assert number(r["ATE m"]) >= 0.0, r
        assert number(r["end %"]) >= 0.0, r
    fused = min(number(by_name[n]["ATE m"]) for n in ("ekf", "ekf_smoothed", "gtsam"))
    assert fused <= number(by_name["wheel"]["ATE m"])
    assert (out / "run-klt" / "metrics.json").is_file()
