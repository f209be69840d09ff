"""The node's ROS parameters: declared from the config dataclasses, typed like them.

Every field of :class:`~speed_sign_detector.config.PipelineConfig` (``section.field``) and
of :class:`~speed_sign_detector.config.NodeOptions` is one parameter, with its
description, range or choices in the descriptor (``ros2 param describe``).

Integers are accepted wherever a float is declared, as the offline tools accept them in
the same YAML file (``max_radius_px: 50``): at start-up (``-p detector.min_radius_px:=8``,
``--params-file``) and in ``ros2 param set``. Float parameters are therefore declared
with dynamic typing, and a pre-set callback turns an integer given for one into a
float; any other type is refused by the config's own validation, with the reason.
"""
from __future__ import annotations

import json
import textwrap
from typing import Any

import numpy as np
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.node import Node
from rclpy.parameter import Parameter

from speed_sign_detector.config_parameters import (
    ParameterSpec,
    node_option_specs,
    parameter_specs,
    unknown_parameter_message,
)

NODE_NAME = 'speed_sign_detector'

#: Parameters that cannot change while the node runs.
READ_ONLY_PARAMETERS = frozenset({'diagnostics_period_s', 'overlap_stages'})
#: Parameters that rclpy declares itself once a publisher or subscription exists (after
#: the start-up check of :func:`unknown_parameter_overrides`).
RCLPY_LATER_PARAMETER_PREFIXES = ('qos_overrides.',)


def all_parameter_specs() -> tuple[ParameterSpec, ...]:
    """The node's options, then the pipeline's parameters, in declaration order."""
    return node_option_specs() + parameter_specs()


def parameter_descriptor(spec: ParameterSpec, read_only: bool = False) -> ParameterDescriptor:
    """ROS parameter descriptor of a spec: description, range or choices, read-only flag."""
    description = spec.description
    if spec.choices:
        description += f' One of: {", ".join(spec.choices)}.'
    descriptor = ParameterDescriptor(name=spec.name, description=description,
                                     read_only=read_only)
    if spec.choices:
        descriptor.additional_constraints = f'one of: {", ".join(spec.choices)}'
    has_range = spec.low is not None or spec.high is not None
    if isinstance(spec.default, bool) or not has_range:
        return descriptor
    if isinstance(spec.default, int):
        descriptor.integer_range = [IntegerRange(
            from_value=int(spec.low) if spec.low is not None else -2**63,
            to_value=int(spec.high) if spec.high is not None else 2**63 - 1, step=1)]
    elif isinstance(spec.default, float):
        descriptor.floating_point_range = [FloatingPointRange(
            from_value=float(spec.low) if spec.low is not None else -np.finfo(float).max,
            to_value=float(spec.high) if spec.high is not None else np.finfo(float).max,
            step=0.0)]
    return descriptor


def declare_node_parameters(node: Node) -> None:
    """Declare every parameter on ``node`` (a Node or LifecycleNode), integers accepted
    for floats (see the module docstring)."""
    float_names = frozenset(spec.name for spec in all_parameter_specs()
                            if isinstance(spec.default, float))

    def integers_as_floats(parameters: list[Parameter]) -> list[Parameter]:
        return [Parameter(p.name, Parameter.Type.DOUBLE, float(p.value))
                if p.name in float_names and p.type_ == Parameter.Type.INTEGER else p
                for p in parameters]

    node.add_pre_set_parameters_callback(integers_as_floats)
    for spec in all_parameter_specs():
        read_only = spec.name in READ_ONLY_PARAMETERS
        descriptor = parameter_descriptor(spec, read_only)
        if spec.name not in float_names:
            node.declare_parameter(spec.name, spec.default, descriptor)
            continue
        # dynamically typed, so that an integer override is not refused by rclpy...
        descriptor.dynamic_typing = True
        value = node.declare_parameter(spec.name, spec.default, descriptor).value
        if isinstance(value, int) and not isinstance(value, bool) and not read_only:
            node.set_parameters([Parameter(spec.name, Parameter.Type.DOUBLE, float(value))])
        # ...a read-only one keeps the integer; the config converts it when read


def unknown_parameter_overrides(node: Node) -> list[str]:
    """One warning per parameter given at start-up (``-p``, ``--params-file``) that
    ``node`` has not declared: rclpy ignores such a value without a word (a misspelt
    ``detector.min_raduis_px``). Call it after :func:`declare_node_parameters`.

    Returns:
        ``unknown parameter detector.min_raduis_px (did you mean
        detector.min_radius_px?) is ignored``, one per unknown name, sorted.
    """
    # rclpy keeps the start-up values in Node._parameter_overrides (no public accessor)
    overrides = getattr(node, '_parameter_overrides', None) or {}
    known = [spec.name for spec in all_parameter_specs()]
    return [f'{unknown_parameter_message(name, known)} is ignored'
            for name in sorted(overrides)
            if not node.has_parameter(name)
            and not name.startswith(RCLPY_LATER_PARAMETER_PREFIXES)]


def parameter_values(node: Node, specs: tuple[ParameterSpec, ...]) -> dict[str, Any]:
    """``{name: value}`` of the node's current parameters for ``specs``."""
    return {spec.name: node.get_parameter(spec.name).value for spec in specs}


def default_parameter_file() -> str:
    """Text of ``config/speed_sign_detector.yaml``: every parameter at its default.

    Regenerate the file after adding a config field::

        python -c "from speed_sign_detector.ros.parameters import default_parameter_file \\
            as f; print(f(), end='')" > config/speed_sign_detector.yaml
    """
    lines = [
        '# Parameters of the speed_sign_detector node, with their defaults (generated by',
        '# speed_sign_detector.ros.parameters.default_parameter_file). Load with:',
        '#   ros2 run speed_sign_detector speed_sign_detector --ros-args --params-file <file>',
        '# (the launch file passes the installed copy). Integers are accepted for',
        '# floating-point values, here as in `speed_sign_eval bag --config`. Every value can',
        '# be changed at run time with `ros2 param set` except the read-only ones; invalid',
        '# values are rejected with the reason.',
        f'{NODE_NAME}:',
        '  ros__parameters:',
    ]
    section = ''
    for spec in all_parameter_specs():
        owner, _, name = spec.name.rpartition('.')
        if owner and owner != section:
            lines.append(f'    {owner}:')
            section = owner
        indent = '      ' if owner else '    '
        notes = [f'one of {", ".join(spec.choices)}'] if spec.choices else []
        if spec.low is not None or spec.high is not None:
            notes.append(f'range [{spec.low}, {spec.high}]')
        if spec.name in READ_ONLY_PARAMETERS:
            notes.append('read-only')
        text = spec.description + (f' ({"; ".join(notes)})' if notes else '')
        lines += [f'{indent}# {line}' for line in textwrap.wrap(text, 92 - len(indent))]
        lines.append(f'{indent}{name}: {_yaml_scalar(spec.default)}')
    return '\n'.join(lines) + '\n'


def _yaml_scalar(value: Any) -> str:
    """A YAML scalar that ROS reads back with the value's type (floats keep a '.')."""
    if isinstance(value, str):
        return "'" + value.replace("'", "''") + "'"
    if isinstance(value, float):
        mantissa, _, exponent = repr(value).partition('e')
        mantissa += '' if '.' in mantissa else '.0'
        return mantissa + (f'e{exponent}' if exponent else '')
    return json.dumps(value)
