"""``speed_sign_eval bag``: run a recorded drive through the pipeline, as fast as possible.

Example::

    speed_sign_eval bag drive_day --truth drive_day.csv --out drive_day_result --json

- Reads ROS 2 bags (MCAP, sqlite3) and ROS 1 bags with rosbags; the image topic
  (``sensor_msgs/Image`` or ``CompressedImage``) is found automatically when there is
  only one, else named with ``--topic``.
- Each frame goes through :class:`speed_sign_detector.pipeline.Pipeline` with its
  header stamp (the record time when the stamp is zero), not at the recorded rate.
- ``--out``: a ROS 2 MCAP bag with the node's outputs at the input stamps
  (:mod:`speed_sign_detector.tools.results_bag`): ``/candidates`` (PointCloud2, every
  frame), ``/speed_limit`` (UInt16, transient local, on the first frame and whenever the
  active limit changes, like the node); with ``--debug-images`` ``/debug_image`` (bgr8);
  with ``--with-images`` the input images (``/image/compressed``) and Foxglove
  annotations of the detections (``/image/annotations``).
- ``--contact-sheet PNG``: the drive at a glance, tiles chosen around the limit changes,
  zoomed views of the signs read, and with ``--truth`` the truth and a tile for every
  missed sign (:mod:`speed_sign_detector.tools.contact_sheet`).
- Output paths are checked, and their missing folders created, before the first frame.
- Times are reported as seconds since the first processed frame (``time_s``;
  ``start_stamp_s`` is that frame's stamp).
- ``--truth``: per-sign metrics against a truth file (:mod:`speed_sign_detector.truth`):

  ``signs``
      speed-limit signs (truth tracks with ``limit_kmh > 0``) seen in the processed part,
      less the ``cut_signs``.
  ``cut_signs``
      signs cut off by a truncation or by Ctrl-C: still in view (or within ``--grace``)
      at the last processed frame and not recognized by then. Reported as ``cut`` in
      ``per_sign`` and left out of ``signs`` and ``recall``: nobody knows whether they
      would have been recognized. A complete run has none.
  ``recognized``
      signs whose value was recognized (a track of the pipeline newly recognized that
      limit) while the sign was visible or within ``--grace`` seconds after it left.
  ``recall``
      recognized / signs.
  ``wrong_limits``
      recognitions that match no visible speed-limit sign of that value: any wrong
      value published. Split into ``lookalike_limits`` (a look-alike sign was in view),
      ``misread_limits`` (a limit sign of another value was in view) and
      ``phantom_limits`` (no sign in view).
  ``false_limits_per_hour``
      wrong_limits per hour of drive time (stamps of the processed frames).
  ``drive_time_s``
      that drive time, seconds: the span of the processed frames' stamps plus one frame
      period. Counts and drive times add up over drives: :func:`sum_drive_metrics`
      gives the metrics of many drives (``speed_sign_eval fleet``) through the same
      :func:`drive_metrics` a single drive's come from (both in
      :mod:`speed_sign_detector.tools.bag_grading`, which matches the recognitions to
      the truth signs).
  ``end_of_limit_signs``, ``end_of_limit_recognized``, ``wrong_end_of_limits``
      end-of-limit signs in the truth (kind ``end_of_limit...``), those the pipeline
      recognized as end of limit, and end-of-limit recognitions with no such sign in
      view (each wrongly cancels the active limit).
  ``time_in_correct_limit``, ``time_in_correct_limit_strict``, ``judged_s``
      share of the time after the first limit-setting sign was passed in which the
      published active limit was the limit in force (or announced the next sign while
      it is in view; strict: the limit in force only), and that time in seconds
      (:mod:`speed_sign_detector.limit_in_force`).
  ``fps``, ``latency_ms_p50``, ``latency_ms_p95``
      frames per second over the whole run (reading, decoding, pipeline, writing; the
      detection of a frame overlaps the recognition of the one before, as in the node)
      and the pipeline's processing time per frame (image conversion, detection,
      recognition and tracking), milliseconds.
  ``stage_ms_p50``, ``stage_ms_mean``
      per stage (:data:`speed_sign_detector.pipeline.STAGE_TIMINGS`: ``conversion``,
      ``scaling``, ``gradients``, ``voting``, ``candidates``, ``classify``, ``track``;
      and ``detect``, the whole detection, and ``total``) the median and the mean
      time per frame, milliseconds: where the time goes on this host. The stages of
      STAGE_TIMINGS follow one another, so their means add up to at most the mean
      ``total``.
  ``backend``, ``renderer``, ``backend_choice``
      the detector backend that ran the drive (``gl``, ``cpu`` or ``numpy``; with
      ``auto`` on a software GL renderer, the faster of gl and cpu on the first frames),
      its renderer, and how it was chosen (with both times).
  ``classifier``
      where the classifier ran: ``in this process`` or ``N worker process(es)``
      (``classifier_workers: 0``, the default, is sized to the host as in the node:
      :mod:`speed_sign_detector.classifier_placement`).

A truncated or damaged bag ends the run with a non-zero exit status after the frames
before the damage were processed, reported (the JSON line is still printed) and
written to ``--out``. Ctrl-C does the same for the frames processed so far, with
``"partial": true`` and exit status 130 (``frames`` of ``frames_planned``).

From Python, :func:`evaluate_bag` runs one bag and returns a :class:`BagEvaluation`
whose ``summary`` is exactly the object ``--json`` prints (:func:`summary_json`). It can
reuse a :class:`~speed_sign_detector.pipeline.Pipeline` built once for many bags (reset
before each) and report each frame to a callback.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from speed_sign_detector.bag_io import BagReader, header_stamp_ns
from speed_sign_detector.classifier_placement import place_classifier
from speed_sign_detector.config import PipelineConfig
from speed_sign_detector.config_parameters import load_yaml
from speed_sign_detector.errors import ImageConversionError, SpeedSignError
from speed_sign_detector.limit_in_force import score_time_in_limit
from speed_sign_detector.tools.bag_grading import (  # noqa: F401 (re-exported)
    DEFAULT_GRACE_S,
    DRIVE_COUNT_KEYS,
    EARLY_RECOGNITION_S,
    DriveScore,
    LimitEvent,
    SignOutcome,
    drive_metrics,
    new_limit_events,
    per_hour,
    recall_of,
    score_drive,
    sum_drive_metrics,
)
from speed_sign_detector.tools.cli_types import non_negative_number
from speed_sign_detector.tools.output_paths import (
    prepare_output_bag,
    prepare_output_file,
)
from speed_sign_detector.tools.run_control import (
    EXIT_INTERRUPTED,
    ItemProgress,
    StopRequest,
    stop_on_interrupt,
)
from speed_sign_detector.truth import group_tracks, is_end_of_limit_kind, read_truth

if TYPE_CHECKING:
    from speed_sign_detector.pipeline import FrameResult, Pipeline

#: File endings a contact sheet may have.
CONTACT_SHEET_SUFFIXES: tuple[str, ...] = ('.png', '.jpg', '.jpeg')

FrameCallback = Callable[[int, int | None], None]
"""``on_frame(frames_done, frames_total)`` after each frame of a bag is booked; the total
is the bag index's message count, None when unknown (a salvaged bag). Called on the
recognition thread."""


@dataclass(frozen=True)
class BagEvaluation:
    """What :func:`evaluate_bag` returns.

    Attributes:
        summary: the object ``speed_sign_eval bag --json`` prints (JSON-ready values;
            see the module docstring for the metric fields).
        stopped_by: the error that cut the run short (a truncated or damaged bag), None
            when every frame was processed; ``summary`` covers the frames before it.
    """

    summary: dict[str, Any]
    stopped_by: SpeedSignError | None = None

    def to_json(self) -> str:
        """The summary as one line of JSON (what ``--json`` prints)."""
        return summary_json(self.summary)


def evaluate_bag(bag_path: Path, topic: str | None = None, truth_path: Path | None = None,
                 out_path: Path | None = None, debug_images: bool = False,
                 config: PipelineConfig | None = None, grace_s: float = DEFAULT_GRACE_S,
                 progress: bool = True, contact_sheet_path: Path | None = None,
                 pipeline: Pipeline | None = None, on_frame: FrameCallback | None = None,
                 with_images: bool = False, stop: StopRequest | None = None
                 ) -> BagEvaluation:
    """Run a bag through the pipeline.

    The summary is complete for the frames processed before an error (the evaluation's
    ``stopped_by``) or a stop request (``partial`` true); errors that stop the run
    before any frame (missing bag, no image topic, bad truth file, an output that
    cannot be created) are raised.

    Args:
        bag_path: ROS 2 bag directory, ``.mcap``/``.db3`` file or ROS 1 ``.bag`` file.
        topic: the image topic; None finds the only one.
        truth_path: truth CSV for the per-sign metrics, or None.
        out_path: the results bag (ROS 2 MCAP) to create, or None.
        debug_images: also write ``/debug_image`` into the results bag.
        config: settings of the pipeline built for this bag (ignored with ``pipeline``).
        grace_s: see :func:`score_drive`, seconds.
        progress: show progress on stderr (a bar on a terminal, else log lines).
        contact_sheet_path: PNG of annotated frames to write, or None.
        pipeline: an already built pipeline to use (for many bags in a row): it is reset
            before the bag and stays open afterwards; it must have been created on this
            thread. None builds one from ``config`` and closes it.
        on_frame: called after each frame, see :data:`FrameCallback`.
        with_images: also write the input images and Foxglove annotations into the
            results bag (:mod:`speed_sign_detector.tools.results_bag`).
        stop: when its ``requested`` turns True (Ctrl-C), no further frame is read; the
            frames read so far are finished and reported (``partial`` true).

    Raises:
        SpeedSignError: (BagError, TruthFileError, ...) when nothing could be processed.
    """
    from speed_sign_detector.image_conversion import message_to_gray
    from speed_sign_detector.overlapped_pipeline import OverlappedPipeline
    from speed_sign_detector.pipeline import Pipeline
    from speed_sign_detector.tools.contact_sheet import ContactSheetCollector
    from speed_sign_detector.tools.results_bag import ResultsBagWriter

    tracks = group_tracks(read_truth(truth_path)) if truth_path is not None else None
    stopped_by: SpeedSignError | None = None
    stamps_s: list[float] = []
    latencies_ms: list[float] = []
    stage_samples_ms: dict[str, list[float]] = {}
    events: list[LimitEvent] = []
    recognized_ids: set[int] = set()
    limit_changes: list[tuple[float, int]] = []
    interrupted = sheet_written = False
    with BagReader(bag_path) as bag:
        image_topic = bag.image_topic(topic)
        frames_total = image_topic.count if image_topic.count >= 0 else None
        writer = (ResultsBagWriter(out_path, debug_images, with_images)
                  if out_path is not None else None)
        sheet = (ContactSheetCollector(contact_sheet_path, frames_total, tracks)
                 if contact_sheet_path is not None else None)
        bar = ItemProgress(frames_total, 'frames', 'frame', enabled=progress)
        started = time.perf_counter()
        owns_pipeline = pipeline is None
        if pipeline is None:
            pipeline = Pipeline(config or PipelineConfig())
        else:
            pipeline.reset()   # a new drive: no tracks or active limit from the last bag
        try:
            backend, renderer = pipeline.backend_name, pipeline.renderer
            active_limit = 0
            recognition_errors: list[SpeedSignError] = []

            def finish_frame(result: FrameResult,
                             context: tuple[int, str, np.ndarray, Any]) -> None:
                """Book one frame's result (recognition thread; frames in order)."""
                nonlocal active_limit
                stamp_ns, frame_id, gray, message = context
                latencies_ms.append(result.timings_ms['total'])
                for stage, duration_ms in result.timings_ms.items():
                    stage_samples_ms.setdefault(stage, []).append(duration_ms)
                stamps_s.append(stamp_ns * 1e-9)
                new_events = new_limit_events(result, recognized_ids)
                events.extend(new_events)
                if sheet is not None:
                    sheet.offer(len(stamps_s) - 1, stamp_ns * 1e-9, gray, result, new_events)
                if result.active_limit_kmh != active_limit:
                    active_limit = result.active_limit_kmh
                    limit_changes.append((stamp_ns * 1e-9, active_limit))
                if writer is not None:
                    writer.write(stamp_ns, frame_id, gray, result, message)
                bar.update()
                if on_frame is not None:
                    on_frame(len(stamps_s), frames_total)

            def recognition_failed(error: Exception, context: tuple[int, str, np.ndarray, Any]
                                   ) -> None:
                recognition_errors.append(SpeedSignError(
                    f'frame stamped {context[0]} ns could not be recognized: '
                    f'{type(error).__name__}: {error}'))

            loop_started = time.perf_counter()
            # detection of a frame overlaps the recognition of the one before
            stages = OverlappedPipeline(pipeline, finish_frame, recognition_failed)
            try:
                for submitted, item in enumerate(bag.messages(image_topic.name)):
                    if stop is not None and stop.requested:
                        interrupted = True
                        break
                    if recognition_errors:
                        raise recognition_errors[0]
                    stamp_ns = header_stamp_ns(item.message, item.log_time_ns)
                    frame_id = str(getattr(getattr(item.message, 'header', None),
                                           'frame_id', ''))
                    try:
                        converting = time.perf_counter()
                        gray = message_to_gray(item.message)
                        stages.submit(gray, stamp_ns * 1e-9,
                                      context=(stamp_ns, frame_id, gray, item.message),
                                      conversion_ms=(time.perf_counter() - converting) * 1e3)
                    except ValueError as err:
                        if isinstance(err, SpeedSignError):
                            raise
                        raise ImageConversionError(
                            f'frame {submitted} of {image_topic.name} cannot be '
                            f'processed: {err}') from err
                stages.drain()
                if recognition_errors:
                    raise recognition_errors[0]
            except SpeedSignError as err:
                stopped_by = err
            finally:
                stages.close()  # the frames submitted before a failure are still booked
                bar.close()
                if writer is not None:
                    writer.close()
            if sheet is not None:
                header = (f'{Path(bag_path).name}: {len(stamps_s)} frames of '
                          f'{image_topic.name}, {_span_s(stamps_s):.1f} s of drive')
                notes = [f'limits published (confirmed by the tracker): '
                         f'{_event_times(events, stamps_s)}']
                if stopped_by is not None or interrupted:
                    notes.append(f'stopped early: {stopped_by or "interrupted (Ctrl-C)"}')
                try:
                    outcomes = None if tracks is None else score_drive(
                        tracks, events, stamps_s, grace_s, stopped_early=interrupted
                        or stopped_by is not None or bag.salvage_reason is not None).outcomes
                    sheet_written = sheet.write(header, notes, outcomes)
                except SpeedSignError as err:   # the metrics are still reported
                    stopped_by = stopped_by or err
            # backend auto may have chosen another backend after timing the first frames
            backend, renderer = pipeline.backend_name, pipeline.renderer
            backend_choice = pipeline.backend_choice
            classifier_location = pipeline.classifier_location
        finally:
            if owns_pipeline:
                pipeline.close()
        elapsed_s = time.perf_counter() - started
        loop_s = time.perf_counter() - loop_started
        salvage_reason = bag.salvage_reason
    frames = len(stamps_s)
    start_stamp_s = stamps_s[0] if frames else None
    summary: dict[str, Any] = {
        'bag': str(bag_path), 'topic': image_topic.name, 'msgtype': image_topic.msgtype,
        'frames': frames, 'frames_planned': frames_total, 'partial': interrupted,
        'start_stamp_s': start_stamp_s,
        'duration_s': round(_span_s(stamps_s), 6),
        'backend': backend, 'renderer': renderer, 'backend_choice': backend_choice,
        'classifier': classifier_location,
        'fps': frames / loop_s if loop_s > 0 else 0.0,
        'latency_ms_p50': float(np.percentile(latencies_ms, 50)) if latencies_ms else None,
        'latency_ms_p95': float(np.percentile(latencies_ms, 95)) if latencies_ms else None,
        'stage_ms_p50': {stage: float(np.percentile(samples, 50))
                         for stage, samples in stage_samples_ms.items()},
        'stage_ms_mean': {stage: float(np.mean(samples))
                          for stage, samples in stage_samples_ms.items()},
        'elapsed_s': elapsed_s,
        'limit_events': [{'stamp_s': e.stamp_s, 'time_s': round(e.stamp_s - stamps_s[0], 6),
                          'limit_kmh': e.limit_kmh,
                          'x_px': None if math.isnan(e.x_px) else round(e.x_px, 1),
                          'y_px': None if math.isnan(e.y_px) else round(e.y_px, 1)}
                         for e in events],
        'final_limit_kmh': limit_changes[-1][1] if limit_changes else 0,
        'out_bag': str(out_path) if out_path is not None else None,
        'contact_sheet': str(contact_sheet_path) if sheet_written else None,
        'truncated': stopped_by is not None or salvage_reason is not None,
        'error': str(stopped_by) if stopped_by is not None else None,
    }
    if tracks is not None:
        score = score_drive(tracks, events, stamps_s, grace_s,
                            stopped_early=interrupted or summary['truncated'])
        summary.update({'truth': str(truth_path), 'grace_s': grace_s})
        summary.update(drive_metrics({key: getattr(score, key) for key in DRIVE_COUNT_KEYS},
                                     score.drive_time_s))
        summary['cut_signs'] = score.cut_signs
        summary['per_sign'] = [asdict(outcome) for outcome in score.outcomes]
        summary.update(asdict(score_time_in_limit(tracks, stamps_s, limit_changes)))
    return BagEvaluation(summary, stopped_by)


def _span_s(stamps_s: Sequence[float]) -> float:
    """Seconds from the first to the last stamp (0 for fewer than two)."""
    return stamps_s[-1] - stamps_s[0] if len(stamps_s) > 1 else 0.0


def _event_times(events: Sequence[LimitEvent], stamps_s: Sequence[float]) -> str:
    """``'50 at 3.20 s, end at 9.87 s'``: recognitions, seconds since the first frame."""
    return ', '.join(f'{event.limit_kmh or "end"} at {event.stamp_s - stamps_s[0]:.2f} s'
                     for event in events) or 'none'


#: What the per-sign table's columns mean (printed under it).
TABLE_LEGEND = ('columns: from s / to s = first and last time the sign is in view, s since '
                'the first frame; max r = its largest radius, px; after s = time from its '
                'first appearance to its recognition, s; r px = its radius then; wrong = '
                'values wrongly read on it')


def format_report(summary: dict[str, Any]) -> str:
    """Human-readable per-sign table and summary (times: seconds since the first frame)."""
    lines = []
    if 'per_sign' in summary:
        lines.append(f'{"sign":>5} {"kind":<22} {"limit":>5} {"from s":>7} {"to s":>7} '
                     f'{"max r":>6} {"result":<10} {"after s":>7} {"r px":>5}  wrong')
        for row in summary['per_sign']:
            if row.get('cut'):
                result = 'cut'
            elif row['limit_kmh'] > 0:
                result = 'recognized' if row['recognized'] else 'MISSED'
            elif is_end_of_limit_kind(row['kind']):
                result = 'end read' if row['recognized'] else 'end missed'
            else:
                result = 'look-alike'
            after = (f'{row["recognized_after_s"]:7.2f}'
                     if row['recognized_after_s'] is not None else f'{"-":>7}')
            radius = (f'{row["radius_at_recognition_px"]:5.1f}'
                      if row['radius_at_recognition_px'] is not None else f'{"-":>5}')
            wrong = ','.join(str(value) if value else 'end'
                             for value in row['wrong_values']) or '-'
            lines.append(f'{row["track_id"]:>5} {row["kind"]:<22} {row["limit_kmh"]:>5} '
                         f'{row["first_s"]:7.2f} {row["last_s"]:7.2f} '
                         f'{row["max_radius_px"]:6.1f} {result:<10} {after} {radius}  {wrong}')
        lines.append(TABLE_LEGEND)
        lines.append('')
        recall = summary['recall']
        cut = (f' ({summary["cut_signs"]} more cut off by the early stop: not counted)'
               if summary.get('cut_signs') else '')
        lines.append((f'signs {summary["signs"]}, recognized {summary["recognized"]}, recall '
                      f'{recall:.3f}' if recall is not None else
                      'signs 0 (no speed-limit sign in the truth)') + cut)
        lines.append(f'wrong limits {summary["wrong_limits"]} (look-alike '
                     f'{summary["lookalike_limits"]}, misread {summary["misread_limits"]}, '
                     f'phantom {summary["phantom_limits"]}), '
                     f'{summary["false_limits_per_hour"]:.1f} per hour')
        lines.append(f'end-of-limit signs {summary["end_of_limit_signs"]}, read '
                     f'{summary["end_of_limit_recognized"]}, wrong end-of-limit '
                     f'{summary["wrong_end_of_limits"]}')
        if summary.get('time_in_correct_limit') is not None:
            lines.append(f'time in correct limit {100 * summary["time_in_correct_limit"]:.1f} % '
                         f'of {summary["judged_s"]:.1f} s after the first sign (strict '
                         f'{100 * summary["time_in_correct_limit_strict"]:.1f} %)')
    p50, p95 = summary['latency_ms_p50'], summary['latency_ms_p95']
    lines.append(f'{summary["frames"]} frames of {summary["topic"]} ({summary["msgtype"]}), '
                 f'{summary["duration_s"]:.1f} s of drive; {summary["fps"]:.1f} fps, latency '
                 + (f'p50 {p50:.1f} ms, p95 {p95:.1f} ms' if p50 is not None else 'n/a')
                 + f'; backend {summary["backend"]} ({summary["renderer"]}; '
                 f'{summary["backend_choice"]}); classifier {summary["classifier"]}')
    limits = ', '.join(f'{event["limit_kmh"] or "end"} at {event["time_s"]:.2f} s'
                       for event in summary['limit_events']) or 'none'
    lines.append(f'limits recognized: {limits} (s since the first frame)')
    if summary['out_bag']:
        lines.append(f'results written to {summary["out_bag"]}')
    if summary.get('contact_sheet'):
        lines.append(f'contact sheet written to {summary["contact_sheet"]}')
    if summary['error']:
        lines.append(f'STOPPED EARLY: {summary["error"]}')
    if summary.get('partial'):
        planned = summary['frames_planned']
        lines.append(f'PARTIAL: interrupted after {summary["frames"]} of '
                     f'{planned if planned is not None else "?"} frames')
    return '\n'.join(lines)


def add_pipeline_options(parser: argparse.ArgumentParser) -> None:
    """The options of ``eval bag`` and ``eval fleet`` that set the pipeline and the grading:
    ``--config``, ``--backend``, ``--grace``."""
    parser.add_argument('--config', type=Path, help='parameter YAML file of the node')
    parser.add_argument('--backend', choices=('auto', 'gl', 'cpu', 'numpy'),
                        help='detector backend (overrides --config)')
    parser.add_argument('--grace', type=non_negative_number, default=DEFAULT_GRACE_S,
                        help=f'seconds after a sign leaves the image within which '
                        f'recognizing it still counts (default {DEFAULT_GRACE_S:g})')


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``bag`` subcommand to ``speed_sign_eval``."""
    parser = subparsers.add_parser(
        'bag', help='run a recorded drive (ROS 2 MCAP/sqlite3 or ROS 1 bag) through the '
        'pipeline', description='Run the image topic of a bag through the pipeline as fast '
        'as possible; with --truth, per-sign metrics (recall, wrong limits, false limits '
        'per hour); with --out, a ROS 2 MCAP bag of the node\'s outputs (with --with-images, '
        'viewable in Foxglove). Output paths are checked (missing folders created) before '
        'the first frame. Ctrl-C reports the frames done, marked partial (exit status 130); '
        'a truncated bag reports the frames before the cut (exit status 1).')
    parser.add_argument('bag', type=Path, help='ROS 2 bag directory, .mcap/.db3 file, or '
                        'ROS 1 .bag file')
    parser.add_argument('--topic', help='image topic (needed when the bag has several)')
    parser.add_argument('--truth', type=Path, help='truth CSV for per-sign metrics')
    parser.add_argument('--out', type=Path, help='write the outputs into this new ROS 2 '
                        'MCAP bag (/candidates, /speed_limit)')
    parser.add_argument('--debug-images', action='store_true',
                        help='with --out, also write /debug_image (bgr8 drawings)')
    parser.add_argument('--with-images', action='store_true',
                        help='with --out, also write the input images (/image/compressed) '
                        'and Foxglove annotations of the detections (/image/annotations)')
    parser.add_argument('--contact-sheet', type=Path, metavar='PNG',
                        help='write the drive at a glance as one picture (.png or .jpg): '
                        'frames around the limit changes with zoomed views of the signs '
                        'read (published or single-frame); with --truth also the truth '
                        'and a tile for every missed sign')
    add_pipeline_options(parser)
    parser.add_argument('--json', action='store_true',
                        help='print the summary as one JSON object (last stdout line)')
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``speed_sign_eval bag``; returns the exit status."""
    config = load_yaml(args.config) if args.config is not None else PipelineConfig()
    if args.backend is not None:
        config = dataclasses.replace(config, backend=args.backend)
    config, _ = place_classifier(config)   # auto workers sized to the host, as in the node
    for option, given in (('--debug-images', args.debug_images),
                          ('--with-images', args.with_images)):
        if given and args.out is None:
            print(f'speed_sign_eval bag: {option} has no effect without --out',
                  file=sys.stderr)
    if args.out is not None:
        prepare_output_bag(args.out, '--out')
    if args.contact_sheet is not None:
        prepare_output_file(args.contact_sheet, '--contact-sheet', CONTACT_SHEET_SUFFIXES)
    with stop_on_interrupt('speed_sign_eval bag') as stop:
        evaluation = evaluate_bag(args.bag, args.topic, args.truth, args.out,
                                  args.debug_images, config, args.grace,
                                  contact_sheet_path=args.contact_sheet,
                                  with_images=args.with_images, stop=stop)
    if args.json:
        print(evaluation.to_json())
    else:
        print(format_report(evaluation.summary))
    if evaluation.stopped_by is not None:
        raise evaluation.stopped_by
    return EXIT_INTERRUPTED if evaluation.summary['partial'] else 0


def summary_json(summary: Mapping[str, Any]) -> str:
    """A summary as one line of JSON, as ``speed_sign_eval bag --json`` prints it."""
    return json.dumps(summary, default=numpy_json_default)


def numpy_json_default(value: Any) -> Any:
    """``json.dumps`` ``default``: numpy scalars as Python values."""
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f'{type(value).__name__} is not JSON serializable')
