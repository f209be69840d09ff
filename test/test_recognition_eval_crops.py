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
from speed_sign_detector.tools.eval_crops import GTSRB_LOOKALIKE_NAMES, read_labels, size_bin

CONFIG_YAML = """speed_sign_detector:
  ros__parameters:
    classifier:
      max_radius_px: 24.0
      cache_dir: "{cache}"
"""


#: (GTSRB class id, what is drawn in its crop): the limit classes and end of 80 as
#: themselves; look-alike classes as themselves, and class 16 as a 50 sign in disguise,
#: which the classifier must read as a limit (a look-alike "read as a limit").
LIMIT_CROPS = [(0, '20'), (1, '30'), (2, '50'), (5, '80'), (6, 'end_of_limit_80'),
               (7, '100'), (8, '120')]
LOOKALIKE_CROPS = [(9, 'no_overtaking'), (17, 'no_entry'), (32, 'end_of_restrictions'),
                   (16, '50')]


def _write_crops(folder: Path, lookalikes: bool = False, sign_px: int = 30,
                 margin_px: int = 5) -> list[int]:
    """GTSRB-like crops of rendered signs (a 30 px sign, 5 px margin by default); returns
    the class ids."""
    classes = LIMIT_CROPS + (LOOKALIKE_CROPS if lookalikes else [])
    lines = ['Filename;Width;Height;Roi.X1;Roi.Y1;Roi.X2;Roi.Y2;ClassId']
    rng = np.random.default_rng(3)
    side = sign_px + 2 * margin_px
    box = f'{side};{side};{margin_px};{margin_px};{margin_px + sign_px - 1};' \
        f'{margin_px + sign_px - 1}'
    for class_id, kind in classes:
        bgr, alpha = render_sign(kind, sign_px)
        background = rng.uniform(60, 180)
        sign = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(np.float32)
        crop = np.full((side, side), background, np.float32)
        crop[margin_px:margin_px + sign_px, margin_px:margin_px + sign_px] = \
            sign + (1.0 - alpha) * background
        crop = cv2.GaussianBlur(crop, (0, 0), 0.6)
        name = f'{class_id:05d}/00000_00000.png'
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(folder / name), np.clip(crop, 0, 255).astype(np.uint8))
        lines.append(f'{name};{box};{class_id}')
    lines.append(f'00012/00000_00000.png;{box};12')  # other class: skipped
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
    assert report['crops_done'] == report['crops_planned'] == len(classes)
    assert report['partial'] is False and report['unreadable'] == []
    assert set(report['per_class']) == {'20', '30', '50', '80', 'end_of_limit', '100', '120'}
    assert report['accuracy'] == pytest.approx(1.0)
    assert report['wrong_limit_rate'] == 0.0
    assert sum(sum(row.values()) for row in report['confusion'].values()) == len(classes)
    assert report['accuracy_by_size_px'] == {'30-40': 1.0}  # ROI 30 px wide
    assert report['ms_per_crop'] > 0 and report['bank_mb'] > 0
    assert report['lookalike_crops'] == 0 and report['read_as_limit_rate'] is None
    assert report['framing'] == 'auto'


def test_framing_option_overrides_the_config(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    # 13 px signs with 2 px around them (17 px crops, padded in proportion): read as
    # GTSRB-framed ('margin', 5 px margins) they would have a 3.5 px radius, too small to
    # read; 'padded' and 'auto' read them
    data = tmp_path / 'crops'
    data.mkdir()
    _write_crops(data, sign_px=13, margin_px=2)
    config = tmp_path / 'params.yaml'
    config.write_text(CONFIG_YAML.format(cache=tmp_path / 'cache'))
    reports = {}
    for framing in ('margin', 'padded', None):
        assert eval_main(['crops', str(data), '--json', '--config', str(config), '-q']
                         + (['--framing', framing] if framing else [])) == 0
        reports[framing] = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
        assert reports[framing]['framing'] == (framing or 'auto')
    # only the end of 80, right with any answer that is not a limit
    assert reports['margin']['accuracy'] == pytest.approx(1 / len(LIMIT_CROPS))
    assert reports['padded']['accuracy'] >= 5 / len(LIMIT_CROPS)
    assert reports[None]['accuracy'] == reports['padded']['accuracy']
    assert reports['padded']['wrong_limit_rate'] == 0.0
    with pytest.raises(SystemExit):
        eval_main(['crops', str(data), '--framing', 'loose'])
    assert 'invalid choice' in capsys.readouterr().err


def test_lookalikes_are_counted_as_signs_that_set_no_limit(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Look-alike classes are evaluated, not skipped: per class and overall, the share
    read as a limit; the limit classes keep their accuracy and wrong-limit rates."""
    data = tmp_path / 'crops'
    data.mkdir()
    _write_crops(data, lookalikes=True)
    config = tmp_path / 'params.yaml'
    config.write_text(CONFIG_YAML.format(cache=tmp_path / 'cache'))
    assert eval_main(['crops', str(data), '--json', '--config', str(config)]) == 0
    report = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert report['crops'] == len(LIMIT_CROPS) and report['skipped'] == 1
    assert report['lookalike_crops'] == len(LOOKALIKE_CROPS)
    assert report['crops_done'] == len(LIMIT_CROPS) + len(LOOKALIKE_CROPS)
    assert report['per_lookalike_count'] == {'no_passing': 1, 'no_vehicles_over_3.5t': 1,
                                             'no_entry': 1, 'end_of_all_limits': 1}
    # the 50 drawn in the class-16 crop is read as 50: that look-alike class is read as
    # a limit every time; the real look-alike drawings are not.
    assert report['lookalike_confusion']['no_vehicles_over_3.5t'] == {'50': 1}
    assert report['per_lookalike_read_as_limit'] == {
        'no_passing': 0.0, 'no_vehicles_over_3.5t': 1.0, 'no_entry': 0.0,
        'end_of_all_limits': 0.0}
    assert report['read_as_limit_rate'] == pytest.approx(1 / len(LOOKALIKE_CROPS))
    # the limit classes are unchanged by the look-alikes beside them
    assert report['accuracy'] == pytest.approx(1.0) and report['wrong_limit_rate'] == 0.0
    assert report['per_class_wrong_limit'] == {name: 0.0 for name in report['per_class']}
    # the human-readable summary goes to stdout and names the look-alike rates
    assert eval_main(['crops', str(data), '--config', str(config)]) == 0
    captured = capsys.readouterr()
    assert 'look-alike crops 4  read as a limit 0.250' in captured.out
    assert 'no_vehicles_over_3.5t: 1.000 read as a limit' in captured.out
    assert 'accuracy 1.000' in captured.out and 'accuracy' not in captured.err


def test_missing_empty_or_malformed_labels_fail_cleanly(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert eval_main(['crops', str(tmp_path / 'absent'), '--json']) == 1
    assert 'is not a folder' in capsys.readouterr().err
    labels = tmp_path / 'labels.csv'
    labels.write_text('')
    assert eval_main(['crops', str(tmp_path), '--json']) == 1
    captured = capsys.readouterr()
    assert f'{labels} is empty' in captured.err and captured.out == ''
    labels.write_text('Filename;Width;Height;Roi.X1;Roi.Y1;Roi.X2;Roi.Y2;ClassId\n')
    assert eval_main(['crops', str(tmp_path), '--json']) == 1
    assert 'has a header but no rows' in capsys.readouterr().err
    labels.write_text('Filename;Width\nx.png;3\n')
    assert eval_main(['crops', str(tmp_path), '--json']) == 1
    assert 'malformed row' in capsys.readouterr().err
    labels.write_text('Filename;Width;Height;Roi.X1;Roi.Y1;Roi.X2;Roi.Y2;ClassId\n'
                      'x.png;40;40;5;5;34;34;12\n')
    assert eval_main(['crops', str(tmp_path), '--json']) == 1
    assert 'lists no crop of the classes 0-8 or a look-alike class' in capsys.readouterr().err


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
    # the real look-alikes (no class 0-8 at all): evaluated, mostly not read as limits
    lookalikes = shared_data_dir / 'gtsrb-lookalikes-dev'
    status = eval_main(['crops', str(lookalikes), '--json', '--every', '100', '--config',
                        str(config)])
    assert status == 0
    report = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    listed, skipped = read_labels(lookalikes, include_lookalikes=True)
    assert skipped == 0 and report['lookalike_crops'] == len(listed[::100])
    assert report['crops'] == 0 and report['accuracy'] is None
    assert set(report['per_lookalike_count']) <= set(GTSRB_LOOKALIKE_NAMES.values())
    assert report['read_as_limit_rate'] < 0.2


def test_tight_real_crops_read_as_well_as_margin_ones(shared_data_dir: Path, tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]
                                                      ) -> None:
    # the same real GTSRB signs, cut to their ROI boxes (as most labelling tools cut
    # crops), read with the default framing (auto) as well as with GTSRB's margin
    folder = shared_data_dir / 'gtsrb-dev'
    labels, _ = read_labels(folder)
    tight = tmp_path / 'tight'
    lines = ['Filename;Width;Height;Roi.X1;Roi.Y1;Roi.X2;Roi.Y2;ClassId']
    for label in labels[::55]:
        image = cv2.imread(str(label.path))
        box = image[label.roi_y1:label.roi_y2 + 1, label.roi_x1:label.roi_x2 + 1]
        name = label.path.relative_to(folder).as_posix()
        (tight / name).parent.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(tight / name), box)
        height, width = box.shape[:2]
        lines.append(f'{name};{width};{height};0;0;{width - 1};{height - 1};{label.class_id}')
    (tight / 'labels.csv').write_text('\n'.join(lines) + '\n')
    config = tmp_path / 'params.yaml'
    config.write_text(CONFIG_YAML.format(cache=tmp_path / 'cache').replace(
        'max_radius_px: 24.0', 'max_radius_px: 48.0'))
    reports = {}
    for name, data in (('margin', folder), ('tight', tight)):
        status = eval_main(['crops', str(data), '--json', '--config', str(config)]
                           + (['--every', '55'] if name == 'margin' else []))
        assert status == 0
        reports[name] = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert reports['tight']['crops'] == reports['margin']['crops'] == len(labels[::55])
    assert reports['tight']['accuracy'] > 0.7
    assert reports['tight']['accuracy'] >= reports['margin']['accuracy'] - 0.05
    assert reports['tight']['wrong_limit_rate'] < 0.1
