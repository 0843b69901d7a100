"""Configuration: paper defaults, YAML file, NEOSLAM_* environment overrides, errors and the dump round trip."""

from __future__ import annotations

from pathlib import Path

import pytest

from neoslam.config import NOISE_PROFILES, NeoSLAMConfig, OdometryNoiseConfig, dump_config, load_config
from neoslam.errors import ConfigError, InputError, NeoSLAMError


def _write(tmp_path: Path, text: str, name: str = "config.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_defaults_carry_the_papers_values() -> None:
    config = load_config(environ={})
    assert config == NeoSLAMConfig()
    assert config.keyframes.e_max == 1.5
    assert config.object_vector.peak_rate == 1.2  # a of eq. 7
    assert config.object_vector.baseline_rate == 0.0  # b of eq. 7
    assert config.object_vector.learning_rate == 0.001
    assert config.object_vector.epochs == 10
    assert config.object_vector.keyframes_per_epoch == 20
    assert config.head_direction.cells == 36
    assert config.matching.appearance_rmse_threshold == 80.0
    assert config.experience_map.gc_distance_threshold == 7.0


def test_noise_profiles() -> None:
    assert set(NOISE_PROFILES) >= {"none", "vo", "heavy"}
    none = NOISE_PROFILES["none"]
    assert all(value == 0.0 for value in none.model_dump().values())
    assert NOISE_PROFILES["vo"] == OdometryNoiseConfig()
    assert NOISE_PROFILES["heavy"].sigma_yaw_rate > NOISE_PROFILES["vo"].sigma_yaw_rate


def test_yaml_file_overrides_defaults(tmp_path: Path) -> None:
    path = _write(tmp_path, "keyframes:\n  e_max: 2.5\nsimulator:\n  camera:\n    fx: 500.0\n  seed: 9\n")
    config = load_config(path, environ={})
    assert config.keyframes.e_max == 2.5
    assert config.simulator.camera.fx == 500.0
    assert config.simulator.seed == 9
    # untouched fields of a touched section keep their defaults
    assert config.keyframes.neighbourhood_radius == NeoSLAMConfig().keyframes.neighbourhood_radius
    assert config.simulator.camera.fy == NeoSLAMConfig().simulator.camera.fy


def test_empty_yaml_file_gives_defaults(tmp_path: Path) -> None:
    assert load_config(_write(tmp_path, ""), environ={}) == NeoSLAMConfig()


def test_environment_overrides_yaml(tmp_path: Path) -> None:
    path = _write(tmp_path, "keyframes:\n  e_max: 2.5\nmatching:\n  min_inliers: 4\n")
    environ = {
        "NEOSLAM_KEYFRAMES__E_MAX": "3.0",
        "NEOSLAM_SIMULATOR__CAMERA__FX": "400",
        "NEOSLAM_EXPERIENCE_MAP__BACKEND": "pose-graph",
        "NEOSLAM_GRID_CELLS__DIMS": "[10, 12, 14]",
    }
    config = load_config(path, environ=environ)
    assert config.keyframes.e_max == 3.0
    assert config.matching.min_inliers == 4  # from the file, not overridden
    assert config.simulator.camera.fx == 400.0
    assert config.experience_map.backend == "pose-graph"
    assert config.grid_cells.dims == (10, 12, 14)


def test_environment_is_read_from_os_environ(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("NEOSLAM_EXPERIENCE_MAP__CORRECTION_FACTOR", "0.3")
    assert load_config().experience_map.correction_factor == 0.3


def test_neoslam_data_and_other_plain_variables_are_ignored(monkeypatch: pytest.MonkeyPatch) -> None:
    environ = {"NEOSLAM_DATA": "/nowhere", "NEOSLAM_REQUIRE_DATA": "1", "OTHER__THING": "x"}
    assert load_config(environ=environ) == NeoSLAMConfig()
    monkeypatch.setenv("NEOSLAM_DATA", "/nowhere")
    assert load_config() == load_config(environ={})


def test_unknown_key_in_yaml_names_it(tmp_path: Path) -> None:
    path = _write(tmp_path, "matching:\n  bogus_key: 3\n")
    with pytest.raises((ConfigError, InputError)) as caught:
        load_config(path, environ={})
    assert "bogus_key" in str(caught.value)
    assert str(path) in str(caught.value)


def test_unknown_section_in_yaml_names_it(tmp_path: Path) -> None:
    path = _write(tmp_path, "no_such_section:\n  a: 1\n")
    with pytest.raises((ConfigError, InputError), match="no_such_section"):
        load_config(path, environ={})


def test_invalid_value_names_the_field(tmp_path: Path) -> None:
    path = _write(tmp_path, "keyframes:\n  e_max: -1\n")
    with pytest.raises(ConfigError, match=r"keyframes\.e_max"):
        load_config(path, environ={})
    with pytest.raises(ConfigError, match=r"keyframes\.e_max"):
        load_config(environ={"NEOSLAM_KEYFRAMES__E_MAX": "-1"})


def test_unknown_environment_field_is_an_error() -> None:
    with pytest.raises(ConfigError, match=r"matching\.bogus"):
        load_config(environ={"NEOSLAM_MATCHING__BOGUS": "1"})


def test_position_floor_below_a_millimetre_is_refused() -> None:
    with pytest.raises(ConfigError, match=r"object_map\.position_sigma_floor"):
        load_config(environ={"NEOSLAM_OBJECT_MAP__POSITION_SIGMA_FLOOR": "1e-9"})


def test_triangle_sides_beyond_the_keys_bits_are_refused() -> None:
    with pytest.raises(ConfigError, match=r"triangle_max_side / triangle_side_bin is 500 bins"):
        load_config(environ={"NEOSLAM_MATCHING__TRIANGLE_MAX_SIDE": "500", "NEOSLAM_MATCHING__TRIANGLE_SIDE_BIN": "1"})


def test_environment_field_set_both_as_a_value_and_as_a_section() -> None:
    environ = {"NEOSLAM_KEYFRAMES__SPACING": "5", "NEOSLAM_KEYFRAMES__SPACING__X": "1"}
    with pytest.raises(ConfigError, match="NEOSLAM_KEYFRAMES__SPACING__X: spacing is set as a value"):
        load_config(environ=environ)


def test_environment_value_that_is_not_yaml_is_a_config_error() -> None:
    with pytest.raises(NeoSLAMError, match="MIN_INLIERS|min_inliers"):
        load_config(environ={"NEOSLAM_MATCHING__MIN_INLIERS": "["})


def test_bad_yaml_names_the_file(tmp_path: Path) -> None:
    path = _write(tmp_path, "matching:\n  min_inliers: [\n")
    with pytest.raises(InputError) as caught:
        load_config(path, environ={})
    assert caught.value.path == path
    assert str(path) in str(caught.value)


def test_yaml_that_is_not_a_mapping(tmp_path: Path) -> None:
    path = _write(tmp_path, "- a\n- b\n")
    with pytest.raises(InputError) as caught:
        load_config(path, environ={})
    assert caught.value.path == path


def test_missing_config_file(tmp_path: Path) -> None:
    path = tmp_path / "absent.yaml"
    with pytest.raises(InputError) as caught:
        load_config(path, environ={})
    assert caught.value.path == path


def test_dump_loads_back_to_the_same_config(tmp_path: Path) -> None:
    for config in (
        NeoSLAMConfig(),
        load_config(
            environ={
                "NEOSLAM_GRID_CELLS__DIMS": "[8, 9, 10]",
                "NEOSLAM_SIMULATOR__WORLD__CLASS_MIX": "{car: 1.0}",
                "NEOSLAM_EVALUATION__ALIGNMENT": "sim3",
                "NEOSLAM_SIMULATOR__SEED": "42",
            }
        ),
    ):
        text = dump_config(config)
        path = _write(tmp_path, text, "dumped.yaml")
        assert load_config(path, environ={}) == config
        assert dump_config(load_config(path, environ={})) == text


def test_dump_lists_sections_in_declaration_order() -> None:
    text = dump_config(NeoSLAMConfig())
    sections = [line[:-1] for line in text.splitlines() if line and not line.startswith(" ")]
    assert sections == list(NeoSLAMConfig.model_fields)
