"""Approach sequences read by scene-fold banks: the whole pipeline on scenes no bank saw.

``speed_sign_train validate ... --scenes SCENE_DIR --approach`` measures each scene fold's
bank (:func:`speed_sign_detector.training.scene_validation.cross_validate_scenes`: every
crop and the other folds' scenes) also on approach sequences made from its own fold's
scenes, through the pipeline as ``speed_sign_synth approach`` + ``speed_sign_eval bag``
would, with tracking. For each fold, :class:`ApproachFolds`

1. writes the fold's bank to a temporary bank file
   (:func:`~speed_sign_detector.recognition.trained_bank.save_trained_bank`, as
   ``speed_sign_train build`` does: the classifier reads what a node would load);
2. makes the approach sequences of the fold's scenes only
   (:class:`~speed_sign_detector.approach_sequences.ApproachStream` with
   ``ApproachConfig(scenes=...)``; the sequences of a scene do not depend on which other
   scenes are chosen) into a temporary bag (raw ``bgr8``, MCAP) and its truth, one bag
   per scene folder;
3. runs that bag through :func:`speed_sign_detector.tools.eval_bag.evaluate_bag` with a
   :class:`~speed_sign_detector.config.PipelineConfig` whose ``classifier.bank_file`` is
   that file, the classifier placed as ``speed_sign_eval bag`` places it (a worker
   process of its own loads the same file);

and deletes the temporary files. The figures add up over folds: counts and drive times
(:func:`~speed_sign_detector.tools.bag_grading.sum_drive_metrics`), the time in the
correct limit weighted by each bag's judged seconds.

This module is a tool (it runs the pipeline and the bag tools); the training package
reaches it only through the :class:`~speed_sign_detector.training.scene_validation.
SceneFoldMeasure` protocol that :class:`ApproachFolds` follows, so that training imports
no tool.
"""
from __future__ import annotations

import dataclasses
import logging
import math
import tempfile
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol

from speed_sign_detector.approach_sequences import ApproachConfig, ApproachStream
from speed_sign_detector.classifier_placement import place_classifier
from speed_sign_detector.config import PipelineConfig
from speed_sign_detector.errors import SpeedSignError
from speed_sign_detector.recognition.trained_bank import TrainedBank, save_trained_bank
from speed_sign_detector.tools.bag_grading import DRIVE_COUNT_KEYS, drive_metrics
from speed_sign_detector.tools.eval_bag import evaluate_bag
from speed_sign_detector.tools.synthetic_bag import write_drive
from speed_sign_detector.truth import write_truth

__all__ = ['APPROACH_KEY', 'ApproachFolds', 'ApproachValidationError', 'approached_figures',
           'format_approach_line', 'sum_approach_figures']

_LOG = logging.getLogger(__name__)

#: The key of the approach figures in the scene folds' report.
APPROACH_KEY = 'approach'
#: The bag format of the temporary approach bags.
_BAG_FORMAT = 'mcap'


class FoldScene(Protocol):
    """What this module reads of a fold's scene: a
    :class:`~speed_sign_detector.training.scene_examples.DetectedScene` (not imported: no
    tool but ``speed_sign_train`` imports the training package)."""

    @property
    def path(self) -> Path:
        """The scene's image file, ``FOLDER/images/FILE``."""

    @property
    def signs(self) -> Sequence[object]:
        """Its annotated signs."""


class ApproachValidationError(SpeedSignError):
    """A fold's approach sequences could not be made or evaluated (the reason names the
    fold and the scene folder)."""


class ApproachFolds:
    """Reads each scene fold's approach sequences with that fold's bank (module docstring).

    A :class:`~speed_sign_detector.training.scene_validation.SceneFoldMeasure`: the scene
    folds call :meth:`measure_fold` once per fold; :meth:`summary` sums the folds.
    """

    key = APPROACH_KEY

    def __init__(self, pipeline_config: PipelineConfig = PipelineConfig(),  # noqa: B008
                 approach_config: ApproachConfig = ApproachConfig(),  # noqa: B008 (frozen)
                 work_dir: Path | None = None) -> None:
        """
        Args:
            pipeline_config: the pipeline that reads the sequences; its
                ``classifier.bank_file`` is replaced by each fold's bank, and
                ``classifier_workers: 0`` (auto) is sized to the host as
                ``speed_sign_eval bag`` sizes it
                (:func:`~speed_sign_detector.classifier_placement.place_classifier`).
            approach_config: the sequences' settings; its ``scenes`` and
                ``max_sequences`` are replaced by each fold's scenes (all their
                sequences).
            work_dir: where the temporary bank, bag and truth files go (a folder of
                their own is made and removed inside it); None: the system's temporary
                folder. Raw 640x480 frames take about 0.9 MB each.
        """
        self.pipeline_config, _ = place_classifier(pipeline_config)
        self.approach_config = approach_config
        self.work_dir = work_dir
        self.per_fold: list[dict[str, Any]] = []

    def measure_fold(self, fold: int, bank: TrainedBank, scenes: Sequence[FoldScene]
                     ) -> None:
        """Read the approach sequences of ``scenes`` with ``bank``.

        Args:
            fold: the fold's index (recorded with its figures).
            bank: the fold's bank, trained without these scenes.
            scenes: the fold's scenes; those without an annotated sign make no sequence.

        Raises:
            ApproachValidationError: the bank cannot be written, or a bag cannot be made
                or read to its end.
        """
        started = time.perf_counter()
        summaries: list[dict[str, Any]] = []
        sequences = 0
        approached: list[str] = []
        unreadable: list[str] = []
        with tempfile.TemporaryDirectory(prefix=f'approach_fold{fold}_',
                                         dir=self.work_dir) as work_name:
            work = Path(work_name)
            bank_path = work / 'bank.npz'
            try:
                save_trained_bank(bank_path, bank)
            except OSError as err:
                raise ApproachValidationError(
                    f'scene fold {fold}: cannot write its bank to {bank_path}: {err}') from err
            config = dataclasses.replace(self.pipeline_config, classifier=dataclasses.replace(
                self.pipeline_config.classifier, bank_file=str(bank_path)))
            for index, (folder, names) in enumerate(_annotated_scenes(scenes)):
                approach = dataclasses.replace(self.approach_config, scenes=names,
                                               max_sequences=0)
                bag_path, truth_path = work / f'approach_{index}', work / f'truth_{index}.csv'
                try:
                    stream = ApproachStream(folder, approach)
                    if not stream.sequences:
                        continue
                    write_truth(truth_path, write_drive(stream, bag_path, _BAG_FORMAT))
                    evaluation = evaluate_bag(bag_path, truth_path=truth_path, config=config,
                                              progress=False)
                except SpeedSignError as err:
                    raise ApproachValidationError(
                        f'scene fold {fold}, approach sequences of {folder}: {err}') from err
                if evaluation.stopped_by is not None:
                    raise ApproachValidationError(
                        f'scene fold {fold}, approach sequences of {folder}: the bag was '
                        f'not read to its end: {evaluation.stopped_by}'
                    ) from evaluation.stopped_by
                summaries.append({**evaluation.summary, **approached_figures(
                    evaluation.summary, stream.approached_track_ids)})
                sequences += len(stream.sequences)
                approached += sorted({f'{folder}/{sequence.scene_file}'
                                      for sequence in stream.sequences})
                unreadable += [f'{folder / "images" / name}: not a readable image'
                               for name in stream.unreadable_scenes]
        last = summaries[-1] if summaries else {}
        figures = {'fold': fold, 'scene_files': approached, **sum_approach_figures(
            summaries, sequences), 'unreadable': unreadable,
            'backend': last.get('backend'), 'classifier': last.get('classifier'),
            'elapsed_s': time.perf_counter() - started}
        self.per_fold.append(figures)
        _LOG.info('scene fold %d approach sequences: %d/%d approached signs recognized, '
                  '%d/%d limit signs in view, in %d sequences, %d wrong limits, time in the '
                  'correct limit %s (%.0f s)', fold, figures['approached_recognized'],
                  figures['approached_signs'], figures['recognized'], figures['signs'],
                  sequences, figures['wrong_limits'],
                  _share(figures['time_in_correct_limit']), figures['elapsed_s'])

    def summary(self) -> dict[str, Any]:
        """The figures of every fold measured, summed (see :func:`sum_approach_figures`),
        with ``'per_fold'`` (each fold's own, with the ``scene_files`` it approached, the
        detector ``backend`` and where the ``classifier`` ran, as ``speed_sign_eval bag``
        reports them, and ``elapsed_s``, seconds), ``'unreadable'`` and the
        ``'settings'`` of the sequences (:class:`ApproachConfig`'s fields)."""
        settings = dataclasses.asdict(self.approach_config)
        for varying in ('scenes', 'max_sequences'):
            settings.pop(varying)
        totals = sum_approach_figures(self.per_fold, sum(row['sequences']
                                                         for row in self.per_fold))
        return {'folds': len(self.per_fold), **totals, 'settings': settings,
                'unreadable': [line for row in self.per_fold for line in row['unreadable']],
                'per_fold': self.per_fold}


def approached_figures(summary: Mapping[str, Any], approached_track_ids: Sequence[int]
                       ) -> dict[str, int]:
    """How many of the approached signs (one per sequence: the sign its view closes in
    on) a bag's evaluation recognized.

    The other signs of a scene are in view too and have truth tracks of their own
    (``signs`` counts them all); many stay small and at the image's edge. The approached
    sign is what a sequence is made for, as a drive passes one sign after another.

    Args:
        summary: a ``speed_sign_eval bag --json`` object with truth (its ``per_sign``).
        approached_track_ids: the truth track of each sequence's approached sign
            (:attr:`~speed_sign_detector.approach_sequences.ApproachStream.
            approached_track_ids`).

    Returns:
        ``{'approached_signs', 'approached_recognized'}``: the approached signs that had
        a truth row (in view at least once) and those recognized.
    """
    wanted = set(approached_track_ids)
    outcomes = [sign for sign in summary['per_sign'] if sign['track_id'] in wanted]
    return {'approached_signs': len(outcomes),
            'approached_recognized': sum(bool(sign['recognized']) for sign in outcomes)}


def sum_approach_figures(summaries: Sequence[Mapping[str, Any]], sequences: int
                         ) -> dict[str, Any]:
    """The approach figures of several bags (or folds) together.

    Args:
        summaries: ``speed_sign_eval bag --json`` objects with truth, or earlier results
            of this function (the same keys).
        sequences: the approach sequences they hold together.

    Returns:
        ``{'sequences', 'frames', ...}`` the per-sign counts of
        :data:`~speed_sign_detector.tools.bag_grading.DRIVE_COUNT_KEYS` summed with
        ``recall`` and ``false_limits_per_hour``, ``drive_time_s`` (seconds), and
        ``time_in_correct_limit`` / ``time_in_correct_limit_strict`` (shares 0..1, None
        when nothing was judged) weighted by ``judged_s`` (seconds, summed), and
        ``approached_signs``, ``approached_recognized`` (:func:`approached_figures`,
        summed) with ``approached_recall`` (None without approached signs).
    """
    counts = {key: sum(int(summary[key]) for summary in summaries)
              for key in DRIVE_COUNT_KEYS}
    drive_time_s = math.fsum(float(summary['drive_time_s']) for summary in summaries)
    judged = [summary for summary in summaries
              if summary.get('time_in_correct_limit') is not None]
    judged_s = math.fsum(float(summary['judged_s']) for summary in judged)

    def weighted(key: str) -> float | None:
        if judged_s <= 0:
            return None
        return math.fsum(float(summary[key]) * float(summary['judged_s'])
                         for summary in judged) / judged_s

    approached = sum(int(summary.get('approached_signs', 0)) for summary in summaries)
    approached_recognized = sum(int(summary.get('approached_recognized', 0))
                                for summary in summaries)
    return {'sequences': sequences,
            'approached_signs': approached, 'approached_recognized': approached_recognized,
            'approached_recall': approached_recognized / approached if approached else None,
            'frames': sum(int(summary['frames']) for summary in summaries),
            **drive_metrics(counts, drive_time_s),
            'time_in_correct_limit': weighted('time_in_correct_limit'),
            'time_in_correct_limit_strict': weighted('time_in_correct_limit_strict'),
            'judged_s': judged_s}


def format_approach_line(figures: Mapping[str, Any], folds: int) -> str:
    """One line of the approach figures (``speed_sign_train validate`` prints it)."""
    recall = figures['recall']
    line = (f'approach sequences, {folds} folds by scene ({figures["sequences"]} sequences, '
            f'{figures["frames"]} frames, each read by the bank of its scenes\' fold): '
            f'{figures["approached_recognized"]}/{figures["approached_signs"]} approached '
            f'signs recognized'
            + (f' ({figures["approached_recall"]:.3f})'
               if figures['approached_recall'] is not None else '')
            + f'; all limit signs in view {figures["recognized"]}/{figures["signs"]}'
            + (f' ({recall:.3f})' if recall is not None else '')
            + f', {figures["wrong_limits"]} wrong limits')
    if figures['end_of_limit_signs'] or figures['wrong_end_of_limits']:
        line += (f', ends of limit {figures["end_of_limit_recognized"]}/'
                 f'{figures["end_of_limit_signs"]} ({figures["wrong_end_of_limits"]} wrong)')
    return (line + f', time in the correct limit {_share(figures["time_in_correct_limit"])}'
            f' (strict {_share(figures["time_in_correct_limit_strict"])}) of '
            f'{figures["judged_s"]:.1f} s')


def _share(value: float | None) -> str:
    return 'n/a' if value is None else f'{value:.3f}'


def _annotated_scenes(scenes: Sequence[FoldScene]) -> list[tuple[Path, tuple[str, ...]]]:
    """(scene folder, the image names of its scenes with an annotated sign), folders
    in order of first appearance, names sorted; a folder without such a scene is left
    out (an empty choice would mean every scene of the folder)."""
    by_folder: dict[Path, set[str]] = {}
    for scene in scenes:
        names = by_folder.setdefault(scene.path.parent.parent, set())
        if scene.signs:
            names.add(scene.path.name)
    return [(folder, tuple(sorted(names))) for folder, names in by_folder.items() if names]
