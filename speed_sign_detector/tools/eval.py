"""``speed_sign_eval``: measure the pipeline on scenes, crops or bags.

Subcommands (each in its own module, registered here):

- ``scenes DIR``: GTSDB-format scenes (``DIR/images``, ``DIR/gt.txt``), detection and
  single-frame recognition metrics (:mod:`speed_sign_detector.tools.eval_scenes`).
- ``crops DIR``: GTSRB-format crops (``DIR/labels.csv``), classification accuracy
  (:mod:`speed_sign_detector.tools.eval_crops`).
- ``bag BAG``: a recorded drive through the full pipeline, per-sign metrics against a
  truth file, optional results bag (:mod:`speed_sign_detector.tools.eval_bag`).
- ``fleet BAG... | --manifest CSV``: many bags on Ray (this machine or a cluster),
  resumable, the per-sign metrics summed (:mod:`speed_sign_detector.tools.fleet`).

With ``--json`` the last line on stdout is ONE JSON object; progress and logs go to
stderr. Exit status: 0 on success; 1 when the evaluation failed with an error, or
finished but had to skip input (unreadable image files, a truncated bag: the metrics of
the rest are still printed); 2 for bad command-line usage; 130 after Ctrl-C (the metrics
of what was done are printed, marked ``"partial": true``).
"""
from __future__ import annotations

import argparse
import logging
import sys

from speed_sign_detector.blas_threads import use_one_blas_thread

use_one_blas_thread()   # before the subcommand modules load numpy

from speed_sign_detector import __version__  # noqa: E402
from speed_sign_detector.tools import eval_bag, eval_crops, eval_scenes, fleet  # noqa: E402
from speed_sign_detector.tools.run_control import run_subcommand  # noqa: E402

SUBCOMMAND_MODULES = (eval_scenes, eval_crops, eval_bag, fleet)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every available subcommand registered."""
    parser = argparse.ArgumentParser(
        prog='speed_sign_eval', description='Evaluate speed-limit sign detection and '
        'recognition on scenes, crops, bags or many bags (fleet).')
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    parser.add_argument('-v', '--verbose', action='store_true', help='debug logging on stderr')
    subparsers = parser.add_subparsers(dest='command', required=True,
                                       metavar='{scenes,crops,bag,fleet}')
    for module in SUBCOMMAND_MODULES:
        module.register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``speed_sign_eval``; returns the process exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO,
                        format='%(levelname)s %(name)s: %(message)s', stream=sys.stderr)
    return run_subcommand('speed_sign_eval', args)


if __name__ == '__main__':
    sys.exit(main())
