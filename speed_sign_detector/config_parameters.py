"""Flat parameters (``section.field``) of the stages' configs, and ROS 2 parameter files.

The configs themselves, with each field's description and range, are in
:mod:`speed_sign_detector.config`; this module names their fields as a user writes them
(``detector.min_radius_px``), flattens a config to such names and builds one back from
them or from a YAML parameter file, with the same validation.
"""
from __future__ import annotations

import dataclasses
import difflib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from speed_sign_detector.config import SECTIONS, NodeOptions, PipelineConfig
from speed_sign_detector.errors import ConfigError

__all__ = ['ParameterSpec', 'closest_parameter', 'from_parameters', 'load_yaml',
           'node_option_specs', 'parameter_specs', 'to_parameters',
           'unknown_parameter_message']


@dataclass(frozen=True)
class ParameterSpec:
    """One flat parameter: name ``section.field``, default, description, range."""

    name: str
    default: Any
    description: str
    low: float | None
    high: float | None
    choices: tuple[str, ...] | None


def parameter_specs() -> tuple[ParameterSpec, ...]:
    """Every flat parameter of :class:`PipelineConfig`, in declaration order."""
    specs: list[ParameterSpec] = []
    for item in dataclasses.fields(PipelineConfig):
        if item.name in SECTIONS:
            for sub in dataclasses.fields(SECTIONS[item.name]):
                specs.append(_spec(f'{item.name}.{sub.name}', sub))
        else:
            specs.append(_spec(item.name, item))
    return tuple(specs)


def node_option_specs() -> tuple[ParameterSpec, ...]:
    """The node-only parameters (:class:`NodeOptions`) as flat specs."""
    return tuple(_spec(item.name, item) for item in dataclasses.fields(NodeOptions))


def _spec(name: str, item: dataclasses.Field) -> ParameterSpec:
    meta = item.metadata
    return ParameterSpec(name, item.default, meta.get('description', ''), meta.get('low'),
                         meta.get('high'), meta.get('choices'))


def to_parameters(config: PipelineConfig) -> dict[str, Any]:
    """Flatten a config to ``{'section.field': value}``."""
    flat: dict[str, Any] = {}
    for spec in parameter_specs():
        section, _, name = spec.name.rpartition('.')
        owner = getattr(config, section) if section else config
        flat[spec.name] = getattr(owner, name)
    return flat


def closest_parameter(name: str, known: Iterable[str]) -> str | None:
    """The known parameter name most like ``name`` (a misspelling of it), or None."""
    matches = difflib.get_close_matches(name, list(known), n=1, cutoff=0.6)
    return matches[0] if matches else None


def unknown_parameter_message(name: str, known: Iterable[str]) -> str:
    """``unknown parameter X (did you mean Y?)``: one short clause, no list of all names."""
    guess = closest_parameter(name, known)
    hint = f'did you mean {guess}?' if guess else 'see config/speed_sign_detector.yaml'
    return f'unknown parameter {name} ({hint})'


def from_parameters(values: Mapping[str, Any],
                    base: PipelineConfig | None = None) -> PipelineConfig:
    """Build a config from flat ``section.field`` values over ``base`` (defaults).

    Raises:
        ConfigError: for an unknown name or a value out of range.
    """
    base = base or PipelineConfig()
    known = {spec.name for spec in parameter_specs()}
    unknown = sorted(set(values) - known)
    if unknown:
        suggestible = known | {spec.name for spec in node_option_specs()}
        raise ConfigError('; '.join(unknown_parameter_message(name, suggestible)
                                    for name in unknown))
    sections: dict[str, dict[str, Any]] = {name: {} for name in SECTIONS}
    top: dict[str, Any] = {}
    for name, value in values.items():
        section, _, field_name = name.rpartition('.')
        (sections[section] if section else top)[field_name] = value
    try:
        replaced = {name: dataclasses.replace(getattr(base, name), **changes)
                    for name, changes in sections.items() if changes}
        return dataclasses.replace(base, **top, **replaced)
    except TypeError as err:
        raise ConfigError(f'invalid parameter value: {err}') from err


def load_yaml(path: str | Path, node_name: str = 'speed_sign_detector') -> PipelineConfig:
    """Load a config from a ROS 2 parameter file (``node: ros__parameters: ...``).

    Nested mappings (``detector: {min_radius_px: 5}``) and flat dotted names are both
    accepted. A file without the ``ros__parameters`` wrapper is read as the mapping itself.
    The node's own options (:class:`NodeOptions`) may be present and are ignored here.

    Raises:
        ConfigError: when the file is missing, not YAML, or holds invalid values.
    """
    import yaml

    path = Path(path)
    try:
        document = yaml.safe_load(path.read_text())
    except OSError as err:
        raise ConfigError(f'cannot read config file {path}: {err}') from err
    except yaml.YAMLError as err:
        raise ConfigError(f'config file {path} is not valid YAML: {err}') from err
    if document is None:
        return PipelineConfig()
    if not isinstance(document, dict):
        raise ConfigError(f'config file {path} must hold a mapping, not {type(document).__name__}')
    for key in (node_name, f'/{node_name}', '/**'):
        if isinstance(document.get(key), dict) and 'ros__parameters' in document[key]:
            document = document[key]['ros__parameters']
            break
    node_options = {spec.name for spec in node_option_specs()}
    return from_parameters({name: value for name, value in _flatten(document).items()
                            if name not in node_options})


def _flatten(mapping: Mapping[str, Any], prefix: str = '') -> dict[str, Any]:
    flat: dict[str, Any] = {}
    for key, value in mapping.items():
        name = f'{prefix}{key}'
        if isinstance(value, Mapping):
            flat.update(_flatten(value, f'{name}.'))
        else:
            flat[name] = value
    return flat
