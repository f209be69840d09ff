"""Each test run on a host takes its own block of ROS domains (test/ros_spin.py), so that
two runs of the suite side by side do not answer each other's frames."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from ros_spin import (
    _MODULE_DOMAINS,
    DOMAIN_BLOCK_SIZE,
    DOMAIN_BLOCK_STARTS,
    block_lock_path,
    domain_block_start,
    module_domain,
)

TEST_DIR = Path(__file__).resolve().parent


def _domain_in_another_process(module: str) -> int:
    """``module_domain(module)`` as a second test run on this host sees it now."""
    code = f'from ros_spin import module_domain; print(module_domain({module!r}))'
    done = subprocess.run([sys.executable, '-c', code], cwd=TEST_DIR, capture_output=True,
                          text=True, timeout=120, check=True)
    return int(done.stdout.strip().splitlines()[-1])


def test_every_module_domain_lies_in_this_runs_block() -> None:
    start = domain_block_start()
    assert start in DOMAIN_BLOCK_STARTS
    domains = [module_domain(module, index) for module, (_, count) in _MODULE_DOMAINS.items()
               for index in range(count)]
    assert len(set(domains)) == len(domains)
    assert all(start <= domain < start + DOMAIN_BLOCK_SIZE for domain in domains)
    assert all(0 <= domain <= 101 for domain in domains)
    assert block_lock_path(start).exists()


def test_a_second_run_on_the_host_takes_another_block() -> None:
    ours = module_domain('test_node')
    theirs = _domain_in_another_process('test_node')
    assert theirs != ours
    assert (theirs - ours) % DOMAIN_BLOCK_SIZE == 0  # the same module, another block
    # the other run ended, and its block with it: the next one takes it again
    assert _domain_in_another_process('test_node') == theirs
