"""Spinning test nodes of one rclpy context on a background thread."""
from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import rclpy
from rclpy.executors import SingleThreadedExecutor

#: Longest wait for the spinning thread to end after the executor shut down, seconds.
JOIN_TIMEOUT_S = 10.0


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
