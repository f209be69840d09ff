"""The installed command-line tools on real files, as a user runs them: bags of every
format ``speed_sign_synth`` writes read back, a crop folder with a corrupt PNG, Ctrl-C
in the middle of ``eval crops`` / ``scenes`` / ``bag``, output paths, ``--version``."""
from __future__ import annotations

import signal
import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest
from cli_helpers import DEADLINE_S, interrupt_at_fifo, last_json, run_tool, tool
from test_detection_synthetic import ring_frame
from test_recognition_eval_crops import CONFIG_YAML, LIMIT_CROPS, _write_crops

from speed_sign_detector import __version__
from speed_sign_detector.bag_io import BagReader, header_stamp_ns
from speed_sign_detector.image_conversion import message_to_gray
from speed_sign_detector.synthetic import DriveConfig, SyntheticDrive
from speed_sign_detector.tools.synth import write_drive
from speed_sign_detector.truth import read_truth

#: A tiny drive: 3 frames of 160x120.
DRIVE = DriveConfig(seed=4, duration_s=0.5, fps=6, width_px=160, height_px=120)
SYNTH_ARGS = ('--seed', '4', '--duration', '0.5', '--fps', '6', '--width', '160',
              '--height', '120', '-q')


@pytest.fixture(scope='module')
def crop_config(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A parameter file with small filter banks, cached for the module."""
    folder = tmp_path_factory.mktemp('crop_config')
    path = folder / 'params.yaml'
    path.write_text(CONFIG_YAML.format(cache=folder / 'cache'))
    return path


@pytest.mark.parametrize(('name', 'bag_format', 'compressed'), [
    ('drive_mcap', 'mcap', False), ('drive_sqlite3', 'sqlite3', True),
    ('drive_ros1.bag', 'ros1', True)])
def test_synth_bags_of_every_format_read_back(tmp_path: Path, name: str, bag_format: str,
                                              compressed: bool) -> None:
    """What speed_sign_synth writes, the project's readers read: the frames (pixels,
    stamps) and the truth file, which goes into a folder that did not exist."""
    truth = tmp_path / 'new_folder' / 'truth.csv'
    result = run_tool('speed_sign_synth', str(tmp_path / name), '--format', bag_format,
                      '--truth', str(truth), *SYNTH_ARGS,
                      *(['--compressed'] if compressed else []))
    assert result.returncode == 0, result.stderr
    # a ROS 1 bag gets the .bag its readers need; ROS 2 bags are folders
    bag = tmp_path / (name if bag_format != 'ros1' or name.endswith('.bag') else f'{name}.bag')
    assert bag.is_file() if bag_format == 'ros1' else bag.is_dir()
    assert f'to {bag}' in result.stderr
    drive = SyntheticDrive(DRIVE)
    with BagReader(bag) as reader:
        assert reader.is_ros2 == (bag_format != 'ros1')
        topic = reader.image_topic()
        items = list(reader.messages(topic.name))
    assert topic.msgtype.endswith('CompressedImage' if compressed else '/Image')
    assert [header_stamp_ns(item.message, 0) for item in items] == [
        DRIVE.stamp_ns(index) for index in range(DRIVE.frame_count)]
    for index, item in enumerate(items):
        expected = cv2.cvtColor(drive.frame(index).bgr, cv2.COLOR_BGR2GRAY).astype(int)
        difference = np.abs(message_to_gray(item.message).astype(int) - expected)
        assert difference.mean() < (3.0 if compressed else 0.51)   # JPEG q90 / rounding
    rows = read_truth(truth)
    assert len(rows) == sum(len(drive.frame(index).truth) for index in range(DRIVE.frame_count))


@pytest.mark.parametrize('name', ['drive', 'drive.bag'])
def test_ros1_synth_bag_goes_through_eval_bag(tmp_path: Path, name: str,
                                              bank_config: Path) -> None:
    """The round trip that failed: synth --format ros1, then eval bag on what it wrote
    (named without .bag, synth writes drive.bag and says so)."""
    synth = run_tool('speed_sign_synth', str(tmp_path / name), '--format', 'ros1',
                     *SYNTH_ARGS)
    assert synth.returncode == 0 and f'to {tmp_path / "drive.bag"}' in synth.stderr
    result = run_tool('speed_sign_eval', 'bag', str(tmp_path / 'drive.bag'), '--json',
                      '--backend', 'numpy', '--config', str(bank_config))
    assert result.returncode == 0, result.stderr
    summary = last_json(result.stdout)
    assert summary['frames'] == DRIVE.frame_count and summary['truncated'] is False


def test_crop_folder_with_a_corrupt_png(tmp_path: Path, crop_config: Path) -> None:
    """A corrupt crop is skipped and listed with its reason; the others are evaluated;
    the exit status says that something was skipped."""
    folder = tmp_path / 'crops'
    folder.mkdir()
    _write_crops(folder)
    corrupt = folder / '00005/00000_00000.png'
    corrupt.write_bytes(corrupt.read_bytes()[:60])   # a PNG cut after its header
    result = run_tool('speed_sign_eval', 'crops', str(folder), '--json', '--config',
                      str(crop_config))
    assert result.returncode == 1
    report = last_json(result.stdout)
    assert [item['file'] for item in report['unreadable']] == ['00005/00000_00000.png']
    assert 'does not decode' in report['unreadable'][0]['reason']
    assert report['crops'] == len(LIMIT_CROPS) - 1 == report['crops_done'] - 1
    assert '80' not in report['per_class'] and report['accuracy'] == pytest.approx(1.0)
    assert report['partial'] is False
    assert "could not be read and were skipped (listed under 'unreadable')" in result.stderr
    text = run_tool('speed_sign_eval', 'crops', str(folder), '--config', str(crop_config))
    assert text.returncode == 1
    assert 'UNREADABLE 1 files (skipped):' in text.stdout
    assert '00005/00000_00000.png: does not decode' in text.stdout


def test_ctrl_c_in_eval_crops_reports_the_crops_done(tmp_path: Path,
                                                     crop_config: Path) -> None:
    """SIGINT while the 4th of 8 crops is being read: 4 crops done, metrics printed,
    marked partial, exit status 130."""
    folder = tmp_path / 'crops'
    folder.mkdir()
    _write_crops(folder)
    lines = (folder / 'labels.csv').read_text().splitlines()
    lines.insert(4, 'pipe/00002.png;40;40;5;5;34;34;2')   # after 3 crops: a 50 sign
    (folder / 'labels.csv').write_text('\n'.join(lines) + '\n')
    (folder / 'pipe').mkdir()
    payload = (folder / '00002/00000_00000.png').read_bytes()
    status, stdout, stderr = interrupt_at_fifo(
        [*tool('speed_sign_eval'), 'crops', str(folder), '--json', '--config',
         str(crop_config)], folder / 'pipe/00002.png', payload)
    assert status == 130, stderr
    report = last_json(stdout)
    assert report['partial'] is True
    assert report['crops_done'] == report['crops'] == 4 and report['crops_planned'] == 8
    assert report['accuracy'] == pytest.approx(1.0)
    assert sum(report['per_class_count'].values()) == 4


def test_ctrl_c_in_eval_scenes_reports_the_frames_done(tmp_path: Path) -> None:
    """SIGINT while the 3rd of 4 scenes is being read: the table of 3 frames, partial."""
    images = tmp_path / 'images'
    images.mkdir()
    lines = []
    for index in range(4):
        x, y = 100.0 + 40 * index, 120.0
        if index != 2:
            cv2.imwrite(str(images / f'{index:05d}.png'), ring_frame(400, 300, (x, y), 14.0))
        lines.append(f'{index:05d}.png;{x - 13.5};{y - 13.5};{x + 14.5};{y + 14.5};1')
    (tmp_path / 'gt.txt').write_text('\n'.join(lines) + '\n')
    _, payload = cv2.imencode('.png', ring_frame(400, 300, (180.0, 120.0), 14.0))
    status, stdout, stderr = interrupt_at_fifo(
        [*tool('speed_sign_eval'), 'scenes', str(tmp_path), '--json', '--no-classify',
         '--backend', 'numpy'], images / '00002.png', payload.tobytes())
    assert status == 130, stderr
    result = last_json(stdout)
    assert result['partial'] is True
    assert result['frames'] == 3 and result['frames_planned'] == 4
    assert result['signs'] == 3 and result['found'] == 3


@pytest.mark.parametrize('name', ['speed_sign_eval', 'speed_sign_synth', 'speed_sign_replay',
                                  'speed_sign_monitor'])
def test_version(name: str) -> None:
    result = run_tool(name, '--version')
    assert result.returncode == 0 and result.stdout.strip() == f'{name} {__version__}'


def test_synth_errors_name_the_options(tmp_path: Path) -> None:
    result = run_tool('speed_sign_synth', str(tmp_path / 'drive'), '--duration', '0')
    assert result.returncode == 2
    assert '--duration must be in (0, 3600] seconds' in result.stderr
    assert 'duration_s' not in result.stderr
    assert not (tmp_path / 'drive').exists()


@pytest.fixture(scope='module')
def long_drive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """15 s at 10 fps, 320x240: long enough that Ctrl-C lands in the middle."""
    path = tmp_path_factory.mktemp('long_drive') / 'drive'
    write_drive(SyntheticDrive(DriveConfig(seed=3, duration_s=15.0, fps=10, width_px=320,
                                           height_px=240, focal_px=380.0)), path, 'mcap')
    return path


def test_ctrl_c_in_eval_bag_reports_and_keeps_the_frames_done(
        long_drive: Path, bank_config: Path, tmp_path: Path) -> None:
    """SIGINT once the first tenth of the frames is done (the progress log says so; the
    other nine tenths take far longer than a signal): the metrics of the frames done,
    marked partial, exit status 130; the results bag and the contact sheet (into a
    folder that did not exist) hold exactly those frames."""
    out = tmp_path / 'results'
    sheet = tmp_path / 'new' / 'folder' / 'sheet.png'
    process = subprocess.Popen(
        [*tool('speed_sign_eval'), 'bag', str(long_drive), '--json', '--out', str(out),
         '--contact-sheet', str(sheet), '--config', str(bank_config)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert process.stderr is not None
        seen = []
        for line in process.stderr:
            seen.append(line)
            if line.rstrip().endswith('/150 frames'):
                process.send_signal(signal.SIGINT)
                break
        stdout, rest = process.communicate(timeout=DEADLINE_S)
    finally:
        if process.poll() is None:
            process.kill()
    stderr = ''.join(seen) + rest
    assert process.returncode == 130, stderr
    summary = last_json(stdout)
    assert summary['partial'] is True and summary['frames_planned'] == 150
    assert 15 <= summary['frames'] < 150
    assert 'interrupted' in stderr
    with BagReader(out) as bag:
        assert len(list(bag.messages('/candidates'))) == summary['frames']
    assert cv2.imread(str(sheet)) is not None


def test_eval_bag_checks_its_output_paths_before_the_first_frame(
        long_drive: Path, tmp_path: Path) -> None:
    """Outputs that cannot be written are refused at once, naming the option; nothing is
    processed (no JSON), nothing is left behind."""
    blocker = tmp_path / 'a_file'
    blocker.write_text('not a folder')
    cases = [(['--contact-sheet', str(blocker / 'sheet.png')], '--contact-sheet'),
             (['--contact-sheet', str(tmp_path / 'sheet.gif')], 'must end in .png'),
             (['--out', str(blocker / 'results')], '--out'),
             (['--out', str(blocker)], 'exists already')]
    for arguments, message in cases:
        result = run_tool('speed_sign_eval', 'bag', str(long_drive), '--json', *arguments)
        assert result.returncode == 1, arguments
        assert message in result.stderr and result.stdout == ''
        assert 'speed_sign_eval bag: error:' in result.stderr


@pytest.mark.parametrize(('command', 'expected'), [
    (('speed_sign_eval', 'scenes', '--help'), ['found when one of the frame', '--backend']),
    (('speed_sign_eval', 'crops', '--help'),
     ['Classify every crop listed', 'read as a speed limit']),
    (('speed_sign_eval', 'bag', '--help'), ['--with-images', 'Foxglove']),
    (('speed_sign_synth', '--help'), ['image width, px (default 640)', '(default 480)']),
    (('speed_sign_replay', '--help'), ['queue depth (default 5)'])])
def test_help_texts_are_plain_and_complete(command: tuple[str, ...], expected: list[str]) -> None:
    """No reStructuredText markup; the description and the option help users asked for."""
    result = run_tool(*command)
    assert result.returncode == 0
    text = ' '.join(result.stdout.split())   # argparse wraps lines
    assert '``' not in text and ':mod:' not in text
    for words in expected:
        assert words in text, words
