"""``speed_sign_eval scenes``: JSON contract, hit rule, table output, bad truth files."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from scene_helpers import paste, textured_background
from test_detection_synthetic import ring_frame

from speed_sign_detector.config import DetectorConfig
from speed_sign_detector.detection.candidates import Candidate
from speed_sign_detector.detection.detector import Detector
from speed_sign_detector.recognition.templates import render_sign
from speed_sign_detector.tools import eval as eval_tool
from speed_sign_detector.scene_truth import SceneSign, is_found, read_gtsdb_truth

KEYS = {'frames', 'signs', 'candidate_recall', 'ms_per_frame', 'detector_ms_per_frame',
        'backend'}


def run_json(argv: list[str], capsys: pytest.CaptureFixture[str]) -> dict:
    assert eval_tool.main(argv) == 0
    last_line = capsys.readouterr().out.strip().splitlines()[-1]
    return json.loads(last_line)


def test_hit_rule() -> None:
    sign = SceneSign('a.jpg', 100.0, 50.0, 140.0, 90.0, 1)  # centre (120, 70), r = 20
    assert sign.radius_px == 20.0 and sign.limit_kmh == 30
    assert is_found(sign, [Candidate(126.9, 70.0, 20.0, 1.0)])  # tolerance 0.35 r = 7
    assert not is_found(sign, [Candidate(127.1, 70.0, 20.0, 1.0)])
    small = SceneSign('a.jpg', 10.0, 10.0, 16.0, 16.0, 2)  # r = 3: tolerance 3 px
    assert is_found(small, [Candidate(15.9, 13.0, 3.0, 1.0)])
    assert SceneSign('a.jpg', 0, 0, 9, 9, 6).limit_kmh == 0  # end of 80 is not a limit


def test_synthetic_scenes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / 'images').mkdir()
    lines = []
    for index, (x, y, radius) in enumerate(((120.0, 90.0, 9.0), (300.0, 200.0, 18.0))):
        frame = ring_frame(400, 300, (x, y), radius)
        cv2.imwrite(str(tmp_path / 'images' / f'{index:05d}.png'), frame)
        lines.append(f'{index:05d}.png;{x - radius + 0.5};{y - radius + 0.5};'
                     f'{x + radius + 0.5};{y + radius + 0.5};2')
    lines.append('00001.png;10;10;30;30;12')  # not a speed limit: not counted
    (tmp_path / 'gt.txt').write_text('\n'.join(lines) + '\n')
    result = run_json(['scenes', str(tmp_path), '--json', '--backend', 'gl'], capsys)
    assert KEYS <= set(result)
    assert result['frames'] == 2 and result['signs'] == 2
    assert result['candidate_recall'] == 1.0 and result['backend'] == 'gl'
    assert result['ms_per_frame'] >= result['detector_ms_per_frame'] > 0.0
    # the white disc (0.8 r) votes; candidates report it / voting_edge_radius_ratio
    ratio = DetectorConfig().voting_edge_radius_ratio
    assert result['radius_ratio_median'] == pytest.approx(0.8 / ratio, rel=0.15)
    assert eval_tool.main(['scenes', str(tmp_path), '--backend', 'numpy']) == 0
    table = capsys.readouterr().out
    assert 'candidate recall' in table and 'numpy' in table


def test_bad_truth_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / 'images').mkdir()
    cv2.imwrite(str(tmp_path / 'images' / '00000.png'), np.zeros((100, 100), np.uint8))
    (tmp_path / 'gt.txt').write_text('00000.png;1;2;three;4;1\n')
    assert eval_tool.main(['scenes', str(tmp_path), '--json']) == 1
    assert 'gt.txt:1' in capsys.readouterr().err
    assert eval_tool.main(['scenes', str(tmp_path / 'missing'), '--json']) == 1


def test_real_scenes_subset(shared_data_dir: Path, tmp_path: Path,
                            capsys: pytest.CaptureFixture[str]) -> None:
    source = shared_data_dir / 'gtsdb-dev'
    truth = read_gtsdb_truth(source / 'gt.txt')
    names = sorted(name for name, signs in truth.items()
                   if any(sign.limit_kmh for sign in signs))[:12]
    (tmp_path / 'images').mkdir()
    lines = []
    for name in names:
        shutil.copy(source / 'images' / name, tmp_path / 'images' / name)
        lines += [f'{s.file};{s.x1_px};{s.y1_px};{s.x2_px};{s.y2_px};{s.class_id}'
                  for s in truth[name]]
    (tmp_path / 'gt.txt').write_text('\n'.join(lines) + '\n')
    result = run_json(['scenes', str(tmp_path), '--json'], capsys)
    expected_signs = sum(1 for name in names for s in truth[name] if s.limit_kmh)
    assert result['frames'] == len(names) and result['signs'] == expected_signs
    # the command's recall is the hit rule applied to the detector's own candidates
    found = 0
    with Detector(DetectorConfig(), backend=result['backend']) as detector:
        for name in names:
            gray = cv2.imread(str(source / 'images' / name), cv2.IMREAD_GRAYSCALE)
            candidates = detector.detect(gray)
            found += sum(is_found(s, candidates) for s in truth[name] if s.limit_kmh)
    assert result['found'] == found
    assert result['candidate_recall'] == pytest.approx(found / expected_signs)


def test_recognition_fields_on_rendered_signs(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    """A 50 sign labelled 50 is recognized; the same sign labelled 80 (class 5) is not,
    and its reading counts as a false limit, as does a 50 on an unlabelled frame."""
    (tmp_path / 'images').mkdir()
    bgr, alpha = render_sign('50', 48)
    for index in range(3):
        frame = textured_background(index, 400, 300)
        paste(frame, bgr, alpha, 176, 126)
        cv2.imwrite(str(tmp_path / 'images' / f'{index:05d}.png'), frame)
    box = '176;126;224;174'
    (tmp_path / 'gt.txt').write_text(f'00000.png;{box};2\n00001.png;{box};5\n'
                                     '00002.png;10;10;30;30;12\n')
    result = run_json(['scenes', str(tmp_path), '--json', '--backend', 'gl'], capsys)
    assert result['signs'] == 2 and result['found'] == 2
    assert result['recognized'] == 1
    assert result['recognition_recall'] == 0.5
    assert result['false_limits'] == 2
    assert result['false_limits_per_frame'] == pytest.approx(2 / 3)
    detection_only = run_json(['scenes', str(tmp_path), '--json', '--no-classify'], capsys)
    assert 'recognized' not in detection_only and detection_only['found'] == 2


def test_unreadable_images_are_skipped_and_listed(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """A corrupt, an empty and a too small image do not stop the run: the others are
    evaluated, each is listed with its reason, and the exit status is 1."""
    (tmp_path / 'images').mkdir()
    cv2.imwrite(str(tmp_path / 'images' / '00000.png'), ring_frame(400, 300, (120.0, 90.0), 14.0))
    (tmp_path / 'images' / '00001.png').write_bytes(b'\x89PNG\r\n\x1a\n' + bytes(100))
    (tmp_path / 'images' / '00002.jpg').write_bytes(b'')
    cv2.imwrite(str(tmp_path / 'images' / '00003.png'), np.zeros((20, 30), np.uint8))
    (tmp_path / 'gt.txt').write_text('00000.png;106.5;76.5;134.5;104.5;1\n'
                                     '00001.png;10;10;30;30;1\n')
    assert eval_tool.main(['scenes', str(tmp_path), '--json', '--no-classify']) == 1
    captured = capsys.readouterr()
    result = json.loads(captured.out.strip().splitlines()[-1])
    assert result['frames'] == 1 and result['frames_planned'] == 4
    assert result['signs'] == 1 and result['found'] == 1 and result['partial'] is False
    reasons = {item['file']: item['reason'] for item in result['unreadable']}
    assert set(reasons) == {'images/00001.png', 'images/00002.jpg', 'images/00003.png'}
    assert 'does not decode' in reasons['images/00001.png']
    assert reasons['images/00002.jpg'] == 'empty file (0 bytes)'
    assert 'smaller than the voting window' in reasons['images/00003.png']
    assert '3 image(s) could not be read or used' in captured.err
    assert eval_tool.main(['scenes', str(tmp_path), '--no-classify']) == 1
    table = capsys.readouterr().out
    assert 'UNREADABLE 3 images (skipped):' in table and 'images/00002.jpg: empty' in table
