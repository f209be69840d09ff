"""Approach sequences with real pixels: annotated road scenes turned into a drive-like stream.

A GTSDB-format scene folder (``images/`` and ``gt.txt``, see
:func:`speed_sign_detector.scene_truth.read_gtsdb_truth`) holds single frames. For
the development loop of temporal integration this module turns each speed-limit sign
of at least ``min_sign_px`` (mean of box width and height) into a short **approach
sequence**: ``frames_per_sequence`` frames (12 by default, 10 Hz) in which the view
closes in on the sign, as a car driving towards it sees it, followed by a sign-free
**gap**. Every frame is resampled (``cv2.warpAffine``, bilinear) from the real scene's
pixels to the output size (640x480); nothing is drawn or pasted.

Path of one sequence (all sizes in pixels)
    The output is a window of the scene, magnified by a zoom ``z``: scene point ``q``
    lands at ``(q - window origin) * z``. The first frame uses the smallest zoom at which
    an output-sized window fits in the scene (1.0 for an 816x480 scene and 640x480
    output): the sign at its real size. The last frame uses ``z1 = growth * z0`` with
    ``growth`` drawn per sign in ``[growth_min, growth_max]`` (2-3x by default). As for a
    camera approaching at constant speed, ``1 / z`` falls linearly over the frames (the
    sign grows faster near the end), and the sign's offset from the output centre grows
    in proportion to ``z`` along the direction from the scene's centre to the sign
    (outward: up and right for a sign above the road on the right), ending at 80 % of
    the way to the edge where the magnified sign would touch it. Windows are clamped to
    the scene (no border is ever invented), so near the scene's edges the path bends.
    The truth boxes are the scene boxes mapped through each frame's window, exact.

Truth
    Every annotated sign of the scene that is in view (radius >= 5 px and 3/4 of its box
    inside the output, as in :mod:`speed_sign_detector.synthetic`) gets a truth row; other
    signs, look-alikes included, stay in the pixels as the real distractors they are.
    Each sign of each sequence is its own truth track (a scene with two limit signs
    shows the second one in the first one's sequence too, and reading it there is right).
    Kinds are the limit (``'50'``), ``end_of_limit_80`` for GTSDB class 6 and a name for
    the other classes (:data:`GTSDB_CLASS_KINDS`).

Sign-free gaps
    After each sequence, ``gap_frames`` frames (15 = 1.5 s by default) of the same scene
    without any sign: the lowest window (the road ahead, nearest the centre) at zoom
    ``2 * z0`` (or 3, 4x) whose box, enlarged by :data:`GAP_SIGN_MARGIN_PX`, meets no
    annotated sign, slowly magnified further (x1.15) as if driving on. When no such
    window exists the scene is shown blurred beyond recognition (Gaussian, sigma
    :data:`GAP_BLUR_SIGMA_PX`). Unannotated round things (wheels, lamps) may remain in a
    gap: real distractors. The gap is "the drive after passing the sign": the limit
    in force (:mod:`speed_sign_detector.limit_in_force`) becomes the sign's value at the
    sequence's last frame and holds through the gap and the next sequence until the next
    sign is passed, so each sequence is judged as one sign of one continuous drive.
    The gap is also longer than the tracker's window, so no track carries over from one
    sequence to the next.

The same scenes and configuration give the same frames, byte for byte.
"""
from __future__ import annotations

import logging
import zlib
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from speed_sign_detector.errors import SpeedSignError
from speed_sign_detector.synthetic import (
    MIN_TRUTH_RADIUS_PX,
    MIN_TRUTH_VISIBLE_FRACTION,
    SyntheticFrame,
)
from speed_sign_detector.scene_truth import (
    SPEED_LIMIT_CLASSES,
    SceneSign,
    read_gtsdb_truth,
)
from speed_sign_detector.truth import TruthRow

LOGGER = logging.getLogger(__name__)

#: GTSDB class id -> truth kind (limits are their value; see :data:`SPEED_LIMIT_CLASSES`).
GTSDB_CLASS_KINDS: dict[int, str] = {
    **{class_id: str(limit) for class_id, limit in SPEED_LIMIT_CLASSES.items()},
    6: 'end_of_limit_80', 9: 'no_overtaking', 10: 'no_overtaking_trucks',
    11: 'priority_at_next_intersection', 12: 'priority_road', 13: 'give_way', 14: 'stop',
    15: 'no_vehicles', 16: 'no_trucks', 17: 'no_entry', 18: 'danger', 19: 'bend_left',
    20: 'bend_right', 21: 'double_bend', 22: 'uneven_road', 23: 'slippery_road',
    24: 'road_narrows_right', 25: 'road_works', 26: 'traffic_signals', 27: 'pedestrians',
    28: 'children', 29: 'cyclists', 30: 'ice_or_snow', 31: 'wild_animals',
    32: 'end_of_restrictions', 33: 'turn_right_ahead', 34: 'turn_left_ahead',
    35: 'ahead_only', 36: 'ahead_or_right', 37: 'ahead_or_left', 38: 'keep_right',
    39: 'keep_left', 40: 'roundabout', 41: 'end_of_no_overtaking',
    42: 'end_of_no_overtaking_trucks'}
#: A gap window keeps this far from every annotated sign box, scene pixels.
GAP_SIGN_MARGIN_PX = 8.0
#: Zooms (relative to the first frame's) tried for the sign-free gap window.
GAP_ZOOMS = (2.0, 3.0, 4.0)
#: Extra magnification over a gap (driving on).
GAP_ZOOM_GAIN = 1.15
#: Blur of a gap frame when no sign-free window exists, pixels (output).
GAP_BLUR_SIGMA_PX = 12.0
#: The sign ends this far (share) of the way from the output centre to where it would
#: touch the edge.
END_OFFSET_SHARE = 0.8
#: Pixels kept between the magnified sign and the output edge on the last frame.
EDGE_MARGIN_PX = 4.0


class ApproachSceneError(SpeedSignError):
    """A scene folder cannot be turned into approach sequences (missing, empty, unreadable)."""


@dataclass(frozen=True)
class ApproachConfig:
    """Settings of the approach sequences (sizes in pixels, times in seconds).

    Attributes:
        frames_per_sequence: frames of one approach.
        gap_frames: sign-free frames after each approach.
        fps: frame rate, frames per second.
        width_px, height_px: output image size.
        min_sign_px: smallest sign that gets a sequence, mean of box width and height.
        growth_min, growth_max: range of the sign's growth over a sequence (last zoom /
            first zoom), drawn per sign.
        seed: seed of the per-sign draws; the frames are a function of the scenes and
            this config.
        start_stamp_s: stamp of the first frame, seconds since the epoch.
        scenes: only these image files (names as in ``gt.txt``); empty = all.
        max_sequences: stop after this many sequences (0 = no limit).
    """

    frames_per_sequence: int = 12
    gap_frames: int = 15
    fps: float = 10.0
    width_px: int = 640
    height_px: int = 480
    min_sign_px: float = 14.0
    growth_min: float = 2.0
    growth_max: float = 3.0
    seed: int = 0
    start_stamp_s: float = 1_700_000_000.0
    scenes: tuple[str, ...] = field(default_factory=tuple)
    max_sequences: int = 0

    def __post_init__(self) -> None:
        if not 2 <= self.frames_per_sequence <= 1000:
            raise ApproachSceneError(f'frames_per_sequence must be in [2, 1000], got '
                                     f'{self.frames_per_sequence}')
        if not 0 <= self.gap_frames <= 1000:
            raise ApproachSceneError(f'gap_frames must be in [0, 1000], got {self.gap_frames}')
        if not 1.0 <= self.fps <= 240.0:
            raise ApproachSceneError(f'fps must be in [1, 240], got {self.fps}')
        if not (64 <= self.width_px <= 4096 and 48 <= self.height_px <= 4096):
            raise ApproachSceneError(f'output size {self.width_px}x{self.height_px} out of '
                                     f'range (64..4096 x 48..4096)')
        if not 1.0 <= self.growth_min <= self.growth_max <= 10.0:
            raise ApproachSceneError(f'need 1 <= growth_min <= growth_max <= 10, got '
                                     f'{self.growth_min}, {self.growth_max}')
        if self.min_sign_px < 0 or self.max_sequences < 0:
            raise ApproachSceneError('min_sign_px and max_sequences must be >= 0')

    def stamp_ns(self, frame: int) -> int:
        """Message time of a frame, integer nanoseconds since the epoch."""
        return int(round(self.start_stamp_s * 1e9)) + int(round(frame * 1e9 / self.fps))


@dataclass(frozen=True)
class CropWindow:
    """The part of the scene one output frame shows.

    Attributes:
        left_px, top_px: the window's top-left corner in the scene, pixels.
        zoom: output pixels per scene pixel (the window is output size / zoom).
    """

    left_px: float
    top_px: float
    zoom: float

    def to_output(self, x_px: float, y_px: float) -> tuple[float, float]:
        """A scene point in output pixels."""
        return (x_px - self.left_px) * self.zoom, (y_px - self.top_px) * self.zoom

    def affine(self) -> np.ndarray:
        """The (2, 3) float64 scene-to-output matrix for ``cv2.warpAffine``.

        Boxes use edge coordinates (pixel ``i`` spans ``[i, i + 1)``), OpenCV pixel
        centres (pixel ``i`` is at ``i``): the half-pixel shifts make the mapped truth
        boxes land exactly on the resampled pixels.
        """
        return np.array([[self.zoom, 0.0, self.zoom * (0.5 - self.left_px) - 0.5],
                         [0.0, self.zoom, self.zoom * (0.5 - self.top_px) - 0.5]])


@dataclass(frozen=True)
class ApproachSequence:
    """One planned sequence: a sign of a scene, its approach path and its gap.

    Attributes:
        index: 0-based sequence number.
        scene_file: image file name (relative to ``images/``).
        sign: the speed-limit sign approached.
        scene_signs: every annotated sign of the scene.
        growth: last zoom / first zoom.
        windows: one window per approach frame.
        gap_windows: one window per gap frame.
        gap_blurred: True when the gap frames are blurred (no sign-free window found).
        first_frame: index of the sequence's first frame in the stream.
    """

    index: int
    scene_file: str
    sign: SceneSign
    scene_signs: tuple[SceneSign, ...]
    growth: float
    windows: tuple[CropWindow, ...]
    gap_windows: tuple[CropWindow, ...]
    gap_blurred: bool
    first_frame: int

    @property
    def frame_count(self) -> int:
        """Approach and gap frames."""
        return len(self.windows) + len(self.gap_windows)


def approach_windows(sign: SceneSign, scene_size: tuple[int, int], output_size: tuple[int, int],
                     frames: int, growth: float) -> tuple[CropWindow, ...]:
    """The windows of an approach on ``sign`` (see the module docstring).

    Args:
        sign: the sign approached.
        scene_size: (width, height) of the scene, pixels.
        output_size: (width, height) of the output, pixels.
        frames: number of frames (>= 2).
        growth: zoom of the last frame / zoom of the first.

    Returns:
        ``frames`` windows, each inside the scene.
    """
    scene_width, scene_height = scene_size
    out_width, out_height = output_size
    first_zoom = max(out_width / scene_width, out_height / scene_height)
    last_zoom = first_zoom * growth
    sign_x, sign_y = sign.centre_px
    radius_px = 0.5 * max(sign.x2_px - sign.x1_px, sign.y2_px - sign.y1_px)
    direction = np.array([sign_x - 0.5 * scene_width, sign_y - 0.5 * scene_height])
    norm = float(np.hypot(*direction))
    direction = direction / norm if norm >= 1.0 else np.array([1.0, 0.0])
    centre = np.array([0.5 * out_width, 0.5 * out_height])
    size = np.array([out_width, out_height], dtype=np.float64)
    # how far along `direction` the magnified sign can go before touching an edge
    room = radius_px * last_zoom + EDGE_MARGIN_PX
    limits = [(half - room) / abs(component)
              for half, component in zip(centre, direction) if abs(component) > 1e-9]
    end_offset = END_OFFSET_SHARE * max(0.0, min(limits))

    def window_for(target: np.ndarray, zoom: float) -> CropWindow:
        """The window showing the sign at output point ``target``, clamped to the scene."""
        left = _clamp(sign_x - target[0] / zoom, 0.0, scene_width - out_width / zoom)
        top = _clamp(sign_y - target[1] / zoom, 0.0, scene_height - out_height / zoom)
        return CropWindow(left, top, zoom)

    # the first frame: the sign's offset is the last one's / growth (pure approach);
    # the last: the first's actual offset x growth, kept inside the output
    start = np.array(window_for(centre + direction * end_offset / growth,
                                first_zoom).to_output(sign_x, sign_y))
    low = np.minimum(room, centre)
    end = np.clip(centre + (start - centre) * growth, low, size - low)
    windows = []
    for frame in range(frames):
        progress = frame / (frames - 1)
        zoom = first_zoom / (1.0 - (1.0 - 1.0 / growth) * progress)
        share = (zoom - first_zoom) / (last_zoom - first_zoom) if growth > 1.0 else 0.0
        windows.append(window_for(start + (end - start) * share, zoom))
    return tuple(windows)


def gap_windows(signs: Sequence[SceneSign], scene_size: tuple[int, int],
                output_size: tuple[int, int], frames: int) -> tuple[tuple[CropWindow, ...], bool]:
    """Windows of a sign-free gap in the scene, and whether it must be blurred instead.

    Returns:
        (``frames`` windows, False) on the lowest, most central window free of signs at
        the first of :data:`GAP_ZOOMS` that has one, magnified by up to
        :data:`GAP_ZOOM_GAIN` about its centre; or (whole-scene windows, True) when no
        window is free.
    """
    scene_width, scene_height = scene_size
    out_width, out_height = output_size
    first_zoom = max(out_width / scene_width, out_height / scene_height)
    for relative_zoom in GAP_ZOOMS:
        zoom = first_zoom * relative_zoom
        width, height = out_width / zoom, out_height / zoom
        free = _free_window(signs, scene_width, scene_height, width, height)
        if free is None:
            continue
        left, top = free
        centre_x, centre_y = left + 0.5 * width, top + 0.5 * height
        windows = []
        for frame in range(frames):
            frame_zoom = zoom * (1.0 + (GAP_ZOOM_GAIN - 1.0) * frame / max(frames - 1, 1))
            windows.append(CropWindow(centre_x - 0.5 * out_width / frame_zoom,
                                      centre_y - 0.5 * out_height / frame_zoom, frame_zoom))
        return tuple(windows), False
    whole = CropWindow(0.5 * (scene_width - out_width / first_zoom),
                       0.5 * (scene_height - out_height / first_zoom), first_zoom)
    return (whole,) * frames, True


def plan_sequences(scenes_dir: str | Path, config: ApproachConfig
                   ) -> tuple[tuple[ApproachSequence, ...], tuple[str, ...]]:
    """Plan the sequences of a GTSDB-format folder (scenes sorted by name, signs by x).

    Args:
        scenes_dir: folder with ``gt.txt`` and ``images/``.
        config: the settings.

    Returns:
        (the sequences, the scene files with a limit sign that could not be read: they
        are skipped, with a warning in the log).

    Raises:
        ApproachSceneError: no ``gt.txt``, a malformed one, or a ``scenes`` name that is
            not in it.
    """
    scenes_dir = Path(scenes_dir)
    try:
        signs_by_file = read_gtsdb_truth(scenes_dir / 'gt.txt')
    except SpeedSignError as err:
        raise ApproachSceneError(f'{scenes_dir} is not a GTSDB-format scene folder '
                                 f'(images/ and gt.txt): {err}') from err
    files = sorted(signs_by_file)
    if config.scenes:
        unknown = sorted(set(config.scenes) - set(files))
        if unknown:
            raise ApproachSceneError(f'scene(s) {", ".join(unknown)} not annotated in '
                                     f'{scenes_dir / "gt.txt"}')
        files = [name for name in files if name in set(config.scenes)]
    output_size = (config.width_px, config.height_px)
    sequences: list[ApproachSequence] = []
    unreadable: list[str] = []
    first_frame = 0
    for name in files:
        signs = tuple(signs_by_file[name])
        limits = sorted((sign for sign in signs
                         if sign.limit_kmh > 0 and 2.0 * sign.radius_px >= config.min_sign_px),
                        key=lambda sign: (sign.x1_px, sign.y1_px))
        if not limits:
            continue
        size = _image_size(scenes_dir / 'images' / name)
        if size is None:
            LOGGER.warning('scene %s cannot be read: skipped', scenes_dir / 'images' / name)
            unreadable.append(name)
            continue
        gap, blurred = gap_windows(signs, size, output_size, config.gap_frames)
        for sign_index, sign in enumerate(limits):
            if config.max_sequences and len(sequences) >= config.max_sequences:
                return tuple(sequences), tuple(unreadable)
            rng = np.random.default_rng([config.seed, zlib.crc32(name.encode()), sign_index])
            growth = float(rng.uniform(config.growth_min, config.growth_max))
            windows = approach_windows(sign, size, output_size,
                                       config.frames_per_sequence, growth)
            sequences.append(ApproachSequence(len(sequences), name, sign, signs, growth,
                                              windows, gap, blurred, first_frame))
            first_frame += sequences[-1].frame_count
    return tuple(sequences), tuple(unreadable)


class ApproachStream:
    """The frames of all sequences of a scene folder, rendered while iterated.

    Example:
        >>> stream = ApproachStream('../shared/data/gtsdb-dev', ApproachConfig(max_sequences=2))
        >>> stream.frame_count  # doctest: +SKIP
        54
    """

    def __init__(self, scenes_dir: str | Path, config: ApproachConfig | None = None) -> None:
        self.scenes_dir = Path(scenes_dir)
        self.config = config or ApproachConfig()
        self.sequences, unreadable = plan_sequences(self.scenes_dir, self.config)
        #: scene files with a limit sign that could not be read (no frames from them)
        self.unreadable_scenes: list[str] = list(unreadable)
        #: the truth track id of each sequence's approached sign, in the order the
        #: sequences were rendered (filled while iterating; skipped sequences have none)
        self.approached_track_ids: list[int] = []

    @property
    def frame_count(self) -> int:
        """Frames of all planned sequences."""
        return sum(sequence.frame_count for sequence in self.sequences)

    def __iter__(self) -> Iterator[SyntheticFrame]:
        """Frames in order: for each sequence its approach, then its gap.

        A scene that cannot be read is skipped (logged, listed in
        :attr:`unreadable_scenes`); the stamps stay continuous.
        """
        config = self.config
        index = 0
        next_track_id = 1
        decoded: tuple[str, np.ndarray | None] | None = None   # the sequences of a scene
        for sequence in self.sequences:                          # follow one another
            if decoded is None or decoded[0] != sequence.scene_file:
                decoded = (sequence.scene_file, cv2.imread(
                    str(self.scenes_dir / 'images' / sequence.scene_file), cv2.IMREAD_COLOR))
            scene = decoded[1]
            if scene is None:
                LOGGER.warning('scene %s cannot be read: its sequence is skipped',
                               sequence.scene_file)
                if sequence.scene_file not in self.unreadable_scenes:
                    self.unreadable_scenes.append(sequence.scene_file)
                continue
            first_track_id = next_track_id
            next_track_id += len(sequence.scene_signs)
            self.approached_track_ids.append(first_track_id + next(
                offset for offset, sign in enumerate(sequence.scene_signs)
                if sign is sequence.sign))
            for window in sequence.windows:
                bgr = self._render(scene, window)
                stamp_ns = config.stamp_ns(index)
                truth = tuple(row for offset, sign in enumerate(sequence.scene_signs)
                              if (row := self._truth_row(sign, window, stamp_ns, index,
                                                         first_track_id + offset)) is not None)
                yield SyntheticFrame(index, stamp_ns, bgr, truth, 0.0)
                index += 1
            for window in sequence.gap_windows:
                bgr = self._render(scene, window)
                if sequence.gap_blurred:
                    bgr = cv2.GaussianBlur(bgr, (0, 0), GAP_BLUR_SIGMA_PX)
                yield SyntheticFrame(index, config.stamp_ns(index), bgr, (), 0.0)
                index += 1

    def _render(self, scene: np.ndarray, window: CropWindow) -> np.ndarray:
        return cv2.warpAffine(scene, window.affine(), (self.config.width_px,
                                                       self.config.height_px),
                              flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)

    def _truth_row(self, sign: SceneSign, window: CropWindow, stamp_ns: int, frame: int,
                   track_id: int) -> TruthRow | None:
        x1, y1 = window.to_output(sign.x1_px, sign.y1_px)
        x2, y2 = window.to_output(sign.x2_px, sign.y2_px)
        width, height = self.config.width_px, self.config.height_px
        inside = (max(0.0, min(x2, width) - max(x1, 0.0))
                  * max(0.0, min(y2, height) - max(y1, 0.0)))
        if (0.5 * max(x2 - x1, y2 - y1) < MIN_TRUTH_RADIUS_PX
                or inside < MIN_TRUTH_VISIBLE_FRACTION * (x2 - x1) * (y2 - y1)):
            return None
        kind = GTSDB_CLASS_KINDS.get(sign.class_id, f'gtsdb_class_{sign.class_id}')
        return TruthRow(stamp_ns * 1e-9, frame, track_id, kind, sign.limit_kmh, x1, y1, x2, y2)


def _free_window(signs: Sequence[SceneSign], scene_width: int, scene_height: int,
                 width: float, height: float) -> tuple[float, float] | None:
    """Top-left corner of the lowest, most central sign-free window of this size."""
    if width > scene_width or height > scene_height:
        return None
    step = 8.0
    tops = np.arange(scene_height - height, -1e-9, -step)
    lefts = np.arange(0.0, scene_width - width + 1e-9, step)
    lefts = sorted(lefts, key=lambda left: (abs(left + 0.5 * width - 0.5 * scene_width), left))
    margin = GAP_SIGN_MARGIN_PX
    for top in tops:
        for left in lefts:
            if not any(left - margin < sign.x2_px and sign.x1_px < left + width + margin
                       and top - margin < sign.y2_px and sign.y1_px < top + height + margin
                       for sign in signs):
                return float(left), float(top)
    return None


def _image_size(path: Path) -> tuple[int, int] | None:
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        return None
    return int(image.shape[1]), int(image.shape[0])


def _clamp(value: float, low: float, high: float) -> float:
    return min(max(value, low), max(low, high))


__all__ = ['ApproachConfig', 'ApproachSceneError', 'ApproachSequence', 'ApproachStream',
           'CropWindow', 'GTSDB_CLASS_KINDS', 'approach_windows', 'gap_windows',
           'plan_sequences']
