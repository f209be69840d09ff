"""The contact sheet of ``speed_sign_eval bag --contact-sheet`` on a real short synthetic
drive (written by the installed ``speed_sign_synth``): zoomed views of the signs read,
the truth drawn with what became of each sign, a tile for every missed sign, and
published limits told apart from single-frame readings.

The sheet's choices are read as data (:class:`SheetTile`) from the collector that
``speed_sign_eval bag`` used (recorded, not replaced); the expectations come from the
truth file, the frames' results and the run's JSON summary. To be sure of a missed
sign, the truth of one limit sign is changed to a value the classifier has no class for
(its value + 5): nothing can recognize it, and the value read on it is wrong.
"""
from __future__ import annotations

import contextlib
import io
import json
import subprocess
import sys
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from speed_sign_detector.pipeline import FrameResult
from speed_sign_detector.recognition.classification import LABEL_END_OF_LIMIT
from speed_sign_detector.tools import contact_sheet
from speed_sign_detector.tools import eval as eval_tool
from speed_sign_detector.tools.contact_sheet_drawing import (
    CAPTION_HEIGHT_PX,
    SheetTile,
    SignZoom,
    legend_lines,
)
from speed_sign_detector.truth import (
    TruthRow,
    TruthTrack,
    group_tracks,
    is_end_of_limit_kind,
    read_truth,
    write_truth,
)

#: A drive with a 30, a 20 and an end-of-limit sign, at 10 fps to keep the run short.
SYNTH_OPTIONS = ('--seed', '7', '--duration', '10.5', '--fps', '10', '--lighting', 'mixed',
                 '--compressed')
FRAME_WIDTH_PX, FRAME_HEIGHT_PX = 640, 480   # the synthetic camera
HEADER_HEIGHT_PX = 34


@dataclass
class SheetRun:
    """One ``speed_sign_eval bag --contact-sheet`` run and what its collector saw."""

    summary: dict[str, Any]
    png: Path
    tracks: tuple[TruthTrack, ...]
    relabelled_track_id: int
    offers: list[tuple[int, float, np.ndarray, FrameResult, list[Any]]]
    outcomes: Sequence[Any]
    tiles: list[SheetTile]             # the sheet's tiles
    every_frame_tiles: list[SheetTile]  # the same frames offered to a collector keeping all


@pytest.fixture(scope='module')
def sheet_run(tmp_path_factory: pytest.TempPathFactory, bank_config: Path) -> SheetRun:
    folder = tmp_path_factory.mktemp('contact_sheet')
    drive, truth = folder / 'drive', folder / 'truth.csv'
    synth = subprocess.run([str(Path(sys.executable).parent / 'speed_sign_synth'), str(drive),
                            '--truth', str(truth), *SYNTH_OPTIONS],
                           capture_output=True, text=True, timeout=600)
    assert synth.returncode == 0, synth.stderr
    rows = read_truth(truth)
    relabelled = [track for track in group_tracks(rows) if track.is_limit][-1]
    value = relabelled.limit_kmh + 5
    rows = tuple(replace(row, kind=str(value), limit_kmh=value)
                 if row.track_id == relabelled.track_id else row for row in rows)
    write_truth(truth, rows)

    offers: list[tuple[int, float, np.ndarray, FrameResult, list[Any]]] = []
    written: list[tuple[contact_sheet.ContactSheetCollector, Any]] = []

    class RecordingCollector(contact_sheet.ContactSheetCollector):
        """The real collector, recording what it was offered and its tiles."""

        def offer(self, index: int, stamp_s: float, gray: np.ndarray, result: FrameResult,
                  recognized: Sequence[Any]) -> None:
            offers.append((index, stamp_s, gray, result, list(recognized)))
            super().offer(index, stamp_s, gray, result, recognized)

        def write(self, header: str, notes: list[str], outcomes: Any = None) -> bool:
            done = super().write(header, notes, outcomes)
            written.append((self, outcomes))
            return done

    png = folder / 'sheet.png'
    stdout, stderr = io.StringIO(), io.StringIO()
    with pytest.MonkeyPatch.context() as patch, contextlib.redirect_stdout(stdout), \
            contextlib.redirect_stderr(stderr):
        patch.setattr(contact_sheet, 'ContactSheetCollector', RecordingCollector)
        status = eval_tool.main(['bag', str(drive), '--truth', str(truth), '--contact-sheet',
                                 str(png), '--json', '--config', str(bank_config)])
    assert status == 0, stderr.getvalue()
    summary = json.loads(stdout.getvalue().strip().splitlines()[-1])
    assert len(written) == 1 and summary['contact_sheet'] == str(png)
    collector, outcomes = written[0]
    tracks = group_tracks(rows)
    keeping_all = contact_sheet.ContactSheetCollector(folder / 'unused.png', len(offers),
                                                      tracks, sheet_tiles=len(offers))
    for index, stamp_s, gray, result, recognized in offers:
        keeping_all.offer(index, stamp_s, gray, result, recognized)
    every_frame_tiles = keeping_all.tiles(outcomes)
    assert len(every_frame_tiles) == len(offers)
    return SheetRun(summary, png, tracks, relabelled.track_id, offers, outcomes,
                    collector.last_tiles, every_frame_tiles)


def _missed(summary: dict[str, Any]) -> list[dict[str, Any]]:
    """Limit and end-of-limit signs of the per-sign table never recognized."""
    return [row for row in summary['per_sign']
            if (row['limit_kmh'] > 0 or is_end_of_limit_kind(row['kind']))
            and not row['recognized'] and not row['cut']]


def _largest_view(track: TruthTrack) -> TruthRow:
    """The row where the sign is largest, among those whole in the frame if any."""
    def whole(row: TruthRow) -> bool:
        return (row.x1_px >= 0 and row.y1_px >= 0 and row.x2_px <= FRAME_WIDTH_PX
                and row.y2_px <= FRAME_HEIGHT_PX)
    return max(track.rows, key=lambda row: (whole(row), row.radius_px))


def _zooms(tiles: list[SheetTile], subject: str) -> list[tuple[SheetTile, SignZoom]]:
    return [(tile, zoom) for tile in tiles for zoom in tile.zooms if zoom.subject == subject]


def test_every_missed_sign_has_a_tile_of_its_own_at_its_largest_view(sheet_run: SheetRun
                                                                       ) -> None:
    missed = _missed(sheet_run.summary)
    missed_ids = {row['track_id'] for row in missed}
    assert sheet_run.relabelled_track_id in missed_ids   # its value is in no image
    tracks = {track.track_id: track for track in sheet_run.tracks}
    assert {track_id for tile in sheet_run.tiles
            for track_id in tile.missed_track_ids} == missed_ids
    for track_id in missed_ids:
        track = tracks[track_id]
        tiles = [tile for tile in sheet_run.tiles if track_id in tile.missed_track_ids]
        assert len(tiles) == 1
        tile = tiles[0]
        assert tile.frame_index == _largest_view(track).frame
        shown = (str(track.limit_kmh) if track.limit_kmh else 'end of limit')
        assert f'{shown} MISSED' in tile.reasons
        zoom = tile.zooms[0]   # the missed sign comes first
        assert (zoom.subject, zoom.truth_track_id, zoom.verdict) == ('truth', track_id,
                                                                     'missed')
        assert zoom.image.shape[0] >= 64 and zoom.image.shape[1] >= 64
        assert 'MISSED, never recognized' in zoom.lines[0][1]
        boxes = [mark for mark in tile.marks if mark.shape == 'box'
                 and mark.words.startswith(f'{shown} ')]
        assert len(boxes) == 1 and boxes[0].style in ('missed', 'wrong')
    # a value published on the relabelled sign is named in its zoom
    relabelled = next(row for row in sheet_run.summary['per_sign']
                      if row['track_id'] == sheet_run.relabelled_track_id)
    zoom = next(zoom for tile in sheet_run.tiles for zoom in tile.zooms
                if zoom.subject == 'truth' and zoom.truth_track_id == relabelled['track_id'])
    for value in relabelled['wrong_values']:
        assert str(value or 'end') in zoom.lines[1][1] and zoom.lines[1][0] == 'wrong'


def test_every_sign_read_has_a_zoomed_view_of_at_least_64_px(sheet_run: SheetRun) -> None:
    tiles = {tile.frame_index: tile for tile in sheet_run.every_frame_tiles}
    readings_in_all = 0
    for index, _, _, result, _ in sheet_run.offers:
        readings = sum(detection.classification is not None
                       and (detection.classification.is_limit
                            or detection.classification.label == LABEL_END_OF_LIMIT)
                       for detection in result.detections)
        readings_in_all += readings
        tile = tiles[index]
        zoomed = [zoom for zoom in tile.zooms if zoom.subject == 'reading']
        assert len(zoomed) + tile.more_readings == readings, index
        assert tile.more_readings == 0 or len(tile.zooms) == contact_sheet.MOST_ZOOMS
    assert readings_in_all > 0
    for tile in sheet_run.tiles + sheet_run.every_frame_tiles:
        for zoom in tile.zooms:
            assert zoom.image.ndim == 2 and min(zoom.image.shape) >= 64


def test_published_limits_are_told_apart_from_single_frame_readings(sheet_run: SheetRun
                                                                    ) -> None:
    """A reading is published when its value became a published limit on its track; any
    other reading is a single-frame reading (a value never published on the drive:
    :func:`test_a_value_never_published_is_shown_as_a_single_frame_reading`)."""
    published_at: dict[str, list[float]] = {}
    for event in sheet_run.summary['limit_events']:
        label = str(event['limit_kmh']) if event['limit_kmh'] else LABEL_END_OF_LIMIT
        published_at.setdefault(label, []).append(event['time_s'])
    zooms = [zoom for _, zoom in _zooms(sheet_run.every_frame_tiles, 'reading')]
    for zoom in zooms:
        style, words = zoom.lines[0]
        if zoom.published:
            assert style == 'published'
            assert words.startswith('read ') and ': published at ' in words
            time_s = float(words.split(': published at ')[1].removesuffix(' s'))
            assert min(abs(time_s - event_s) for event_s in published_at[zoom.label]) < 0.006
        else:
            assert style != 'published' and words.endswith(': single frame, not published')
        if zoom.label not in published_at:
            assert not zoom.published
    assert any(zoom.published for zoom in zooms)


def test_a_value_never_published_is_shown_as_a_single_frame_reading(
        sheet_run: SheetRun, tmp_path: Path) -> None:
    """A value read on a sign but never published there (like the issue's "80" on a 60
    sign) is drawn as a single-frame reading. The drive's own misreadings come and go
    with the bank, so one frame's reading of a published limit is turned into a value
    the drive never published, and the frames are offered to a new collector."""
    published = {str(event['limit_kmh']) for event in sheet_run.summary['limit_events']
                 if event['limit_kmh']}
    value = next(kmh for kmh in (110, 90, 130, 40) if str(kmh) not in published)
    changed_frame = None
    collector = contact_sheet.ContactSheetCollector(
        tmp_path / 'unused.png', len(sheet_run.offers), sheet_run.tracks,
        sheet_tiles=len(sheet_run.offers))
    for index, stamp_s, gray, result, recognized in sheet_run.offers:
        readings = [position for position, detection in enumerate(result.detections)
                    if detection.classification is not None
                    and str(detection.classification.limit_kmh) in published]
        if changed_frame is None and readings:
            detections = list(result.detections)
            detection = detections[readings[0]]
            detections[readings[0]] = replace(detection, classification=replace(
                detection.classification, label=str(value), limit_kmh=value))
            result = replace(result, detections=tuple(detections))
            changed_frame = index
        collector.offer(index, stamp_s, gray, result, recognized)
    assert changed_frame is not None, 'the drive should hold a reading of a published limit'
    zooms = [zoom for _, zoom in _zooms(collector.tiles(sheet_run.outcomes), 'reading')
             if zoom.label == str(value)]
    assert len(zooms) == 1
    style, words = zooms[0].lines[0]
    assert not zooms[0].published
    assert style == 'single_frame' and words.endswith(': single frame, not published')


def test_readings_are_judged_against_the_truth_sign_they_lie_on(sheet_run: SheetRun
                                                                ) -> None:
    tracks = {track.track_id: track for track in sheet_run.tracks}
    judged = _zooms(sheet_run.every_frame_tiles, 'reading')
    for tile, zoom in judged:
        style, words = zoom.lines[1]
        if zoom.truth_track_id < 0:
            assert (zoom.verdict, style) == ('wrong', 'wrong')
            assert words == 'no sign in the truth here: WRONG'
            continue
        track = tracks[zoom.truth_track_id]
        assert any(row.frame == tile.frame_index for row in track.rows)   # in view
        right = (zoom.label == str(track.limit_kmh) if track.is_limit
                 else zoom.label == LABEL_END_OF_LIMIT and track.is_end_of_limit)
        assert zoom.verdict == ('right' if right else 'wrong')
        assert words.endswith('reading right' if right else 'WRONG')
    on_relabelled = [zoom for _, zoom in judged
                     if zoom.truth_track_id == sheet_run.relabelled_track_id]
    assert on_relabelled and all(zoom.verdict == 'wrong' for zoom in on_relabelled)


def test_truth_boxes_say_what_became_of_each_sign(sheet_run: SheetRun) -> None:
    per_sign = {row['track_id']: row for row in sheet_run.summary['per_sign']}

    def expected(row: dict[str, Any]) -> str:
        if row['cut']:
            return 'cut'
        if row['wrong_values']:
            return 'wrong'
        if row['limit_kmh'] > 0 or is_end_of_limit_kind(row['kind']):
            return 'right' if row['recognized'] else 'missed'
        return 'lookalike'

    boxes_seen = 0
    for tile in sheet_run.tiles:
        scale = tile.picture.shape[1] / FRAME_WIDTH_PX
        rows = [row for track in sheet_run.tracks for row in track.rows
                if row.frame == tile.frame_index]
        boxes = [mark for mark in tile.marks if mark.shape == 'box']
        assert len(boxes) == len(rows)
        for row in rows:
            box = next(mark for mark in boxes if abs(mark.x1_px - row.x1_px * scale) < 1e-6
                       and abs(mark.y1_px - row.y1_px * scale) < 1e-6)
            verdict = expected(per_sign[row.track_id])
            assert box.style == verdict
            word = {'right': 'right', 'wrong': 'WRONG', 'missed': 'MISSED',
                    'lookalike': 'look-alike', 'cut': 'cut off'}[verdict]
            assert box.words.endswith(word)
            boxes_seen += 1
    assert boxes_seen > 0
    styles = {box.style for tile in sheet_run.tiles for box in tile.marks
              if box.shape == 'box'}
    assert {'right', 'wrong'} <= styles


def test_the_png_shows_the_zooms_and_a_legend_in_plain_words(sheet_run: SheetRun) -> None:
    sheet = cv2.imread(str(sheet_run.png))
    assert sheet is not None and sheet.shape[1] == 1280
    tile = sheet_run.tiles[0]
    assert tile.zooms
    top = HEADER_HEIGHT_PX + CAPTION_HEIGHT_PX + tile.picture.shape[0] + 3
    zoom = tile.zooms[0].image
    drawn = sheet[top:top + zoom.shape[0], 4:4 + zoom.shape[1]]
    inner = (slice(2, -2), slice(2, -2))   # inside the coloured border
    assert np.array_equal(drawn[inner], cv2.cvtColor(zoom, cv2.COLOR_GRAY2BGR)[inner])
    legend = ' '.join(words for _, words in legend_lines(True))
    assert 'correlation peak strength' in legend
    for words in ('single-frame reading', 'published', 'MISSED', 'WRONG', '"right"',
                  'zoomed views'):
        assert words in legend
    assert 'truth' not in ' '.join(words for _, words in legend_lines(False))
