"""How the evaluation tools stop and report progress: Ctrl-C between items, a bar or log lines.

- :func:`stop_on_interrupt`: while a long loop runs, the first Ctrl-C (SIGINT) only asks
  the loop to stop after the item in hand; the tool then reports the metrics of what
  was done, marked partial, and exits with status 130. A second Ctrl-C stops at once.
- :class:`ItemProgress`: the shared tqdm bar of :mod:`speed_sign_detector.tools.progress`
  when stderr is a terminal; otherwise a log line every tenth of the run, so that logs
  of scripted runs (CI, nohup) still show how far a run got.
"""
from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from types import FrameType

from speed_sign_detector.errors import SpeedSignError
from speed_sign_detector.tools.progress import progress_bar

__all__ = ['EXIT_INTERRUPTED', 'ItemProgress', 'StopRequest', 'stop_on_interrupt']

LOGGER = logging.getLogger(__name__)
#: Exit status of a run stopped by Ctrl-C (128 + SIGINT, as a shell reports it).
EXIT_INTERRUPTED = 130
#: Without a terminal, a progress line is logged every this share of the run.
LOG_EVERY_SHARE = 0.1


@dataclass
class StopRequest:
    """Set by the first Ctrl-C; a loop checks ``requested`` between its items."""

    requested: bool = False


@contextmanager
def stop_on_interrupt(program: str) -> Iterator[StopRequest]:
    """Turn the first SIGINT into a :class:`StopRequest` for the duration of the block.

    Args:
        program: the tool's name, for the message printed on stderr when Ctrl-C arrives.

    Yields:
        The request; loops stop when ``requested`` becomes True. Outside the main thread
        (where Python cannot install signal handlers) the request is never set.
    """
    request = StopRequest()
    if threading.current_thread() is not threading.main_thread():
        yield request
        return

    def on_interrupt(signal_number: int, frame: FrameType | None) -> None:
        if request.requested:
            raise KeyboardInterrupt
        request.requested = True
        print(f'\n{program}: interrupted; finishing the item in hand, then reporting what '
              f'was done (Ctrl-C again stops at once)', file=sys.stderr, flush=True)

    previous = signal.signal(signal.SIGINT, on_interrupt)
    try:
        yield request
    finally:
        signal.signal(signal.SIGINT, previous)


class ItemProgress:
    """Progress over ``total`` items: a tqdm bar on a terminal, else periodic log lines.

    Args:
        total: number of items expected (``None`` or < 1 when unknown).
        description: what is counted, plural (``'frames'``).
        unit: one item's name (``'frame'``).
        enabled: ``False`` shows nothing at all.
    """

    def __init__(self, total: int | None, description: str, unit: str,
                 enabled: bool = True) -> None:
        self.total = total if total is not None and total > 0 else None
        self.description = description
        self.done = 0
        self._bar = progress_bar(self.total, description, unit, enabled=enabled)
        self._log = enabled and bool(self._bar.disable) and self.total is not None
        self._log_step = max(1, round(LOG_EVERY_SHARE * (self.total or 1)))

    def update(self, count: int = 1) -> None:
        """Count ``count`` more items done."""
        self.done += count
        self._bar.update(count)
        if self._log and (self.done % self._log_step == 0 or self.done == self.total):
            LOGGER.info('%d/%d %s', self.done, self.total, self.description)

    def close(self) -> None:
        """End the bar (leaves it on screen)."""
        self._bar.close()


def run_subcommand(program: str, args: argparse.Namespace) -> int:
    """Run the subcommand ``args.run`` chose; a :class:`SpeedSignError` becomes one line
    ``PROGRAM COMMAND: error: ...`` and exit status 1, Ctrl-C outside a
    :func:`stop_on_interrupt` block one line and :data:`EXIT_INTERRUPTED`."""
    try:
        return int(args.run(args))
    except SpeedSignError as err:
        print(f'{program} {args.command}: error: {err}', file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f'{program} {args.command}: interrupted', file=sys.stderr)
        return EXIT_INTERRUPTED
