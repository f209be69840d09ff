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
    """The MCAP raw bag with truth, results bag and debug images: the reference run."""
    out = tmp_path_factory.mktemp('out') / 'result'
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        status = eval_tool.main(['bag', str(drive['bags']['mcap_raw']), '--truth',
                                 str(drive['truth']), '--out', str(out), '--debug-images',
                                 '--json', '--config', str(bank_config)])
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
            '/debug_image': 'sensor_msgs/msg/Image'}
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
    sheet = cv2.imread(str(sheet_path))
    assert sheet is not None and sheet.shape[1] == 4 * 320 and sheet.shape[0] >= 240


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
