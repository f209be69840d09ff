"""Spinning test nodes of one rclpy context on a background thread, and the ROS domain
of each test module that talks over ROS."""
from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor

#: Longest wait for the spinning thread to end after the executor shut down, seconds.
JOIN_TIMEOUT_S = 10.0

#: The ROS domains of each test module that talks over ROS: (first id, how many). One
#: table, so that no two modules share a domain (their nodes would see each other's
#: topics when a process outlives its test, or when two runs overlap).
_MODULE_DOMAINS: dict[str, tuple[int, int]] = {
    'test_node': (87, 1),
    'test_node_process': (88, 1),
    'test_node_cli': (86, 1),
    'test_cli_defects': (89, 2),
    'test_replay_monitor': (91, 2),
    'test_replay_delivery': (93, 1),
    'test_node_transport_loss': (94, 1),
    'test_lifecycle_node': (95, 3),
    'test_monitor_output': (98, 1),
    'test_stage_timing': (100, 1),
    'test_bench_soak': (99, 1),
}


def _check_domains_apart(table: dict[str, tuple[int, int]]) -> None:
    """Raise ValueError when two modules' domain ranges overlap or leave 0..101 (the
    domain ids whose ports never collide on Linux)."""
    owner: dict[int, str] = {}
    for module, (first, count) in table.items():
        for domain in range(first, first + count):
            if not 0 <= domain <= 101:
                raise ValueError(f'{module}: ROS domain {domain} is outside 0..101')
            if domain in owner:
                raise ValueError(f'ROS domain {domain} is used by {owner[domain]} and {module}')
            owner[domain] = module


_check_domains_apart(_MODULE_DOMAINS)


def module_domain(module: str, index: int = 0) -> int:
    """The ``index``-th ROS domain id of test module ``module`` (its file name without
    ``.py``); KeyError for a module missing from the table, IndexError past its count."""
    first, count = _MODULE_DOMAINS[module]
    if not 0 <= index < count:
        raise IndexError(f'{module} has {count} ROS domain(s), not {index + 1}')
    return first + index


@contextmanager
def ros_domain_environment(domain_id: int) -> Iterator[None]:
    """Set ``ROS_DOMAIN_ID`` (what child processes and default contexts use) for the block
    and restore the environment after it."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv('ROS_DOMAIN_ID', str(domain_id))
        yield


@contextmanager
def spinning(context: Any, *nodes: Any) -> Iterator[None]:
    """Spin ``nodes`` (of the initialised ``context``) on a daemon thread for the block.

    On leaving the block the executor stops, the nodes are destroyed, the context is
    shut down and the thread joined, in that order.
    """
    executor = SingleThreadedExecutor(context=context)
    for node in nodes:
        executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        yield
    finally:
        executor.shutdown()
        for node in nodes:
            node.destroy_node()
        rclpy.shutdown(context=context)
        spinner.join(timeout=JOIN_TIMEOUT_S)
