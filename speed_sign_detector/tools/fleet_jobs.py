"""The bags of a fleet run and its output folder: jobs, keys, resume state, atomic writes.

A fleet run (``speed_sign_eval fleet``, :mod:`speed_sign_detector.tools.fleet`) turns its
input into :class:`BagJob` s:

- bag paths or glob patterns (``drives/*.mcap``, ``'drives/**/metadata.yaml'`` names the
  bag directory holding it), without truth;
- a manifest CSV (``--manifest``) with a header line naming a ``bag`` column and an
  optional ``truth`` column; relative paths are taken from the manifest's folder, an
  empty truth cell means none. Lines starting with ``#`` are comments.

Every job has a key naming its outputs: the bag's file name, then a digest of the bag's
absolute path, the truth file, the evaluation settings and every pipeline parameter
that can change a result. A re-run with the same folder and settings finds the bags it
already evaluated; a change of settings evaluates them afresh under new keys.

The output folder (:class:`FleetFolder`)::

    OUT/summaries/KEY.json   one JSON line per bag: the fields of `eval bag --json`
    OUT/results/KEY/         the results bag (ROS 2 MCAP), as `eval bag --out` writes it
    OUT/fleet.json           the aggregate of the last run (also its last stdout line)
    OUT/fleet.png            the aggregate as a picture
    OUT/.partial/            work in progress (removed at the start of a run)

A bag counts as done when its summary exists and records no error. Both files are
written to a temporary name first and moved into place with ``os.replace``, results bag
first, summary last, so an interrupted or retried evaluation never leaves a summary
without its results bag, and two attempts at the same bag (a retried call that ran
twice) leave one complete copy.
"""
from __future__ import annotations

import csv
import glob
import hashlib
import json
import os
import re
import shutil
import uuid
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from speed_sign_detector.config import PipelineConfig
from speed_sign_detector.config_parameters import to_parameters
from speed_sign_detector.errors import SpeedSignError

#: Pipeline parameters that cannot change a result (left out of the job key).
PARAMETERS_NOT_IN_KEY: frozenset[str] = frozenset({'classifier.cache_dir'})
#: Column names of a manifest CSV.
MANIFEST_BAG_COLUMN = 'bag'
MANIFEST_TRUTH_COLUMN = 'truth'
#: Characters of the settings digest in a job key.
KEY_DIGEST_CHARS = 12


class FleetError(SpeedSignError):
    """A fleet run cannot start or go on (bad manifest, no bags, unusable output folder,
    no Ray)."""


@dataclass(frozen=True)
class EvaluationSettings:
    """How every bag of a run is evaluated (the options of ``eval bag`` that apply).

    Attributes:
        config: the pipeline's parameters.
        topic: the image topic, None to find the only one.
        grace_s: seconds after a sign left the image within which recognizing it counts.
        debug_images: also write ``/debug_image`` into the results bags.
    """

    config: PipelineConfig
    topic: str | None = None
    grace_s: float = 1.0
    debug_images: bool = False

    def digest_source(self) -> dict[str, Any]:
        """What of these settings goes into a job key (JSON-ready)."""
        parameters = {name: value for name, value in to_parameters(self.config).items()
                      if name not in PARAMETERS_NOT_IN_KEY}
        return {'parameters': parameters, 'topic': self.topic, 'grace_s': self.grace_s,
                'debug_images': self.debug_images}


@dataclass(frozen=True)
class BagJob:
    """One bag to evaluate.

    Attributes:
        key: names the bag's outputs in the folder (see the module docstring).
        bag: the bag (ROS 2 directory, ``.mcap``/``.db3`` file, ROS 1 ``.bag``), absolute.
        truth: its truth CSV, absolute, or None.
    """

    key: str
    bag: Path
    truth: Path | None


@dataclass(frozen=True)
class BagOutcome:
    """What became of one bag.

    Attributes:
        key: the job's key.
        bag: the bag's path.
        done: True when every frame was evaluated and both outputs were written.
        reason: why it is not done (one line), None when done.
        summary: the bag's ``eval bag --json`` object (also for a truncated bag: the
            frames before the damage), None when nothing could be evaluated.
        worker: ``host:pid`` of the worker process that evaluated it.
        started_unix_s, finished_unix_s: wall-clock times of the call, seconds since
            the epoch.
        setup_s: seconds this call spent building the worker's pipeline (the worker's
            first bag only; 0 otherwise).
        resumed: True when it was done by an earlier run and not evaluated again.
    """

    key: str
    bag: str
    done: bool
    reason: str | None
    summary: dict[str, Any] | None
    worker: str
    started_unix_s: float
    finished_unix_s: float
    setup_s: float = 0.0
    resumed: bool = False

    @property
    def frames(self) -> int:
        """Frames evaluated (0 when nothing could be)."""
        return int(self.summary['frames']) if self.summary is not None else 0


def job_key(bag: Path, truth: Path | None, settings: EvaluationSettings) -> str:
    """``NAME-DIGEST``: the bag's file name (made file-name safe) and a digest of the
    bag's absolute path, its truth file and the settings."""
    source = {'bag': str(bag), 'truth': str(truth) if truth is not None else None,
              **settings.digest_source()}
    digest = hashlib.sha256(json.dumps(source, sort_keys=True, default=str).encode())
    name = re.sub(r'[^A-Za-z0-9_.-]+', '_', bag.name).strip('._') or 'bag'
    return f'{name}-{digest.hexdigest()[:KEY_DIGEST_CHARS]}'


def jobs_from_paths(patterns: Sequence[str], settings: EvaluationSettings) -> list[BagJob]:
    """Jobs for bag paths and glob patterns (no truth).

    A pattern matching a ``metadata.yaml`` or a storage file inside a ROS 2 bag directory
    stands for that directory. Bags named twice are evaluated once.

    Raises:
        FleetError: a path that does not exist or a pattern that matches nothing.
    """
    bags: list[Path] = []
    for pattern in patterns:
        if glob.has_magic(pattern):
            matches = sorted(glob.glob(os.path.expanduser(pattern), recursive=True))
            if not matches:
                raise FleetError(f'no bag matches {pattern!r}')
            bags.extend(_bag_of(Path(match)) for match in matches)
        else:
            path = Path(pattern).expanduser()
            if not path.exists():
                raise FleetError(f'bag {path} does not exist')
            bags.append(path)
    return _jobs([(bag, None) for bag in bags], settings)


def jobs_from_manifest(manifest: Path, settings: EvaluationSettings) -> list[BagJob]:
    """Jobs for the rows of a manifest CSV (format in the module docstring).

    Paths are not checked here: a missing bag is reported as that bag's failure, so one
    wrong row does not stop the others.

    Raises:
        FleetError: the manifest cannot be read, lacks the ``bag`` column, or has no row.
    """
    try:
        text = manifest.read_text(encoding='utf-8')
    except (OSError, UnicodeDecodeError) as err:
        raise FleetError(f'cannot read manifest {manifest}: {err}') from err
    lines = [line for line in text.splitlines()
             if line.strip() and not line.lstrip().startswith('#')]
    if not lines:
        raise FleetError(f'manifest {manifest} is empty: expected a header line '
                         f'"{MANIFEST_BAG_COLUMN},{MANIFEST_TRUTH_COLUMN}" and a row per bag')
    rows = list(csv.DictReader(lines, skipinitialspace=True))
    header = [name.strip() for name in next(csv.reader(lines[:1]))]
    if MANIFEST_BAG_COLUMN not in header:
        raise FleetError(f'manifest {manifest}: header {",".join(header)!r} has no '
                         f'{MANIFEST_BAG_COLUMN!r} column (expected '
                         f'"{MANIFEST_BAG_COLUMN},{MANIFEST_TRUTH_COLUMN}")')
    if not rows:
        raise FleetError(f'manifest {manifest} lists no bag')
    base = manifest.parent
    pairs: list[tuple[Path, Path | None]] = []
    for number, row in enumerate(rows, start=2):
        bag_text = (row.get(MANIFEST_BAG_COLUMN) or '').strip()
        if not bag_text:
            raise FleetError(f'manifest {manifest}: row {number} has no bag')
        truth_text = (row.get(MANIFEST_TRUTH_COLUMN) or '').strip()
        pairs.append((base / Path(bag_text).expanduser(),
                      base / Path(truth_text).expanduser() if truth_text else None))
    return _jobs(pairs, settings)


def _bag_of(path: Path) -> Path:
    """The bag a glob match stands for: a ROS 2 bag's directory for a file inside it."""
    if path.is_file() and (path.name == 'metadata.yaml'
                           or (path.suffix in ('.mcap', '.db3')
                               and (path.parent / 'metadata.yaml').is_file())):
        return path.parent
    return path


def _jobs(pairs: Iterable[tuple[Path, Path | None]], settings: EvaluationSettings
          ) -> list[BagJob]:
    jobs: dict[str, BagJob] = {}
    for bag, truth in pairs:
        bag = bag.absolute()
        truth = truth.absolute() if truth is not None else None
        key = job_key(bag, truth, settings)
        jobs.setdefault(key, BagJob(key, bag, truth))
    return list(jobs.values())


class FleetFolder:
    """The output folder of a fleet run (layout in the module docstring).

    Args:
        root: the folder; created when missing.

    Raises:
        FleetError: the folder cannot be created or is a file.
    """

    def __init__(self, root: Path) -> None:
        self.root = root
        try:
            for folder in (self.summaries_dir, self.results_dir, self.partial_dir):
                folder.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise FleetError(f'cannot use output folder {root}: {err}') from err

    @property
    def summaries_dir(self) -> Path:
        return self.root / 'summaries'

    @property
    def results_dir(self) -> Path:
        return self.root / 'results'

    @property
    def partial_dir(self) -> Path:
        return self.root / '.partial'

    @property
    def aggregate_json(self) -> Path:
        return self.root / 'fleet.json'

    @property
    def aggregate_png(self) -> Path:
        return self.root / 'fleet.png'

    def summary_path(self, key: str) -> Path:
        """Where a bag's JSON line goes."""
        return self.summaries_dir / f'{key}.json'

    def results_path(self, key: str) -> Path:
        """Where a bag's results bag goes."""
        return self.results_dir / key

    def clear_partial(self) -> None:
        """Remove the work in progress an interrupted run left (call before a run)."""
        shutil.rmtree(self.partial_dir, ignore_errors=True)
        self.partial_dir.mkdir(parents=True, exist_ok=True)

    def new_partial_dir(self) -> Path:
        """A fresh folder for one attempt's work in progress."""
        path = self.partial_dir / uuid.uuid4().hex
        path.mkdir(parents=True)
        return path

    def done_summary(self, key: str) -> dict[str, Any] | None:
        """A bag's summary when it was evaluated completely before, else None.

        An unreadable summary (a file damaged outside this tool) counts as not done.
        """
        path = self.summary_path(key)
        try:
            summary = json.loads(path.read_text(encoding='utf-8'))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError):
            return None
        if not isinstance(summary, dict) or summary.get('error') is not None:
            return None
        if not self.results_path(key).is_dir():
            return None
        return summary

    def publish_results_bag(self, written: Path, key: str) -> Path:
        """Move a finished results bag into place (replacing an older copy); returns it.

        Raises:
            FleetError: it cannot be moved.
        """
        target = self.results_path(key)
        try:
            try:
                os.replace(written, target)
            except OSError:   # an older copy (a directory) is in the way
                shutil.rmtree(target, ignore_errors=True)
                os.replace(written, target)
        except OSError as err:
            raise FleetError(f'cannot move results bag {written} to {target}: {err}') from err
        return target

    def publish_summary(self, line: str, key: str, scratch: Path) -> Path:
        """Write a bag's JSON line: to ``scratch`` first, then ``os.replace``; returns it.

        Raises:
            FleetError: it cannot be written.
        """
        target = self.summary_path(key)
        temporary = scratch / f'{key}.json'
        try:
            temporary.write_text(line + '\n', encoding='utf-8')
            os.replace(temporary, target)
        except OSError as err:
            raise FleetError(f'cannot write summary {target}: {err}') from err
        return target
