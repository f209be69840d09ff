"""A broken image among real crops: the installed tools name it in their own words, and
OpenCV's raw log lines (``[ WARN:0@0.079] global grfmt_png.cpp ...``) do not leak."""
from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

#: The GTSRB classes copied (30 and 50 km/h) and how many crops of each.
CLASS_FOLDERS = ('00001', '00002')
CROPS_PER_CLASS = 4
#: A file with the PNG signature and nothing valid after it: OpenCV's PNG decoder logs a
#: warning and an error for it (a file that is not a PNG at all it rejects silently).
BROKEN_PNG = b'\x89PNG\r\n\x1a\n broken'
BROKEN_NAME = '00002/99999_00000.png'
#: A raw OpenCV log line, as its logger writes it to stderr.
OPENCV_LOG_LINE = re.compile(r'^\[\s*(WARN|ERROR|INFO):\d+@[\d.]+\]', re.MULTILINE)


def _installed(name: str) -> str:
    script = Path(sys.executable).with_name(name)
    assert script.exists(), f'{name} is not installed next to {sys.executable}'
    return str(script)


@pytest.fixture(scope='module')
def crops_with_broken_png(shared_data_dir: Path, tmp_path_factory: pytest.TempPathFactory
                          ) -> Path:
    """A GTSRB-format folder: the first crops of two classes of gtsrb-dev, and one broken
    PNG listed in labels.csv like the others."""
    source = shared_data_dir / 'gtsrb-dev'
    folder = tmp_path_factory.mktemp('crops')
    header, *rows = (source / 'labels.csv').read_text().splitlines()
    kept = [header]
    for class_folder in CLASS_FOLDERS:
        for row in [row for row in rows if row.startswith(f'{class_folder}/')][
                :CROPS_PER_CLASS]:
            name = row.split(';')[0]
            (folder / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(source / name, folder / name)
            kept.append(row)
    (folder / BROKEN_NAME).write_bytes(BROKEN_PNG)
    kept.append(f'{BROKEN_NAME};30;30;5;5;25;25;2')
    (folder / 'labels.csv').write_text('\n'.join(kept) + '\n')
    return folder


@pytest.fixture(scope='module')
def small_params(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A node parameter file with small filter banks (quick to build)."""
    path = tmp_path_factory.mktemp('params') / 'params.yaml'
    path.write_text('speed_sign_detector:\n  ros__parameters:\n    classifier:\n'
                    '      max_radius_px: 24\n      cache_dir: ""\n')
    return path


def test_the_broken_png_makes_opencv_log(crops_with_broken_png: Path) -> None:
    """The control: decoded plainly, the file does make OpenCV write its log lines, so
    their absence below is the tools' doing."""
    probe = ('import sys, cv2, numpy as np\n'
             'data = open(sys.argv[1], "rb").read()\n'
             'assert cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE) is None\n')
    done = subprocess.run([sys.executable, '-c', probe, str(crops_with_broken_png / BROKEN_NAME)],
                          capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 0, done.stderr
    assert OPENCV_LOG_LINE.search(done.stderr), done.stderr


def test_train_build_names_the_unreadable_crop_without_opencv_lines(
        crops_with_broken_png: Path, small_params: Path, tmp_path: Path) -> None:
    out = tmp_path / 'bank.npz'
    done = subprocess.run(
        [_installed('speed_sign_train'), 'build', str(out), str(crops_with_broken_png),
         '--config', str(small_params), '--no-second-opinion', '--augmented-copies', '0',
         '--examples-per-class', '0', '--rendered-per-kind', '1', '--composites-per-value', '0',
         '--design-per-kind', '0',
         '-q'],
        capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 1, done.stderr  # finished, but skipped input
    assert out.is_file(), done.stderr  # the other crops still built the bank
    assert f'from {len(CLASS_FOLDERS) * CROPS_PER_CLASS} crops' in done.stdout
    skipped = [line for line in done.stdout.splitlines()
               if line.startswith('skipped unreadable crop:')]
    assert len(skipped) == 1 and BROKEN_NAME in skipped[0] and 'does not decode' in skipped[0]
    assert not OPENCV_LOG_LINE.search(done.stderr), done.stderr
    assert 'grfmt' not in done.stderr and 'Traceback' not in done.stderr


def test_eval_crops_names_the_unreadable_crop_without_opencv_lines(
        crops_with_broken_png: Path, small_params: Path) -> None:
    done = subprocess.run(
        [_installed('speed_sign_eval'), 'crops', str(crops_with_broken_png),
         '--config', str(small_params), '-q'],
        capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 1, done.stderr
    assert BROKEN_NAME in done.stdout and 'does not decode' in done.stdout
    assert 'could not be read and were skipped' in done.stderr
    assert not OPENCV_LOG_LINE.search(done.stderr), done.stderr
    assert 'grfmt' not in done.stderr and 'Traceback' not in done.stderr
