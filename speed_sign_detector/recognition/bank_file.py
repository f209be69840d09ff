"""One ``.npz`` file of named arrays with its provenance: filter banks and their caches.

The file's ``__meta__`` entry is a 0-d string, ``json.dumps(meta, sort_keys=True)``,
holding the format name and version, the package version, what the caller records
(data folders, counts per class, parameters) and the sha256 of every array. Loading
checks the format and version before reading any array, reads every array, checks its
digest, and turns every way a file can be broken (missing, empty, truncated, a flipped
byte, another format or version) into :class:`~speed_sign_detector.errors.BankFileError`
with the reason. Saving refuses object arrays and writes a temporary file first, then
renames it, so a crash never leaves half a file under the final name.
"""
from __future__ import annotations

import hashlib
import json
import os
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from speed_sign_detector import __version__
from speed_sign_detector.errors import BankFileError

__all__ = ['load_bank_file', 'save_bank_file']

_META_KEY = '__meta__'
#: The first bytes of every ``.npz`` file (a zip archive: a local file header, or the end
#: record of an empty archive).
_NPZ_MAGICS = (b'PK\x03\x04', b'PK\x05\x06')


def _digest(array: np.ndarray) -> str:
    data = np.ascontiguousarray(array)
    header = f'{data.dtype.str}{data.shape}'.encode()
    return hashlib.sha256(header + data.tobytes()).hexdigest()


def save_bank_file(path: Path, arrays: Mapping[str, np.ndarray], meta: Mapping[str, Any],
                   file_format: str, version: int) -> None:
    """Write ``arrays`` and ``meta`` to ``path`` (an ``.npz`` file), atomically.

    Args:
        path: the file to write; its folder is created when missing.
        arrays: named arrays of numeric, boolean or string dtypes.
        meta: JSON-serialisable provenance (data folders, counts, parameters, ...).
        file_format: the format's name, checked on loading.
        version: the format's integer version, checked on loading.

    Raises:
        ValueError: for an object array or a reserved name.
        OSError: when the file cannot be written.
    """
    path = Path(path)
    checked: dict[str, np.ndarray] = {}
    for name, array in arrays.items():
        array = np.asarray(array)
        if array.dtype.hasobject:
            raise ValueError(f'array {name!r} has an object dtype; only numeric, boolean and '
                             'string arrays can be saved without pickle')
        if name == _META_KEY:
            raise ValueError(f'{_META_KEY!r} is reserved')
        checked[name] = array
    record = dict(meta, format=file_format, format_version=int(version),
                  package_version=__version__,
                  sha256={name: _digest(array) for name, array in checked.items()})
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(f'.{path.name}.{os.getpid()}.tmp.npz')
    try:
        np.savez(temporary, **checked, **{_META_KEY: np.asarray(json.dumps(record,
                                                                             sort_keys=True))})
        os.replace(temporary, path)
    finally:
        temporary.unlink(missing_ok=True)


def _check_npz_magic(path: Path, file_format: str) -> None:
    """Refuse a file that is no ``.npz`` archive at all (a text file given as a bank)
    before numpy reads it: numpy would take it for a pickle and advise loading it
    unsafely.

    Raises:
        BankFileError: missing, unreadable, empty, or not an ``.npz`` archive.
    """
    try:
        with open(path, 'rb') as handle:
            head = handle.read(4)
    except FileNotFoundError as err:
        raise BankFileError(f'{path} does not exist') from err
    except OSError as err:
        raise BankFileError(f'{path} cannot be read ({err.strerror or err})') from err
    if not head:
        raise BankFileError(f'{path} is empty, not a bank file')
    if not head.startswith(_NPZ_MAGICS):
        raise BankFileError(f'{path} is not a bank file: not an .npz archive (a '
                            f'{file_format} file is expected)')


def load_bank_file(path: Path, file_format: str, versions: tuple[int, ...]
                   ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Read a file written by :func:`save_bank_file`.

    Args:
        path: the file.
        file_format: the format expected.
        versions: the format versions this package reads.

    Returns:
        (arrays, meta): every array by name, and the provenance record.

    Raises:
        BankFileError: when the file is missing, unreadable, corrupt, or of another
            format or version; the message names the file and the reason.
    """
    path = Path(path)
    _check_npz_magic(path, file_format)
    try:
        with np.load(path, allow_pickle=False) as data:
            if _META_KEY not in data.files:
                raise BankFileError(f'{path} is not a {file_format} file (no {_META_KEY} entry)')
            meta = json.loads(str(data[_META_KEY][()]))
            if not isinstance(meta, dict) or meta.get('format') != file_format:
                found = meta.get('format') if isinstance(meta, dict) else None
                raise BankFileError(f'{path} is a {found!r} file, not {file_format!r}')
            version = meta.get('format_version')
            if version not in versions:
                raise BankFileError(
                    f'{path} has {file_format} version {version}; this package '
                    f'(version {__version__}) reads version(s) '
                    f'{", ".join(str(v) for v in versions)}: rebuild the file with this '
                    'version (speed_sign_train build)')
            arrays = {name: data[name] for name in data.files if name != _META_KEY}
    except BankFileError:
        raise
    except FileNotFoundError as err:
        raise BankFileError(f'{path} does not exist') from err
    except (OSError, zipfile.BadZipFile, EOFError, ValueError, KeyError,
            json.JSONDecodeError, UnicodeDecodeError) as err:
        raise BankFileError(f'{path} is corrupt or truncated ({type(err).__name__}: {err})'
                            ) from err
    digests = meta.get('sha256', {})
    if set(digests) != set(arrays):
        raise BankFileError(f'{path} is corrupt: its arrays {sorted(arrays)} do not match '
                            f'its record {sorted(digests)}')
    for name, array in arrays.items():
        if _digest(array) != digests[name]:
            raise BankFileError(f'{path} is corrupt: array {name!r} does not match its '
                                'checksum')
    return arrays, meta
