"""Configs: validation, flat parameters, YAML loading (the installed config file too)."""
from __future__ import annotations

from pathlib import Path

import pytest

from speed_sign_detector.config import DetectorConfig, PipelineConfig
from speed_sign_detector.config_parameters import (
    from_parameters,
    load_yaml,
    parameter_specs,
    to_parameters,
)
from speed_sign_detector.errors import ConfigError

PROJECT_ROOT = Path(__file__).resolve().parents[1]


def test_defaults_round_trip_through_flat_parameters() -> None:
    config = PipelineConfig()
    assert from_parameters(to_parameters(config)) == config


def test_every_parameter_has_a_description() -> None:
    for spec in parameter_specs():
        assert spec.description, f'{spec.name} has no description'


@pytest.mark.parametrize('values, message', [
    ({'detector.min_radius_px': -1.0}, 'below its minimum'),
    ({'detector.enclosing_ring_ratio': -1.0}, 'below its minimum'),
    ({'detector.enclosing_ring_ratio': 'twice'}, 'must be float'),
    ({'detector.polarity': 'sideways'}, 'not one of'),
    ({'detector.max_candidates': 'seven'}, 'must be int'),
    ({'detector.min_radius_px': 30.0, 'detector.max_radius_px': 20.0}, 'larger than'),
    ({'detector.no_such_thing': 1}, 'unknown parameter'),
    ({'backend': 'cuda'}, 'not one of'),
])
def test_invalid_values_are_rejected_with_a_reason(values: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        from_parameters(values)


def test_unknown_parameter_names_the_closest_known_one_only() -> None:
    with pytest.raises(ConfigError) as caught:
        from_parameters({'detector.min_raduis_px': 6.0})
    message = str(caught.value)
    assert 'detector.min_raduis_px' in message
    assert 'did you mean detector.min_radius_px?' in message
    others = [spec.name for spec in parameter_specs() if spec.name != 'detector.min_radius_px']
    assert not [name for name in others if name in message]


@pytest.mark.parametrize('values, name', [
    ({'detector.min_radius_px': 'six'}, 'detector.min_radius_px must be float'),
    ({'classifier.psr_threshold': -1.0}, 'classifier.psr_threshold = -1.0 is below'),
    ({'tracker.window_frames': 0}, 'tracker.window_frames = 0 is below'),
    ({'classifier.min_radius_px': 30.0, 'classifier.max_radius_px': 20.0},
     'classifier.max_radius_px (20.0) must be larger than classifier.min_radius_px'),
    ({'backend': 3}, 'backend must be str'),
])
def test_invalid_values_name_the_parameter_as_written(values: dict, name: str) -> None:
    with pytest.raises(ConfigError) as caught:
        from_parameters(values)
    assert name in str(caught.value)
    assert 'Config.' not in str(caught.value)


def test_integer_given_for_float_is_accepted() -> None:
    assert DetectorConfig(min_radius_px=6).min_radius_px == 6.0


def test_yaml_nested_and_ros_wrapped(tmp_path: Path) -> None:
    path = tmp_path / 'params.yaml'
    path.write_text('speed_sign_detector:\n  ros__parameters:\n    backend: numpy\n'
                    '    detector:\n      max_candidates: 3\n')
    config = load_yaml(path)
    assert config.backend == 'numpy'
    assert config.detector.max_candidates == 3


def test_yaml_errors_are_clear(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match='cannot read'):
        load_yaml(tmp_path / 'missing.yaml')
    broken = tmp_path / 'broken.yaml'
    broken.write_text('detector: [unclosed\n')
    with pytest.raises(ConfigError, match='not valid YAML'):
        load_yaml(broken)


def test_installed_config_file_matches_the_defaults() -> None:
    """config/speed_sign_detector.yaml lists every parameter, with valid values."""
    path = PROJECT_ROOT / 'config' / 'speed_sign_detector.yaml'
    config = load_yaml(path)
    import yaml
    listed = yaml.safe_load(path.read_text())['speed_sign_detector']['ros__parameters']
    flat: set[str] = set()
    for key, value in listed.items():
        flat.update(f'{key}.{sub}' for sub in value) if isinstance(value, dict) else flat.add(key)
    missing = {spec.name for spec in parameter_specs()} - flat
    assert not missing, f'config file lacks {sorted(missing)}'
    assert isinstance(config, PipelineConfig)
