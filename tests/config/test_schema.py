"""The one configuration schema: validation messages, --print-config, --print-schema."""

from __future__ import annotations

import json

import pytest
import yaml
from pydantic import BaseModel, Field, model_validator

from frontends.klt import KltConfig
from fusion_vo.backends.config import FusionConfig
from fusion_vo.cli.main import main
from fusion_vo.config import RunConfig, default_config_text, load_config, run_model, schema_text
from fusion_vo.config.base import ConfigError, Section
from fusion_vo.config.files import validate
from fusion_vo.config.render import json_schema, section_view
from fusion_vo.errors import InputError


def _load(tmp_path, text):
    path = tmp_path / "run.yaml"
    path.write_text(text)
    return path, load_config(path)


@pytest.mark.parametrize("text, message", [
    ("fusion:\n  ekf:\n    accel_sigma: abc\n", "run.yaml: fusion.ekf.accel_sigma: expected a number, got 'abc'"),
    ("klt:\n  max_tracks: 2.5\n", "run.yaml: klt.max_tracks: expected an integer, got 2.5"),
    ("klt:\n  max_tracks: true\n", "run.yaml: klt.max_tracks: expected an integer, got True"),
    ("fusion:\n  camera_height: false\n", "run.yaml: fusion.camera_height: expected a number, got False"),
    ("fusion:\n  graph:\n    batch: maybe\n", "run.yaml: fusion.graph.batch: expected true or false, got 'maybe'"),
    ("fusion:\n  ekf:\n    gate: 3\n", "run.yaml: fusion.ekf.gate: unknown key (known: accel_sigma, "),
    ("frontned: klt\n", "run.yaml: frontned: unknown key (known: frontend, sensors, backend, "),
    ("frontend: orb\n", "run.yaml: frontend: expected one of 'klt', 'features' or 'direct', got 'orb'"),
    ("sensors: camera,laser\n", "run.yaml: sensors[1]: expected one of 'camera', "),
    ("fusion: 3\n", "run.yaml: fusion: expected a mapping of key: value, got 3"),
    ("klt:\n  window: 6\n", "run.yaml: klt: window must be an odd number, not 6"),
    ("klt:\n  window: 4\n", "run.yaml: klt: window must be at least 5, not 4"),
    ("klt:\n  grid_cell: 1.0e-9\n", "run.yaml: klt: grid_cell must be 0 (no grid) or at least 16 px, not 1e-09"),
    ("fusion:\n  graph:\n    robust: tukey\n",
     "run.yaml: fusion.graph.robust: expected one of 'huber', 'cauchy' or 'none', got 'tukey'"),
    ("fusion:\n  graph:\n    reweight_passes: 11\n", "run.yaml: fusion.graph: reweight_passes must be at most 10, not 11"),
    ("odometry:\n  height: high\n", "run.yaml: odometry.height: expected a number, got 'high'"),
])
def test_errors_name_file_key_path_and_expected_type(tmp_path, text, message):
    with pytest.raises(InputError) as err:
        _load(tmp_path, text)
    assert message in str(err.value)
    assert str(err.value).startswith(str(tmp_path / "run.yaml") + ": ")


def test_bad_config_exits_2_with_one_line(tmp_path, capsys):
    path = tmp_path / "run.yaml"
    path.write_text("fusion:\n  ekf:\n    accel_sigma: abc\n")
    assert main(["run", str(tmp_path), "--out", str(tmp_path / "out"), "--config", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"fusion-vo: error: {path}: fusion.ekf.accel_sigma: expected a number, got 'abc'"]
    assert not (tmp_path / "out").exists()


def test_values_reach_the_stages(tmp_path):
    _, cfg = _load(tmp_path, "frontend: features\nsensors: camera, wheel\nfeatures: {max_corners: 90}\n"
                             "fusion:\n  ekf: {accel_sigma: 2}\n  odom: {k: 0.05}\n")
    assert cfg.sensors == ["camera", "wheel"]
    odo = cfg.odometry_config()
    assert odo.frontend == "features" and odo.frontend_options["max_corners"] == 90
    fusion = cfg.fusion
    assert isinstance(fusion, FusionConfig) and fusion.ekf.accel_sigma == 2.0
    # a partial section keeps the defaults of that section, not of its class
    default_odom = FusionConfig().odom
    assert fusion.odom.k == 0.05 and fusion.odom.yaw_scale == default_odom.yaw_scale != 0.0
    assert fusion.wheel == FusionConfig().wheel


def test_print_config_lists_every_option_and_loads_back(tmp_path):
    text = default_config_text()
    data = yaml.safe_load(text)

    def names(cls, prefix=""):
        for name, field in cls.model_fields.items():
            if isinstance(field.annotation, type) and issubclass(field.annotation, BaseModel):
                yield from names(field.annotation, f"{prefix}{name}.")
            else:
                yield prefix + name

    def lookup(d, dotted):
        for part in dotted.split("."):
            d = d[part]
        return d

    for name in names(FusionConfig):
        assert lookup(data["fusion"], name) is not None or name == "camera_height"
    assert data["fusion"]["states"]["wheel_curvature"]["sigma"] == 0.05  # a registered sensor's state, its prior
    assert set(data["klt"]) == set(KltConfig.model_fields)
    assert data["fusion"]["odom"]["yaw_scale"] == FusionConfig().odom.yaw_scale
    assert "# Forward acceleration noise of the constant-twist model [m/s²·√s]" in text
    path = tmp_path / "printed.yaml"
    path.write_text(text)
    empty = tmp_path / "empty.yaml"
    empty.write_text("")
    assert load_config(path) == load_config(empty)
    assert load_config(empty).fusion.ekf.accel_sigma == 0.5


def test_print_config_and_schema_commands(tmp_path, capsys):
    assert main(["run", "--print-schema"]) == 0
    json_schema = json.loads(capsys.readouterr().out)
    assert json_schema == json.loads(schema_text())
    ekf = json_schema["$defs"]["EkfConfig"]["properties"]["accel_sigma"]
    assert ekf["type"] == "number" and ekf["default"] == 0.5 and ekf["unit"] == "m/s²·√s"
    assert json_schema["$defs"]["EkfConfig"]["additionalProperties"] is False
    path = tmp_path / "run.yaml"
    path.write_text("fusion: {ekf: {accel_sigma: 2.5}}\n")
    assert main(["run", "--print-config", "--config", str(path)]) == 0
    printed = yaml.safe_load(capsys.readouterr().out)
    assert printed["fusion"]["ekf"]["accel_sigma"] == 2.5 and printed["fusion"]["ekf"]["smoother"] is True


class _Demo(Section):
    """A stage's options."""

    speed: float = Field(1.0, gt=0, description="Top speed [m/s].")
    lo: int = Field(0, description="Lower bound.")
    hi: int = Field(3, description="Upper bound.")

    @model_validator(mode="after")
    def _ordered(self):
        if self.lo > self.hi:
            raise ValueError("need lo <= hi")
        return self


def test_a_section_states_its_fields_and_names_the_key_of_a_mistake(tmp_path):
    props = json_schema(_Demo)["properties"]
    assert props["speed"]["description"] == "Top speed [m/s]." and props["speed"]["unit"] == "m/s"
    assert props["speed"]["exclusiveMinimum"] == 0
    assert validate(_Demo, {"speed": 2}) == _Demo(speed=2.0)
    path = tmp_path / "f.yaml"
    with pytest.raises(InputError, match=r"f\.yaml: stage: need lo <= hi$"):
        validate(_Demo, {"lo": 5}, path, prefix=("stage",))
    with pytest.raises(InputError, match=r"^stage\.speed: expected a number, got \[1\]$"):
        validate(_Demo, {"speed": [1]}, prefix=("stage",))
    with pytest.raises(InputError, match=r"^stage: speed must be positive, not 0$"):
        validate(_Demo, {"speed": 0}, prefix=("stage",))
    with pytest.raises(ConfigError, match=r"^_Demo: need lo <= hi$"):  # built in Python: the class names it
        _Demo(lo=5)
    assert _Demo().merged({"hi": 7}) == _Demo(hi=7)
    with pytest.raises(ConfigError, match=r"^_Demo: fast: unknown key \(known: speed, lo, hi\)$"):
        _Demo().merged({"fast": 1})


def test_run_config_checks_programmatic_values():
    RunConfig(fusion={"ekf": {"accel_sigma": 1.0}})
    with pytest.raises(ValueError, match=r"^RunConfig: fusion\.ekf\.accel_sigma: expected a number, got 'fast'$"):
        RunConfig(fusion={"ekf": {"accel_sigma": "fast"}})
    assert set(run_model().model_fields) == set(RunConfig.model_fields)
    config = RunConfig(sensors="camera, wheel")  # one string names several, as on the command line
    assert config.sensors == ["camera", "wheel"]
    assert RunConfig.from_dict(config.to_dict()) == config  # run.yaml reads back as the configuration


def test_simulate_prints_its_options_and_reads_them_back(tmp_path, capsys):
    assert main(["simulate", "--standard", "hard", "--print-config", "-O", "noise=2.5"]) == 0
    printed = capsys.readouterr().out
    data = yaml.safe_load(printed)
    assert data["noise"] == 2.5 and data["duration"] == 40.0 and data["width"] == 640
    assert data["profile"] == "random" and data["seed"] == 5  # the drive itself, not only its options
    path = tmp_path / "sim.yaml"
    path.write_text(printed)
    assert main(["simulate", "--config", str(path), "--print-config"]) == 0
    assert yaml.safe_load(capsys.readouterr().out) == data
    assert main(["simulate", "--print-config", "-O", "width=wide"]) == 2
    assert capsys.readouterr().err.strip() == "fusion-vo: error: width: expected an integer, got 'wide'"
    assert main(["simulate"]) == 2
    assert "needs an output folder" in capsys.readouterr().err


def test_empty_sections_keep_their_defaults(tmp_path):
    _, cfg = _load(tmp_path, "frontend:\nfusion:\n  ekf:\n  graph: {batch: false}\nklt:\nodometry: {height: null}\n")
    assert cfg == _load(tmp_path, "fusion: {graph: {batch: false}}\n")[1]
    assert cfg.fusion.graph.batch is False and cfg.odometry.height is None


def test_every_option_has_a_description_and_every_parser_is_the_schema():
    from frontends.features import FeatureConfig
    from fusion_vo.simulation.generate import SimulationOptions

    for cls in (SimulationOptions, FusionConfig, KltConfig, FeatureConfig, RunConfig):
        schema = json_schema(section_view(cls))
        for definition in [schema, *schema.get("$defs", {}).values()]:
            assert [name for name, p in definition["properties"].items() if not p.get("description")] == [], \
                definition["title"]
    sim = json_schema(section_view(SimulationOptions))["properties"]
    assert sim["camera_rate"]["unit"] == "Hz" and sim["gps_outages"]["unit"] == "s"
    # the models' own from_dict give the same messages (key path and expected type), naming the class
    with pytest.raises(InputError, match=r"^fusion\.ekf\.accel_sigma: expected a number, got 'abc'$"):
        validate(FusionConfig, {"ekf": {"accel_sigma": "abc"}}, prefix=("fusion",))
    with pytest.raises(ValueError, match=r"^FusionConfig: ekf\.accel_sigma: expected a number, got 'abc'$"):
        FusionConfig.from_dict({"ekf": {"accel_sigma": "abc"}})
    with pytest.raises(ValueError, match=r"^KltConfig: max_tracks: expected an integer, got 'many'$"):
        KltConfig.from_dict({"max_tracks": "many"})
