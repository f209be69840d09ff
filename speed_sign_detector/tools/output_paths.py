"""Checks of the command-line tools' output paths, made before any work starts.

A tool that has run for minutes must not fail at its end because an output cannot be
written. Every output path (a results bag, a contact sheet, a truth file) goes through
:func:`prepare_output_file` or :func:`prepare_output_bag` first: missing parent folders
are created (the same for every output option), and a path that cannot be written is
refused with a one-line :class:`OutputPathError` naming the option.
"""
from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from speed_sign_detector.errors import SpeedSignError

__all__ = ['OutputPathError', 'prepare_output_bag', 'prepare_output_file']


class OutputPathError(SpeedSignError, ValueError):
    """An output path cannot be written (a folder, a file that exists, no permission)."""


def _prepare_parent(path: Path, option: str) -> None:
    """Create the missing parent folders of ``path``; refuse one that is not writable."""
    parent = path.parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise OutputPathError(f'{option} {path}: cannot create the folder {parent}: '
                              f'{err.strerror or err}') from err
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputPathError(f'{option} {path}: the folder {parent} is not writable')


def prepare_output_file(path: Path, option: str, suffixes: Sequence[str] = ()) -> Path:
    """Check that a file can be written at ``path`` (it may exist: it is replaced).

    Args:
        path: the file to write later.
        option: the command-line option that named it (``'--contact-sheet'``), for messages.
        suffixes: the allowed file name endings (``('.png', '.jpg')``), any when empty.

    Returns:
        ``path``; its parent folders exist afterwards.

    Raises:
        OutputPathError: ``path`` is a folder, has another ending, or its folder cannot
            be created or written.
    """
    path = Path(path)
    if path.is_dir():
        raise OutputPathError(f'{option} {path} is a folder; give a file name')
    if suffixes and path.suffix.lower() not in suffixes:
        raise OutputPathError(f'{option} {path}: the file name must end in '
                              f'{" or ".join(suffixes)}')
    if path.exists() and not os.access(path, os.W_OK):
        raise OutputPathError(f'{option} {path} exists and is not writable')
    _prepare_parent(path, option)
    return path


def prepare_output_bag(path: Path, option: str) -> Path:
    """Check that a new bag can be created at ``path`` (which must not exist).

    Args:
        path: the bag to create later (a folder for ROS 2, a file for ROS 1).
        option: the command-line option or argument that named it, for messages.

    Returns:
        ``path``; its parent folders exist afterwards.

    Raises:
        OutputPathError: ``path`` exists, or its folder cannot be created or written.
    """
    path = Path(path)
    if path.exists():
        raise OutputPathError(f'{option} {path} exists already; remove it or choose another '
                              f'output')
    _prepare_parent(path, option)
    return path
