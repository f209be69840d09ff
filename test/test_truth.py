"""Truth CSV files: round trip, grouping into tracks, and the errors for bad files."""
from __future__ import annotations

from pathlib import Path

import pytest

from speed_sign_detector.errors import TruthFileError
from speed_sign_detector.truth import (
    TRUTH_COLUMNS,
    TruthRow,
    group_tracks,
    read_truth,
    write_truth,
)

ROWS = (
    TruthRow(1700000000.0, 0, 1, '50', 50, 300.0, 200.0, 320.0, 220.0),
    TruthRow(1700000000.1, 1, 1, '50', 50, 302.5, 199.0, 324.5, 221.0),
    TruthRow(1700000000.1, 1, 2, 'no_overtaking', 0, 100.0, 80.0, 112.0, 92.0),
    TruthRow(1700000000.2, 2, 2, 'no_overtaking', 0, 98.0, 79.0, 112.0, 93.0),
)


def test_round_trip_keeps_rows_and_comments_are_skipped(tmp_path: Path) -> None:
    path = tmp_path / 'truth.csv'
    write_truth(path, ROWS, comments=['made by a test'])
    text = path.read_text()
    assert text.startswith('# made by a test\n')
    assert text.splitlines()[1] == ','.join(TRUTH_COLUMNS)
    rows = read_truth(path)
    assert len(rows) == len(ROWS)
    for written, read in zip(ROWS, rows):
        assert read.track_id == written.track_id and read.kind == written.kind
        assert read.limit_kmh == written.limit_kmh and read.frame == written.frame
        assert read.stamp_s == pytest.approx(written.stamp_s, abs=1e-6)
        assert read.x1_px == pytest.approx(written.x1_px, abs=0.01)
        assert read.y2_px == pytest.approx(written.y2_px, abs=0.01)


def test_columns_in_any_order_with_extra_columns(tmp_path: Path) -> None:
    path = tmp_path / 'truth.csv'
    path.write_text('note,x1,y1,x2,y2,kind,limit_kmh,track_id,frame,stamp_s\n'
                    'hello,1,2,11,12,30,30,7,0,5.5\n')
    (row,) = read_truth(path)
    assert (row.track_id, row.kind, row.limit_kmh, row.stamp_s) == (7, '30', 30, 5.5)
    assert row.centre_px == (6.0, 7.0) and row.radius_px == 5.0


def test_group_tracks_orders_by_first_appearance() -> None:
    tracks = group_tracks(reversed(ROWS))
    assert [track.track_id for track in tracks] == [1, 2]
    first = tracks[0]
    assert first.is_limit and first.limit_kmh == 50 and len(first.rows) == 2
    assert first.first_stamp_s == pytest.approx(1700000000.0)
    assert first.last_stamp_s == pytest.approx(1700000000.1)
    assert first.max_radius_px == pytest.approx(11.0)
    assert not tracks[1].is_limit


@pytest.mark.parametrize(('content', 'problem'), [
    ('', 'empty'),
    ('stamp_s,frame,track_id,kind,x1,y1,x2,y2\n', 'limit_kmh'),
    ('stamp_s,frame,track_id,kind,limit_kmh,x1,y1,x2,y2\n0.1,0,1,50,50,1,2,3\n', 'expected 9'),
    ('stamp_s,frame,track_id,kind,limit_kmh,x1,y1,x2,y2\nabc,0,1,50,50,1,2,3,4\n', ':2:'),
    ('stamp_s,frame,track_id,kind,limit_kmh,x1,y1,x2,y2\nnan,0,1,50,50,1,2,3,4\n', 'finite'),
    ('stamp_s,frame,track_id,kind,limit_kmh,x1,y1,x2,y2\n0.1,0,1,50,50,5,2,3,4\n', 'empty'),
    ('stamp_s,frame,track_id,kind,limit_kmh,x1,y1,x2,y2\n0.1,0,1,50,50,1,2,3,4\n'
     '0.2,1,1,60,60,1,2,3,4\n', 'changes'),
])
def test_bad_files_raise_truth_file_error(tmp_path: Path, content: str, problem: str) -> None:
    path = tmp_path / 'bad.csv'
    path.write_text(content)
    with pytest.raises(TruthFileError, match=problem):
        read_truth(path)


def test_missing_file_is_a_truth_file_error(tmp_path: Path) -> None:
    with pytest.raises(TruthFileError, match='cannot read'):
        read_truth(tmp_path / 'absent.csv')
    assert issubclass(TruthFileError, ValueError)
