"""Spinning test nodes of one rclpy context on a background thread, and the ROS domain
of each test module that talks over ROS."""
from __future__ import annotations

import fcntl
import tempfile
import threading
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor

#: Longest wait for the spinning thread to end after the executor shut down, seconds.
JOIN_TIMEOUT_S = 10.0

#: The ROS domains of each test module that talks over ROS: (first id within a run's
#: block of :data:`DOMAIN_BLOCK_SIZE` ids, how many). One table, so that no two modules
#: share a domain (their nodes would see each other's topics when a process outlives its
#: test).
_MODULE_DOMAINS: dict[str, tuple[int, int]] = {
    'test_node_cli': (0, 1),
    'test_node': (1, 1),
    'test_node_process': (2, 1),
    'test_cli_defects': (3, 2),
    'test_replay_monitor': (5, 2),
    'test_replay_delivery': (7, 1),
    'test_node_transport_loss': (8, 1),
    'test_lifecycle_node': (9, 3),
    'test_monitor_output': (12, 1),
    'test_bench_soak': (13, 1),
    'test_stage_timing': (14, 1),
}
#: Ids in one run's block of ROS domains.
DOMAIN_BLOCK_SIZE = 16
#: The first id of each block, one block per test run that runs at once on this host (two
#: runs of ``make test`` side by side would otherwise answer each other's frames). Every
#: id stays within 0..101, the domain ids whose ports never collide on Linux.
DOMAIN_BLOCK_STARTS = (86, 70, 54, 38, 22, 6)

#: The lock file held by this process for the block it uses (open for its lifetime).
_held_block: tuple[int, IO[str]] | None = None


def _check_domains_apart(table: dict[str, tuple[int, int]]) -> None:
    """Raise ValueError when two modules' domain ranges overlap or leave the block, or a
    block leaves 0..101."""
    owner: dict[int, str] = {}
    for module, (first, count) in table.items():
        for domain in range(first, first + count):
            if not 0 <= domain < DOMAIN_BLOCK_SIZE:
                raise ValueError(f'{module}: ROS domain {domain} is outside the block of '
                                 f'{DOMAIN_BLOCK_SIZE}')
            if domain in owner:
                raise ValueError(f'ROS domain {domain} is used by {owner[domain]} and {module}')
            owner[domain] = module
    for start in DOMAIN_BLOCK_STARTS:
        if not (0 <= start and start + DOMAIN_BLOCK_SIZE - 1 <= 101):
            raise ValueError(f'the block of domains from {start} leaves 0..101')


_check_domains_apart(_MODULE_DOMAINS)


def block_lock_path(start: int) -> Path:
    """The lock file that a test run holds while it uses the block of domains from
    ``start``."""
    return Path(tempfile.gettempdir()) / f'speed_sign_detector_test_ros_domains_{start}.lock'


def domain_block_start() -> int:
    """The first domain id of this test run's block: the first block of
    :data:`DOMAIN_BLOCK_STARTS` whose lock no other process holds, claimed for the life of
    this process (the operating system frees the lock when it ends, however it ends).
    With every block taken the first is shared, with a warning."""
    global _held_block
    if _held_block is None:
        for start in DOMAIN_BLOCK_STARTS:
            lock = block_lock_path(start).open('a')
            try:
                fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                lock.close()
                continue
            _held_block = (start, lock)
            break
        else:
            warnings.warn(f'all {len(DOMAIN_BLOCK_STARTS)} blocks of test ROS domains are held '
                          'by other test runs on this host: sharing the first, whose nodes '
                          'may see this run\'s topics', stacklevel=2)
            return DOMAIN_BLOCK_STARTS[0]
    return _held_block[0]


def module_domain(module: str, index: int = 0) -> int:
    """The ``index``-th ROS domain id of test module ``module`` (its file name without
    ``.py``) in this run's block (:func:`domain_block_start`); KeyError for a module
    missing from the table, IndexError past its count."""
    first, count = _MODULE_DOMAINS[module]
    if not 0 <= index < count:
        raise IndexError(f'{module} has {count} ROS domain(s), not {index + 1}')
    return domain_block_start() + first + index


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
