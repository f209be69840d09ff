"""``speed_sign_eval bag`` end to end: real bags (rosbags) of a synthetic drive, the real
pipeline, metrics against the synthetic truth, results bags read back with rosbags."""
from __future__ import annotations

import contextlib
import io
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from speed_sign_detector.bag_io import BagReader, BagWriter, header_stamp_ns
from speed_sign_detector.ros.messages import CANDIDATE_DTYPE, pointcloud_to_array
from speed_sign_detector.synthetic import DriveConfig, SyntheticDrive
from speed_sign_detector.tools import eval as eval_tool
from speed_sign_detector.tools import eval_bag
from speed_sign_detector.tools.synth import write_drive
from speed_sign_detector.truth import group_tracks, write_truth

#: 2.6 s at 20 fps: one speed-limit sign approaching from ~9 px to ~45 px radius.
CONFIG = DriveConfig(seed=1, duration_s=2.6, fps=20)


Evaluate = Callable[..., tuple[int, str, str]]


@pytest.fixture()
def evaluate(capsys: pytest.CaptureFixture[str], bank_config: Path) -> Evaluate:
    """Run ``speed_sign_eval bag ARGS --config BANK_CONFIG``: (status, stdout, stderr)."""
    def run(*args: str) -> tuple[int, str, str]:
        status = eval_tool.main(['bag', *args, '--config', str(bank_config)])
        captured = capsys.readouterr()
        return status, captured.out, captured.err
    return run


def last_json(stdout: str) -> dict[str, Any]:
    return json.loads(stdout.strip().splitlines()[-1])


@pytest.fixture(scope='module')
def drive(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    folder = tmp_path_factory.mktemp('drive')
    frames = list(SyntheticDrive(CONFIG))
    bags = {}
    rows: list = []
    for bag_format in ('mcap', 'sqlite3', 'ros1'):
        for compressed in (False, True):
            name = f'{bag_format}_{"jpeg" if compressed else "raw"}'
            path = folder / (f'{name}.bag' if bag_format == 'ros1' else name)
            rows = write_drive(frames, path, bag_format, compressed)
            bags[name] = path
    truth = folder / 'truth.csv'
    write_truth(truth, rows)
    return {'bags': bags, 'truth': truth, 'tracks': group_tracks(rows), 'folder': folder}


@pytest.fixture(scope='module')
def reference(drive: dict[str, Any], tmp_path_factory: pytest.TempPathFactory,
              bank_config: Path) -> dict[str, Any]:
    """The MCAP raw bag with truth, results bag with debug images, input images and
    Foxglove annotations: the reference run."""
    out = tmp_path_factory.mktemp('out') / 'result'
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        status = eval_tool.main(['bag', str(drive['bags']['mcap_raw']), '--truth',
                                 str(drive['truth']), '--out', str(out), '--debug-images',
                                 '--with-images', '--json', '--config', str(bank_config)])
    assert status == 0, stderr.getvalue()
    return {'status': status, 'out': out, 'summary': last_json(stdout.getvalue())}


def test_reference_drive_is_recognized(drive: dict[str, Any], reference: dict[str, Any]
                                       ) -> None:
    summary = reference['summary']
    limit_tracks = [track for track in drive['tracks'] if track.is_limit]
    assert summary['frames'] == CONFIG.frame_count
    assert summary['signs'] == len(limit_tracks) >= 1
    assert summary['recognized'] == summary['signs'] and summary['recall'] == 1.0
    assert summary['wrong_limits'] == 0 and summary['false_limits_per_hour'] == 0.0
    # The active limit at the end is the last recognition (0 after an end of limit).
    assert summary['final_limit_kmh'] == summary['limit_events'][-1]['limit_kmh']
    assert limit_tracks[-1].limit_kmh in [event['limit_kmh']
                                          for event in summary['limit_events']]
    assert [row['track_id'] for row in summary['per_sign']] == [
        track.track_id for track in drive['tracks']]
    assert summary['fps'] > 0 and summary['latency_ms_p95'] >= summary['latency_ms_p50'] > 0


@pytest.mark.parametrize('name', ['sqlite3_raw', 'ros1_raw', 'mcap_jpeg', 'sqlite3_jpeg',
                                  'ros1_jpeg'])
def test_every_format_and_encoding_gives_the_reference_metrics(
        drive: dict[str, Any], reference: dict[str, Any], name: str,
        evaluate: Evaluate) -> None:
    expected = reference['summary']
    status, stdout, stderr = evaluate(str(drive['bags'][name]), '--truth',
                                      str(drive['truth']), '--json')
    assert status == 0, stderr
    summary = last_json(stdout)
    assert summary['frames'] == expected['frames']
    assert summary['msgtype'].endswith('CompressedImage' if 'jpeg' in name else '/Image')
    for key in ('signs', 'recognized', 'recall', 'wrong_limits'):
        assert summary[key] == expected[key], key
    if 'raw' in name:   # the same pixels: the same recognitions at the same times
        assert summary['limit_events'] == expected['limit_events']
        assert summary['final_limit_kmh'] == expected['final_limit_kmh']


def test_several_classifier_workers_give_the_reference_metrics(
        drive: dict[str, Any], reference: dict[str, Any], bank_config: Path,
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A parameter file of a many-core host (two classifier worker processes): the frames
    are classified two at a time and still tracked in order, so the recognitions and
    their times are those of one classifier."""
    params = tmp_path / 'workers.yaml'
    params.write_text(bank_config.read_text()
                      + 'classifier_process: true\nclassifier_workers: 2\n')
    status = eval_tool.main(['bag', str(drive['bags']['mcap_raw']), '--truth',
                             str(drive['truth']), '--json', '--config', str(params)])
    captured = capsys.readouterr()
    assert status == 0, captured.err
    summary, expected = last_json(captured.out), reference['summary']
    for key in ('frames', 'signs', 'recognized', 'recall', 'wrong_limits', 'limit_events',
                'final_limit_kmh', 'per_sign'):
        assert summary[key] == expected[key], key


def test_results_bag_holds_outputs_at_input_stamps(drive: dict[str, Any],
                                                   reference: dict[str, Any]) -> None:
    """Topics, types and stamps of the --out bag, read back with rosbags."""
    assert reference['status'] == 0
    input_stamps = [CONFIG.stamp_ns(index) for index in range(CONFIG.frame_count)]
    with BagReader(reference['out']) as bag:
        assert bag.is_ros2
        topics = bag.topics()
        assert {name: topic.msgtype for name, topic in topics.items()} == {
            '/candidates': 'sensor_msgs/msg/PointCloud2',
            '/speed_limit': 'std_msgs/msg/UInt16',
            '/debug_image': 'sensor_msgs/msg/Image',
            '/image/compressed': 'sensor_msgs/msg/CompressedImage',
            '/image/annotations': 'foxglove_msgs/msg/ImageAnnotations'}
        clouds = list(bag.messages('/candidates'))
        limits = list(bag.messages('/speed_limit'))
        debug = list(bag.messages('/debug_image'))
    assert [item.log_time_ns for item in clouds] == input_stamps
    assert [header_stamp_ns(item.message, 0) for item in clouds] == input_stamps
    assert [item.log_time_ns for item in debug] == input_stamps
    assert all(item.message.encoding == 'bgr8' and item.message.width == 640 for item in debug)
    points = [pointcloud_to_array(item.message) for item in clouds]
    assert all(cloud.dtype.names == CANDIDATE_DTYPE.names for cloud in points)
    assert any(cloud.size > 0 for cloud in points)
    # speed_limit: 0 at the first frame, then one message per change of the active limit.
    assert limits[0].log_time_ns == input_stamps[0] and limits[0].message.data == 0
    values = [item.message.data for item in limits]
    assert all(a != b for a, b in zip(values, values[1:]))
    assert values[-1] == reference['summary']['final_limit_kmh']
    assert all(track.limit_kmh in values for track in drive['tracks'] if track.is_limit)
    # Each change is published at the stamp of the frame that recognized it.
    event_stamps_s = [event['stamp_s'] for event in reference['summary']['limit_events']]
    for item in limits[1:]:
        assert min(abs(item.log_time_ns * 1e-9 - stamp) for stamp in event_stamps_s) < 1e-6


def test_text_report_and_contact_sheet(drive: dict[str, Any], evaluate: Evaluate,
                                       tmp_path: Path) -> None:
    sheet_path = tmp_path / 'sheet.png'
    status, stdout, _ = evaluate(str(drive['bags']['ros1_jpeg']), '--truth',
                                 str(drive['truth']), '--contact-sheet', str(sheet_path))
    assert status == 0
    header, first_sign = stdout.splitlines()[:2]
    assert header.split()[:3] == ['sign', 'kind', 'limit']
    assert first_sign.split()[:3] == ['1', drive['tracks'][0].kind,
                                      str(drive['tracks'][0].limit_kmh)]
    assert 'recognized' in first_sign
    assert 'recall 1.000' in stdout
    assert 'frames of /camera/image_raw/compressed' in stdout
    assert f'contact sheet written to {sheet_path}' in stdout
    assert eval_bag.TABLE_LEGEND in stdout   # what 'max r', 'after s', 'r px' mean
    # times since the first frame, not epoch stamps
    limits_line = next(line for line in stdout.splitlines()
                       if line.startswith('limits recognized:'))
    assert limits_line.endswith('(s since the first frame)')
    times = [float(word) for word in limits_line.replace(',', ' ').split()
             if word.replace('.', '', 1).isdigit() and '.' in word]
    assert times and all(0.0 <= value <= CONFIG.duration_s for value in times)
    sheet = cv2.imread(str(sheet_path))
    assert sheet is not None and sheet.shape[1] == 1280 and sheet.shape[0] >= 400


def test_truncated_bag_reports_and_writes_the_frames_before_the_cut(
        drive: dict[str, Any], evaluate: Evaluate, tmp_path: Path) -> None:
    source = drive['bags']['mcap_raw']
    cut = tmp_path / 'cut'
    cut.mkdir()
    (cut / 'metadata.yaml').write_bytes((source / 'metadata.yaml').read_bytes())
    data = (source / 'mcap_raw.mcap').read_bytes()
    (cut / 'mcap_raw.mcap').write_bytes(data[:len(data) // 2])
    out = tmp_path / 'partial_result'
    status, stdout, stderr = evaluate(str(cut), '--truth', str(drive['truth']),
                                      '--out', str(out), '--json')
    assert status == 1
    assert 'truncated' in stderr and 'error' in stderr
    summary = last_json(stdout)
    assert 0 < summary['frames'] < CONFIG.frame_count
    assert summary['truncated'] is True and 'truncated' in summary['error']
    assert summary['signs'] >= 1
    with BagReader(out) as bag:
        clouds = list(bag.messages('/candidates'))
    assert len(clouds) == summary['frames']


def test_bag_without_image_topic_fails_with_its_topics(
        evaluate: Evaluate, tmp_path: Path) -> None:
    path = tmp_path / 'no_images'
    with BagWriter(path, 'mcap') as writer:
        writer.add_topic('/speed', 'std_msgs/msg/UInt16')
        writer.write('/speed', 1, writer.message_class('std_msgs/msg/UInt16')(data=3))
    status, stdout, stderr = evaluate(str(path), '--json')
    assert status == 1 and stdout == ''
    assert 'no sensor_msgs/Image or CompressedImage topic' in stderr and '/speed' in stderr


def test_unsupported_encoding_is_named(evaluate: Evaluate,
                                       tmp_path: Path) -> None:
    path = tmp_path / 'float_images'
    with BagWriter(path, 'sqlite3') as writer:
        writer.add_topic('/depth', 'sensor_msgs/msg/Image')
        for index in range(2):
            writer.write('/depth', index + 1, writer.message_class('sensor_msgs/msg/Image')(
                header=writer.header(index + 1), height=48, width=64, encoding='32FC1',
                is_bigendian=0, step=256, data=np.zeros(48 * 256, np.uint8)))
    status, stdout, stderr = evaluate(str(path), '--json')
    assert status == 1
    assert "unsupported image encoding '32FC1'" in stderr
    assert last_json(stdout)['frames'] == 0


def test_existing_output_is_refused_before_processing(
        drive: dict[str, Any], evaluate: Evaluate, tmp_path: Path) -> None:
    status, _, stderr = evaluate(str(drive['bags']['mcap_raw']), '--out',
                                 str(tmp_path))
    assert status == 1 and 'exists already' in stderr


def test_results_bag_with_images_opens_in_foxglove(drive: dict[str, Any],
                                                   reference: dict[str, Any]) -> None:
    """--with-images: the input frames as JPEG CompressedImages and, at the same stamps,
    foxglove_msgs/ImageAnnotations (read back with rosbags from the bag's own message
    definitions): a circle per candidate of /candidates, the value and PSR of each
    candidate read as a limit, the active limit as published on /speed_limit."""
    input_stamps = [CONFIG.stamp_ns(index) for index in range(CONFIG.frame_count)]
    frames = list(SyntheticDrive(CONFIG))
    with BagReader(reference['out']) as bag:
        images = list(bag.messages('/image/compressed'))
        annotations = list(bag.messages('/image/annotations'))
        clouds = list(bag.messages('/candidates'))
    assert [item.log_time_ns for item in images] == input_stamps
    assert [item.log_time_ns for item in annotations] == input_stamps
    for index in (0, len(images) - 1):   # colour JPEGs of the input frames
        image = images[index].message
        assert image.format == 'jpeg' and image.header.frame_id == 'camera'
        decoded = cv2.imdecode(np.asarray(image.data, np.uint8), cv2.IMREAD_COLOR)
        assert decoded.shape == frames[index].bgr.shape
        assert np.abs(decoded.astype(int) - frames[index].bgr.astype(int)).mean() < 4.0
    limit_texts = 0
    for item, cloud in zip(annotations, clouds):
        message, points = item.message, pointcloud_to_array(cloud.message)
        assert all(mark.timestamp.sec * 10**9 + mark.timestamp.nanosec == item.log_time_ns
                   for mark in [*message.circles, *message.labels])
        assert len(message.circles) == points.size
        for circle, point in zip(message.circles, points):
            assert (circle.position.x, circle.position.y) == pytest.approx(
                (point['u'], point['v']), abs=1e-3)
            assert circle.diameter == pytest.approx(2 * point['radius'], abs=1e-3)
        texts = [label.text for label in message.labels]
        expected = [f"{point['limit_kmh']} psr {point['psr']:.0f}" for point in points
                    if point['limit_kmh']]
        assert [text for text in texts if text.split()[0].isdigit()] == expected
        limit_texts += len(expected)
    assert limit_texts > 0
    last_banner = annotations[-1].message.labels[-1].text
    final = reference['summary']['final_limit_kmh']
    assert last_banner == (f'limit {final} km/h' if final else 'limit unknown')


def test_a_sign_cut_off_by_the_truncation_is_reported_as_cut(
        drive: dict[str, Any], reference: dict[str, Any], evaluate: Evaluate,
        tmp_path: Path) -> None:
    """A recording killed while a sign approaches (before the frame that recognized it in
    the complete drive): the sign is 'cut', not missed, and stays out of recall."""
    sign = next(track for track in drive['tracks'] if track.is_limit)
    recognized_s = min(event['stamp_s'] for event in reference['summary']['limit_events']
                       if event['limit_kmh'] == sign.limit_kmh)
    first_frame = round((sign.first_stamp_s - CONFIG.start_stamp_s) * CONFIG.fps)
    recognized_frame = round((recognized_s - CONFIG.start_stamp_s) * CONFIG.fps)
    assert recognized_frame - first_frame >= 4, 'no time between appearance and recognition'
    kept = (first_frame + recognized_frame) // 2
    killed = tmp_path / 'killed'
    write_drive(list(SyntheticDrive(CONFIG))[:kept], killed, 'mcap')
    storage = next(killed.glob('*.mcap'))
    storage.write_bytes(storage.read_bytes()[:-64])   # no footer: the recorder was killed
    status, stdout, _ = evaluate(str(killed), '--truth', str(drive['truth']), '--json')
    assert status == 1
    summary = last_json(stdout)
    assert summary['frames'] == kept and summary['truncated'] is True
    rows = {row['track_id']: row for row in summary['per_sign']}
    assert rows[sign.track_id]['cut'] is True and rows[sign.track_id]['recognized'] is False
    assert summary['cut_signs'] >= 1
    limit_rows = [row for row in rows.values() if row['limit_kmh'] > 0]
    assert summary['signs'] == sum(not row['cut'] for row in limit_rows)
    assert summary['cut_signs'] == sum(row['cut'] for row in limit_rows)
    if summary['signs'] == 0:
        assert summary['recall'] is None
    report = eval_bag.format_report(summary)
    sign_line = next(line for line in report.splitlines()
                     if line.split()[:2] == [str(sign.track_id), sign.kind])
    assert ' cut ' in sign_line and 'MISSED' not in sign_line
    assert f"{summary['cut_signs']} more cut off by the early stop: not counted" in report
