"""Approach sequences from annotated scenes: geometry and truth against the pixels, the
``speed_sign_synth approach`` command writing real bags (rosbags), and
``speed_sign_eval bag --truth`` grading them through the real pipeline."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scene_helpers import write_gtsdb_scenes

from speed_sign_detector.approach_sequences import (
    GTSDB_CLASS_KINDS,
    ApproachConfig,
    ApproachSceneError,
    ApproachStream,
)
from speed_sign_detector.bag_io import BagReader
from speed_sign_detector.config import ClassifierConfig
from speed_sign_detector.tools import eval as eval_tool
from speed_sign_detector.tools import synth
from speed_sign_detector.truth import group_tracks, read_truth

SCENE_WIDTH, SCENE_HEIGHT = 816, 480
#: Hand-made scenes: (file, [(kind, GTSDB class, diameter px, centre x, centre y)]).
#: The 12 px 30 is too small for its own sequence; the look-alikes stay in the pixels.
SCENES = (
    ('00000.jpg', [('50', 2, 28, 560, 150), ('no_entry', 17, 26, 300, 170)]),
    ('00001.jpg', [('80', 5, 24, 620, 190), ('weight_limit', 16, 24, 470, 140),
                   ('30', 1, 12, 250, 300)]),
)
FRAMES, GAP_FRAMES = 12, 15


@pytest.fixture(scope='module')
def scenes_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A GTSDB-format folder of rendered signs pasted on clutter, with its gt.txt."""
    return write_gtsdb_scenes(tmp_path_factory.mktemp('scenes'), SCENES, SCENE_WIDTH,
                              SCENE_HEIGHT)


def red_centroid(bgr: np.ndarray, box: tuple[float, float, float, float]
                 ) -> tuple[float, float]:
    """Centroid of the sign-red pixels inside a box grown by a quarter, pixels (edge
    coordinates: pixel ``i`` spans ``[i, i + 1)``, like the boxes)."""
    x1, y1, x2, y2 = box
    grow = 0.25 * (x2 - x1)
    left, top = int(max(0, x1 - grow)), int(max(0, y1 - grow))
    patch = bgr[top:int(y2 + grow) + 1, left:int(x2 + grow) + 1].astype(np.int32)
    red = (patch[..., 2] > 120) & (patch[..., 2] - np.maximum(patch[..., 0], patch[..., 1]) > 60)
    rows, columns = np.nonzero(red)
    assert rows.size > 10, 'no red ring where the truth says the sign is'
    return left + columns.mean() + 0.5, top + rows.mean() + 0.5


def test_sequences_close_in_on_each_limit_sign_and_truth_matches_the_pixels(
        scenes_dir: Path) -> None:
    config = ApproachConfig(frames_per_sequence=FRAMES, gap_frames=GAP_FRAMES)
    stream = ApproachStream(scenes_dir, config)
    assert [(s.scene_file, s.sign.limit_kmh) for s in stream.sequences] == [
        ('00000.jpg', 50), ('00001.jpg', 80)]
    frames = list(stream)
    assert len(frames) == stream.frame_count == 2 * (FRAMES + GAP_FRAMES)
    assert [frame.stamp_ns for frame in frames] == [config.stamp_ns(i) for i in range(54)]
    assert all(frame.bgr.shape == (480, 640, 3) for frame in frames)
    centre = np.array([320.0, 240.0])
    for sequence in stream.sequences:
        first = sequence.first_frame
        approach = frames[first:first + FRAMES]
        gap = frames[first + FRAMES:first + FRAMES + GAP_FRAMES]
        rows = [next(row for row in frame.truth if row.limit_kmh) for frame in approach]
        assert len({row.track_id for row in rows}) == 1
        sizes = [row.x2_px - row.x1_px for row in rows]
        original = sequence.sign.x2_px - sequence.sign.x1_px
        assert sizes[0] == pytest.approx(original)          # starts at its real size
        assert 2.0 <= sizes[-1] / sizes[0] <= 3.0           # grows 2-3x
        assert all(later > earlier for earlier, later in zip(sizes, sizes[1:]))
        offsets = [np.hypot(*(np.array(row.centre_px) - centre)) for row in rows]
        assert offsets[-1] > offsets[0] + 50                # drifts outward
        for frame, row in zip(approach[::4] + approach[-1:], rows[::4] + rows[-1:]):
            x, y = red_centroid(frame.bgr, (row.x1_px, row.y1_px, row.x2_px, row.y2_px))
            assert abs(x - row.centre_px[0]) < 1.5 and abs(y - row.centre_px[1]) < 1.5
        assert all(frame.truth == () for frame in gap)      # sign-free gap
        # the stream names the approached sign's truth track, apart from the scene's others
        approached = stream.approached_track_ids[sequence.index]
        assert approached == rows[0].track_id
        assert all(row.limit_kmh == sequence.sign.limit_kmh for frame in approach
                   for row in frame.truth if row.track_id == approached)
    assert len(stream.approached_track_ids) == len(stream.sequences)
    others = {row.track_id for frame in frames for row in frame.truth
              if row.limit_kmh and row.track_id not in stream.approached_track_ids}
    assert others   # the small 30 beside the 80 has a track of its own, not approached
    # the look-alikes in view are listed with their kinds, limit 0
    kinds = {row.kind: row.limit_kmh for frame in frames for row in frame.truth}
    assert kinds['no_entry'] == 0 and kinds['no_trucks'] == 0   # GTSDB classes 17, 16
    # deterministic: the same folder and config give the same pixels
    again = list(ApproachStream(scenes_dir, config))
    assert all(np.array_equal(a.bgr, b.bgr) and a.truth == b.truth
               for a, b in zip(frames, again))


def synth_and_grade(capsys: pytest.CaptureFixture[str], bank_config: Path, scenes: Path,
                    out: Path, *options: str) -> dict[str, Any]:
    """``speed_sign_synth approach`` then ``speed_sign_eval bag --truth --json``."""
    truth = out.with_suffix('.csv')
    status = synth.main(['approach', str(scenes), str(out), '--truth', str(truth), '-q',
                         *options])
    captured = capsys.readouterr()
    assert status == 0, captured.err
    assert f'to {out}' in captured.err
    status = eval_tool.main(['bag', str(out), '--truth', str(truth), '--json',
                             '--config', str(bank_config)])
    captured = capsys.readouterr()
    assert status == 0, captured.err
    return {'summary': json.loads(captured.out.strip().splitlines()[-1]),
            'tracks': group_tracks(read_truth(truth))}


def test_approach_bag_is_graded_by_eval_bag(scenes_dir: Path, bank_config: Path,
                                            tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    graded = synth_and_grade(capsys, bank_config, scenes_dir, tmp_path / 'approach',
                             '--compressed', '--frames', str(FRAMES),
                             '--gap-frames', str(GAP_FRAMES))
    summary, tracks = graded['summary'], graded['tracks']
    assert summary['msgtype'] == 'sensor_msgs/msg/CompressedImage'
    assert summary['frames'] == 2 * (FRAMES + GAP_FRAMES)
    limit_tracks = [track for track in tracks if track.is_limit]
    # the two approached signs, and the small 30 while it is in view
    assert {track.limit_kmh for track in limit_tracks} >= {50, 80}
    assert summary['signs'] == len(limit_tracks)
    outcomes = {row['track_id']: row for row in summary['per_sign']}
    for track in limit_tracks:
        if track.limit_kmh in (50, 80):
            assert outcomes[track.track_id]['recognized'], track.kind
    assert summary['wrong_limits'] == 0
    # judged from the 50 being passed (last approach frame) to the last frame, at 10 Hz
    assert summary['judged_s'] == pytest.approx((2 * (FRAMES + GAP_FRAMES) - FRAMES) / 10,
                                                abs=1e-3)
    assert 0.0 < summary['time_in_correct_limit'] <= 1.0


def test_max_sequences_and_scene_filter_make_a_small_sqlite3_bag(
        scenes_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / 'one'
    status = synth.main(['approach', str(scenes_dir), str(out), '--scenes', '00001.jpg',
                         '--format', 'sqlite3', '--gap-frames', '3', '--frames', '4', '-q'])
    assert status == 0
    with BagReader(out) as bag:
        topic = bag.image_topic()
        assert topic.msgtype == 'sensor_msgs/msg/Image' and topic.count == 7
    out = tmp_path / 'first'
    assert synth.main(['approach', str(scenes_dir), str(out), '--max-sequences', '1',
                       '--gap-frames', '0', '--frames', '3', '-q']) == 0
    with BagReader(out) as bag:
        assert bag.image_topic().count == 3


def test_bad_scene_folders_give_one_line_errors(scenes_dir: Path, tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    assert synth.main(['approach', str(tmp_path / 'missing'), str(tmp_path / 'b1')]) == 1
    assert 'not a GTSDB-format scene folder' in capsys.readouterr().err
    assert synth.main(['approach', str(scenes_dir), str(tmp_path / 'b2'),
                       '--scenes', 'nope.jpg']) == 1
    assert 'nope.jpg not annotated' in capsys.readouterr().err
    with pytest.raises(ApproachSceneError, match='growth'):
        ApproachConfig(growth_min=3.0, growth_max=2.0)
    # one unreadable scene: the others are still written, the status says what was lost
    broken = tmp_path / 'broken'
    (broken / 'images').mkdir(parents=True)
    for name in ('00000.jpg', '00001.jpg'):
        (broken / 'images' / name).write_bytes((scenes_dir / 'images' / name).read_bytes())
    (broken / 'images' / '00001.jpg').write_bytes(b'not a jpeg')
    (broken / 'gt.txt').write_text((scenes_dir / 'gt.txt').read_text())
    truth = tmp_path / 'broken.csv'
    assert synth.main(['approach', str(broken), str(tmp_path / 'b3'), '--truth', str(truth),
                       '--frames', '3', '--gap-frames', '1', '-q']) == 1
    err = capsys.readouterr().err
    assert 'wrote 4 frames' in err and '00001.jpg' in err.splitlines()[-1]
    assert {track.kind for track in group_tracks(read_truth(truth))} == {'50', 'no_entry'}


def test_real_gtsdb_scenes_become_a_graded_approach_bag(
        shared_data_dir: Path, bank_config: Path, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    """Two real scenes (a 50 sign each) through synth approach and eval bag: a limit sign
    whose approach reaches the filter banks' smallest size (no magnification needed) must
    be recognized, and no limit read wrong."""
    scenes = shared_data_dir / 'gtsdb-dev'
    graded = synth_and_grade(capsys, bank_config, scenes, tmp_path / 'real', '--scenes',
                             '00004.jpg,00006.jpg', '--gap-frames', '10')
    summary, tracks = graded['summary'], graded['tracks']
    assert summary['frames'] == 2 * (12 + 10)
    limit_tracks = [track for track in tracks if track.is_limit]
    assert [track.limit_kmh for track in limit_tracks] == [50, 50]
    readable = [track.max_radius_px >= ClassifierConfig().min_radius_px
                for track in limit_tracks]
    assert readable == [True, True]  # the approaches end at the scenes' own sizes
    outcomes = {row['track_id']: row for row in summary['per_sign']}
    assert [outcomes[track.track_id]['recognized'] for track in limit_tracks] == readable
    assert summary['signs'] == 2 and summary['recognized'] == sum(readable)
    assert summary['wrong_limits'] == 0
    assert all(row['kind'] in GTSDB_CLASS_KINDS.values() for row in summary['per_sign'])
    assert summary['judged_s'] == pytest.approx((2 * 22 - 12) / 10, abs=1e-3)
