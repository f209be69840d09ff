"""``speed_sign_eval crops``: JSON contract on a synthetic GTSRB-format folder, errors,
and a short run on the real GTSRB crops."""
from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from speed_sign_detector.recognition.templates import render_sign
from speed_sign_detector.tools.eval import main as eval_main
from speed_sign_detector.tools.eval_crops import read_labels, size_bin

CONFIG_YAML = """speed_sign_detector:
  ros__parameters:
    classifier:
      max_radius_px: 24.0
      cache_dir: "{cache}"
"""


def _write_crops(folder: Path) -> list[int]:
    """GTSRB-like crops of rendered signs (5 px margin); returns the class ids."""
    classes = [(0, '20'), (1, '30'), (2, '50'), (5, '80'), (6, 'end_of_limit_80'),
               (7, '100'), (8, '120')]
    lines = ['Filename;Width;Height;Roi.X1;Roi.Y1;Roi.X2;Roi.Y2;ClassId']
    rng = np.random.default_rng(3)
    for class_id, kind in classes:
        bgr, alpha = render_sign(kind, 30)
        background = rng.uniform(60, 180)
        sign = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(np.float32)
        crop = np.full((40, 40), background, np.float32)
        crop[5:35, 5:35] = sign + (1.0 - alpha) * background
        crop = cv2.GaussianBlur(crop, (0, 0), 0.6)
        name = f'{class_id:05d}/00000_00000.png'
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(folder / name), np.clip(crop, 0, 255).astype(np.uint8))
        lines.append(f'{name};40;40;5;5;34;34;{class_id}')
    lines.append('00042/00000_00000.png;40;40;5;5;34;34;42')  # other class: skipped
    (folder / 'labels.csv').write_text('\n'.join(lines) + '\n')
    return [c for c, _ in classes]


def test_json_report_on_synthetic_crops(tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    data = tmp_path / 'crops'
    data.mkdir()
    classes = _write_crops(data)
    config = tmp_path / 'params.yaml'
    config.write_text(CONFIG_YAML.format(cache=tmp_path / 'cache'))
    status = eval_main(['crops', str(data), '--json', '--config', str(config)])
    assert status == 0
    report = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert report['crops'] == len(classes) and report['skipped'] == 1
    assert set(report['per_class']) == {'20', '30', '50', '80', 'end_of_limit', '100', '120'}
    assert report['accuracy'] == pytest.approx(1.0)
    assert report['wrong_limit_rate'] == 0.0
    assert sum(sum(row.values()) for row in report['confusion'].values()) == len(classes)
    assert report['accuracy_by_size_px'] == {'30-40': 1.0}  # ROI 30 px wide
    assert report['ms_per_crop'] > 0 and report['bank_mb'] > 0


def test_missing_or_malformed_labels_fail_cleanly(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    assert eval_main(['crops', str(tmp_path / 'absent'), '--json']) == 1
    (tmp_path / 'labels.csv').write_text('Filename;Width\nx.png;3\n')
    assert eval_main(['crops', str(tmp_path), '--json']) == 1
    err = capsys.readouterr().err
    assert 'malformed row' in err


def test_size_bins() -> None:
    assert size_bin(19) == '0-20'
    assert size_bin(29) == '25-30'
    assert size_bin(250) == '70+'


def test_short_run_on_real_crops(shared_data_dir: Path, tmp_path: Path,
                                 capsys: pytest.CaptureFixture[str]) -> None:
    folder = shared_data_dir / 'gtsrb-dev'
    labels, _ = read_labels(folder)
    assert len(labels) > 1000
    config = tmp_path / 'params.yaml'
    config.write_text(CONFIG_YAML.format(cache=tmp_path / 'cache').replace(
        'max_radius_px: 24.0', 'max_radius_px: 48.0'))
    status = eval_main(['crops', str(folder), '--json', '--every', '55', '--config',
                        str(config)])
    assert status == 0
    report = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert report['crops'] == len(labels[::55])
    # a real but small sample: far above the naive 0.33 and few wrong limits
    assert report['accuracy'] > 0.7
    assert report['wrong_limit_rate'] < 0.1
