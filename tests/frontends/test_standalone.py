"""The frontends are a package of their own: image in, similarity out, nothing of fusion_vo."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

from frontends.direct import DirectConfig
from frontends.features import FeatureConfig
from frontends.klt import KltConfig
from frontends.similarity import RobustOptions
from fusion_vo.config.render import json_schema

#: run in a fresh interpreter in which importing fusion_vo fails
STANDALONE = textwrap.dedent("""
    import importlib, pkgutil, sys

    class NoFusionVo:
        def find_spec(self, name, path=None, target=None):
            if name == "fusion_vo" or name.startswith("fusion_vo."):
                raise ImportError(f"the frontends imported {name}")
            return None

    sys.meta_path.insert(0, NoFusionVo())
    import cv2
    import numpy as np
    import frontends

    names = sorted(m.name for m in pkgutil.iter_modules(frontends.__path__))
    for name in names:
        importlib.import_module("frontends." + name)

    # a smooth random texture, and the same texture 3.25 px to the right and 1.5 px down
    rng = np.random.default_rng(1)
    big = cv2.GaussianBlur(rng.uniform(0, 255, (600, 800)).astype(np.float32), (0, 0), 2.0)
    big = cv2.normalize(big, None, 0, 255, cv2.NORM_MINMAX)
    shift = np.array([[1.0, 0.0, 3.25], [0.0, 1.0, 1.5]])
    first = big[100:460, 80:720].astype(np.uint8)
    second = cv2.warpAffine(big, shift, (800, 600), flags=cv2.INTER_LINEAR)[100:460, 80:720].astype(np.uint8)
    for kind in ("klt", "features", "direct"):
        frontend = frontends.make_frontend(kind)
        assert frontend.process(first, 0.0).status.value == "first"
        motion = frontend.process(second, 0.1)
        assert motion.ok, (kind, motion.info)
        print(kind, round(float(motion.matrix[0, 2]), 3), round(float(motion.matrix[1, 2]), 3),
              round(float(motion.params[2]), 6), round(float(motion.params[3]), 6))
    loaded = sorted(m for m in sys.modules if m.split(".")[0] == "fusion_vo")
    print("modules", len(names), "fusion_vo", loaded)
""")


def test_frontends_import_and_run_without_fusion_vo():
    out = subprocess.run([sys.executable, "-c", STANDALONE], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert lines[-1].startswith("modules ") and lines[-1].endswith(" fusion_vo []")
    assert int(lines[-1].split()[1]) >= 20  # every module of the package was imported
    for line in lines[:-1]:
        kind, tx, ty, angle, log_scale = line.split()
        assert abs(float(tx) - 3.25) < 0.05 and abs(float(ty) - 1.5) < 0.05, line
        assert abs(float(angle)) < 1e-3 and abs(float(log_scale)) < 1e-3, line
    assert [line.split()[0] for line in lines[:-1]] == ["klt", "features", "direct"]


@pytest.mark.parametrize("model, work", [(KltConfig, "max_tracks"), (FeatureConfig, "max_corners"),
                                         (DirectConfig, "finest_iterations"), (RobustOptions, "max_iterations")])
def test_every_integer_setting_has_an_upper_bound(model, work):
    """A setting that sets how much work is done (tracks, corners, levels, iterations, windows) has an upper
    bound: ``max_tracks: 1e11`` was accepted and then failed every frame inside OpenCV."""
    integers = {}
    for name, prop in json_schema(model)["properties"].items():
        number = next((p for p in prop.get("anyOf", [prop]) if p.get("type") == "integer"), None)
        if number is not None:
            integers[name] = number
    assert work in integers
    assert [name for name, number in integers.items() if "maximum" not in number] == (
        ["seed"] if "seed" in integers else [])


@pytest.mark.parametrize("values, message", [
    ({"grid_cell": 1e-9}, "KltConfig: grid_cell must be 0 (no grid) or at least 16 px, not 1e-09"),
    ({"max_tracks": 100_000_000_000}, "KltConfig: max_tracks must be at most 10000, not 100000000000"),
    ({"lk_iterations": 0}, "KltConfig: lk_iterations must be at least 1, not 0"),
    ({"window": 14}, "KltConfig: window must be an odd number, not 14"),
    ({"max_tracks": True}, "KltConfig: max_tracks: expected an integer, got True"),
    ({"min_texture": float("nan")}, "KltConfig: min_texture must be a finite number, not nan"),
    ({"replenish_below": 80}, "KltConfig: need min_inliers <= replenish_below <= max_tracks"),
    ({"bogus": 1}, "KltConfig: bogus: unknown key (known: max_tracks, "),
])
def test_a_library_user_gets_one_line_naming_the_key(values, message):
    with pytest.raises(ValueError) as err:
        KltConfig(**values)
    assert str(err.value).startswith(message) and "\n" not in str(err.value)
    with pytest.raises(ValueError) as again:
        KltConfig.from_dict(values)
    assert str(again.value) == str(err.value)


def test_settings_are_immutable_and_round_trip():
    config = FeatureConfig(neighbourhood=7, detector="fast")
    assert config.neighbourhood == (7, 7)
    assert FeatureConfig.from_dict(config.to_dict()) == config
    with pytest.raises(ValueError):
        config.detector = "harris"
    assert KltConfig().to_dict()["max_tracks"] == 60
