"""Synthetic drives: a camera moving along a road lined with signs, frame by frame.

No ROS here: :class:`SyntheticDrive` renders BGR frames (numpy) and the truth rows
(:class:`speed_sign_detector.truth.TruthRow`) of every sign in view; the
``speed_sign_synth`` tool writes them into a bag and a truth file.

World and camera (metres, right-handed, y down):

- ``X`` to the right, ``Y`` down, ``Z`` along the road. The ground is the plane
  ``Y = camera_height_m``; the camera drives in the right lane along ``Z`` at about
  ``speed_mps`` with a slow lateral sway, a small yaw wobble and a pitch shake.
- Pinhole camera, focal length ``focal_px`` pixels, principal point at the image
  centre, pitched down by ``base_pitch_deg``.
- Road: two 3.6 m lanes between ``X = -5.4`` and ``X = +1.8``, edge lines, a dashed
  centre line; grass verges, trees, lamp posts with round globes, traffic mirrors.
- Signs: round signs on poles right of the road (look-alikes also on the left), outer
  radius 0.32 to 0.40 m, turned slightly out of the image plane. A sign grows from
  5-10 px radius to 35-50 px before it leaves the image at the right edge and is
  visible for about 2 s (the first sign) to 4 s at the default speed. The truth lists
  a sign while 3/4 of its box lies inside the image and its radius is at least 5 px, or
  3.5 px for an end sign (:func:`min_truth_radius_px`: from where the edge the detector
  votes on reaches its least radius).
- Look-alikes: end-of-limit signs and other round signs (no overtaking, no entry,
  weight/width/height limits, ...), half each.
- Distractors (:mod:`.synthetic_roadside`): lamp globes (growing circles), a vehicle
  ahead with a spare wheel and round tail lights (circles that hardly grow), stickers
  fixed on the windscreen (circles that never move).
- Lighting: ``day``, ``dusk`` (darker, warm), ``night`` (dark, low contrast, headlight
  pool on the road, retro-reflecting signs, lit lamps) or ``mixed`` (day to night
  over the drive). Motion blur (forward motion and camera shake; exposure about 4 ms
  by day, 13 ms at dusk, 30 ms at night at 30 fps) and sensor noise.

Everything is a function of the seed and the frame index: the same
:class:`DriveConfig` renders the same frames in any order.
"""
from __future__ import annotations

import functools
import math
from collections.abc import Iterator
from dataclasses import dataclass

import cv2
import numpy as np

from speed_sign_detector.synthetic_roadside import (
    LeadVehicle,
    RoadsideProp,
    Sticker,
    draw_lead_vehicle,
    draw_props,
    draw_stickers,
    place_props,
    plan_lead_vehicle,
    plan_stickers,
)
from speed_sign_detector.synthetic_scenery import (
    FAR_AZIMUTH_RAD,
    FAR_SIZE,
    FAR_TAN_HIGH,
    FAR_TAN_LOW,
    FOG_DISTANCE_M,
    GROUND_HALF_WIDTH_M,
    GROUND_PERIOD_M,
    GROUND_RESOLUTION_M,
    apply_lighting,
    background_gain,
    composite,
    far_texture,
    fill_rect,
    ground_texture,
    headlight_pool,
    line_kernel,
    sign_image,
)
from speed_sign_detector.truth import TruthRow, is_end_of_limit_kind

#: Lighting choices of a drive.
LIGHTING_CHOICES: tuple[str, ...] = ('day', 'dusk', 'night', 'mixed')
#: Darkness of each fixed lighting (0 = day, 0.5 = dusk, 1 = night).
DARKNESS: dict[str, float] = {'day': 0.0, 'dusk': 0.5, 'night': 1.0}
#: A sign with a red ring (a limit, most look-alikes) is in the truth while its radius is
#: at least this, pixels: the detector votes on the ring's inner edge (0.66 of the radius),
#: which reaches the detector's least radius (``detector.min_radius_px``, 3.5 px) there.
MIN_TRUTH_RADIUS_PX = 5.0
#: An end sign (end of limit, end of all restrictions: a thin black rim, no red ring) from
#: this radius, pixels: the detector votes on its outer edge, so it is found, and read,
#: from the detector's least radius.
MIN_TRUTH_RADIUS_END_SIGN_PX = 3.5
#: ... and at least this fraction of its box lies inside the image.
MIN_TRUTH_VISIBLE_FRACTION = 0.75


@dataclass(frozen=True)
class DriveConfig:
    """Settings of one synthetic drive.

    Attributes:
        seed: random seed; the drive is a deterministic function of the config.
        duration_s: length of the drive, seconds.
        fps: camera rate, frames per second.
        lighting: one of :data:`LIGHTING_CHOICES`.
        width_px, height_px: image size.
        focal_px: focal length, pixels.
        speed_mps: mean forward speed, metres per second.
        start_stamp_s: message time of the first frame, seconds since the epoch.
        camera_height_m: camera height above the road.
        base_pitch_deg: the camera's downward tilt.
        lookalike_fraction: share of the sign slots that get a look-alike sign.
        distractors: draw lamps, mirrors, the vehicle ahead and windscreen stickers.
    """

    seed: int = 0
    duration_s: float = 20.0
    fps: float = 30.0
    lighting: str = 'day'
    width_px: int = 640
    height_px: int = 480
    focal_px: float = 760.0
    speed_mps: float = 12.0
    start_stamp_s: float = 1_700_000_000.0
    camera_height_m: float = 1.3
    base_pitch_deg: float = 2.0
    lookalike_fraction: float = 0.35
    distractors: bool = True

    def __post_init__(self) -> None:
        if self.lighting not in LIGHTING_CHOICES:
            raise ValueError(f'lighting must be one of {", ".join(LIGHTING_CHOICES)}, '
                             f'got {self.lighting!r}')
        if not 0.0 < self.duration_s <= 3600.0:
            raise ValueError(f'duration_s must be in (0, 3600] seconds, got {self.duration_s}')
        if not 1.0 <= self.fps <= 240.0:
            raise ValueError(f'fps must be in [1, 240], got {self.fps}')
        if not (64 <= self.width_px <= 4096 and 48 <= self.height_px <= 4096):
            raise ValueError(f'image size {self.width_px}x{self.height_px} out of range '
                             f'(64..4096 x 48..4096)')
        if not 1.0 <= self.speed_mps <= 60.0:
            raise ValueError(f'speed_mps must be in [1, 60], got {self.speed_mps}')
        if not 0.0 <= self.lookalike_fraction <= 1.0:
            raise ValueError(f'lookalike_fraction must be in [0, 1], got '
                             f'{self.lookalike_fraction}')

    @property
    def frame_count(self) -> int:
        """Number of frames of the drive."""
        return max(1, int(round(self.duration_s * self.fps)))

    def stamp_ns(self, frame: int) -> int:
        """Message time of a frame, integer nanoseconds since the epoch."""
        return int(round(self.start_stamp_s * 1e9)) + int(round(frame * 1e9 / self.fps))


@dataclass(frozen=True)
class SignPlacement:
    """A sign standing beside the road.

    Attributes:
        track_id: the sign's id in the truth (1, 2, ...).
        kind: a kind of :func:`speed_sign_detector.recognition.templates.render_sign`.
        limit_kmh: the limit it sets, km/h; 0 when it is not a speed limit.
        x_m, z_m: position of its centre across and along the road.
        height_m: height of its centre above the road.
        radius_m: outer radius of the sign plate.
        yaw_deg: turn of the plate about the vertical axis (out-of-plane rotation).
        roll_deg: in-plane rotation of the plate.
        fading: 0 = new plate, up to ~0.3 = weathered (washed-out colours).
    """

    track_id: int
    kind: str
    limit_kmh: int
    x_m: float
    z_m: float
    height_m: float
    radius_m: float
    yaw_deg: float
    roll_deg: float
    fading: float


@dataclass(frozen=True)
class SyntheticFrame:
    """One rendered frame.

    Attributes:
        index: 0-based frame index.
        stamp_ns: message time, nanoseconds since the epoch.
        bgr: the image, (H, W, 3) uint8, BGR.
        truth: the signs in view (see :mod:`speed_sign_detector.truth`).
        darkness: lighting of the frame, 0 = day, 0.5 = dusk, 1 = night.
    """

    index: int
    stamp_ns: int
    bgr: np.ndarray
    truth: tuple[TruthRow, ...]
    darkness: float

    @property
    def stamp_s(self) -> float:
        """Message time, seconds."""
        return self.stamp_ns * 1e-9


@dataclass(frozen=True)
class _Pose:
    x_m: float
    z_m: float
    yaw_rad: float
    pitch_rad: float
    yaw_rate: float     # rad/s
    pitch_rate: float   # rad/s


@dataclass(frozen=True)
class _SignView:
    """Where a sign appears in one frame: centre (px), radius (px), horizontal squeeze
    (out-of-plane rotation) and its truth box (None when too small or mostly outside)."""

    u_px: float
    v_px: float
    radius_px: float
    width_factor: float
    box: tuple[float, float, float, float] | None


def min_truth_radius_px(kind: str) -> float:
    """The least radius, pixels, at which the truth lists a sign of this kind:
    :data:`MIN_TRUTH_RADIUS_END_SIGN_PX` for an end sign (no red ring), else
    :data:`MIN_TRUTH_RADIUS_PX`."""
    return MIN_TRUTH_RADIUS_END_SIGN_PX if is_end_of_limit_kind(kind) else MIN_TRUTH_RADIUS_PX


#: Kinds the renderer draws that the drives leave out, so that a drive of a given seed stays
#: the drive its published figures were measured on (140 km/h came later; the rendered
#: designs' bench, bench/bench_sign_designs.py, reads it).
DRIVE_EXCLUDED_KINDS: frozenset[str] = frozenset({'140', 'end_of_limit_140'})


def sign_kinds() -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(speed-limit kinds, look-alike kinds) that the drives place: those the sign
    renderer can draw but :data:`DRIVE_EXCLUDED_KINDS`."""
    from speed_sign_detector.recognition.templates import SIGN_KINDS

    kinds = [kind for kind in SIGN_KINDS if kind not in DRIVE_EXCLUDED_KINDS]
    limits = tuple(kind for kind in kinds if kind.isdigit() and int(kind) > 0)
    lookalikes = tuple(kind for kind in kinds if not kind.isdigit())
    return limits, lookalikes


class SyntheticDrive:
    """A deterministic synthetic drive; render any frame with :meth:`frame`.

    Example:
        >>> drive = SyntheticDrive(DriveConfig(seed=3, duration_s=1.0, fps=5))
        >>> frame = drive.frame(0)
        >>> frame.bgr.shape
        (480, 640, 3)
    """

    def __init__(self, config: DriveConfig | None = None) -> None:
        self.config = config or DriveConfig()
        config = self.config
        rng = np.random.default_rng([config.seed, 1])
        self._phases = rng.uniform(0.0, 2.0 * math.pi, 8)
        self._speed_wobble = rng.uniform(0.03, 0.08)
        self.signs: tuple[SignPlacement, ...] = self._place_signs(rng)
        self._props: tuple[RoadsideProp, ...] = (
            place_props(rng, config.speed_mps * config.duration_s) if config.distractors
            else ())
        self._lead_vehicle: LeadVehicle | None = (
            plan_lead_vehicle(rng, config.duration_s) if config.distractors else None)
        self._stickers: tuple[Sticker, ...] = (
            plan_stickers(rng, config.width_px, config.height_px) if config.distractors
            else ())
        self._ground = ground_texture(np.random.default_rng([config.seed, 2]))
        self._far = far_texture(np.random.default_rng([config.seed, 3]))
        width, height = config.width_px, config.height_px
        cols, rows = np.meshgrid(np.arange(width, dtype=np.float32) + 0.5,
                                 np.arange(height, dtype=np.float32) + 0.5)
        self._ray_x = (cols - width / 2.0) / config.focal_px
        self._ray_y = (rows - height / 2.0) / config.focal_px
        self._headlight = headlight_pool(width, height)

    # ----------------------------------------------------------------- public API
    @property
    def frame_count(self) -> int:
        """Number of frames of the drive."""
        return self.config.frame_count

    def __iter__(self) -> Iterator[SyntheticFrame]:
        for index in range(self.frame_count):
            yield self.frame(index)

    def darkness(self, time_s: float) -> float:
        """Lighting at a time: 0 = day, 0.5 = dusk, 1 = night."""
        if self.config.lighting == 'mixed':
            return float(np.clip(time_s / max(self.config.duration_s, 1e-6), 0.0, 1.0))
        return DARKNESS[self.config.lighting]

    def truth(self, index: int) -> tuple[TruthRow, ...]:
        """The truth rows of one frame (cheap: no rendering)."""
        time_s = index / self.config.fps
        pose = self._pose(time_s)
        stamp_s = self.config.stamp_ns(index) * 1e-9
        rows = []
        for sign in self.signs:
            view = self._sign_view(sign, pose)
            if view is not None and view.box is not None:
                rows.append(TruthRow(stamp_s, index, sign.track_id, sign.kind, sign.limit_kmh,
                                     *view.box))
        return tuple(rows)

    def frame(self, index: int) -> SyntheticFrame:
        """Render frame ``index`` (0-based) with its truth."""
        config = self.config
        if not 0 <= index < self.frame_count:
            raise IndexError(f'frame {index} outside the drive (0..{self.frame_count - 1})')
        time_s = index / config.fps
        pose = self._pose(time_s)
        darkness = self.darkness(time_s)
        night = float(np.clip((darkness - 0.5) * 2.0, 0.0, 1.0))
        # Exposure: ~4 ms by day, ~13 ms at dusk, ~30 ms at night (at 30 fps).
        exposure_s = (0.12 + 0.78 * darkness) / config.fps
        rng = np.random.default_rng([config.seed, 4, index])

        image = self._background(pose)
        project = functools.partial(self._project, pose)
        scene = (pose.z_m, project, config.focal_px)
        draw_props(image, self._props, *scene, config.width_px, config.camera_height_m, night,
                   emissive=False)
        draw_lead_vehicle(image, self._lead_vehicle, time_s, *scene, config.camera_height_m,
                          night, emissive=False)
        draw_stickers(image, self._stickers)
        image = apply_lighting(image, darkness, self._headlight)
        rows = []
        for sign in sorted(self.signs, key=lambda s: -(s.z_m - pose.z_m)):
            view = self._sign_view(sign, pose)
            if view is None:
                continue
            self._draw_sign(image, sign, view, pose, darkness, exposure_s)
            if view.box is not None:
                rows.append(TruthRow(config.stamp_ns(index) * 1e-9, index, sign.track_id,
                                     sign.kind, sign.limit_kmh, *view.box))
        draw_props(image, self._props, *scene, config.width_px, config.camera_height_m, night,
                   emissive=True)
        draw_lead_vehicle(image, self._lead_vehicle, time_s, *scene, config.camera_height_m,
                          night, emissive=True)
        image = _shake_blur(image, pose, config.focal_px, exposure_s)
        noise_sigma = 1.5 + 4.5 * darkness
        image += rng.standard_normal(image.shape, dtype=np.float32) * noise_sigma
        bgr = np.clip(image, 0.0, 255.0).astype(np.uint8)
        rows.sort(key=lambda row: row.track_id)
        return SyntheticFrame(index, config.stamp_ns(index), bgr, tuple(rows), darkness)

    # ------------------------------------------------------------------ layout
    def _place_signs(self, rng: np.random.Generator) -> tuple[SignPlacement, ...]:
        """Signs at increasing Z; each is passed before the drive ends."""
        config = self.config
        limit_kinds, lookalike_kinds = sign_kinds()
        half_width_px = config.width_px / 2.0
        road_end_m = config.speed_mps * config.duration_s
        signs: list[SignPlacement] = []
        exit_time_s = 1.8 + rng.uniform(0.0, 0.4)
        previous_limit = ''
        while True:
            is_limit = not signs or rng.uniform() >= config.lookalike_fraction
            radius_m = float(rng.choice([0.32, 0.36, 0.40]))
            if is_limit or rng.uniform() < 0.7:
                x_m = float(rng.uniform(2.2, 2.7))
            else:
                x_m = float(rng.uniform(-6.2, -5.8))
            # Z where the sign's outer edge leaves the image (straight ahead camera).
            exit_offset_m = config.focal_px * (abs(x_m) + radius_m) / half_width_px
            z_m = config.speed_mps * exit_time_s + exit_offset_m
            if z_m - exit_offset_m > road_end_m - 0.1 * config.speed_mps:
                break
            if is_limit:
                choices = [kind for kind in limit_kinds if kind != previous_limit]
                kind = str(rng.choice(choices))
                previous_limit = kind
                limit_kmh = int(kind)
            else:
                ends = [kind for kind in lookalike_kinds if kind.startswith('end_of_limit')]
                others = [kind for kind in lookalike_kinds if kind not in ends] or ends
                kind = str(rng.choice(ends if rng.uniform() < 0.5 else others))
                limit_kmh = 0
            signs.append(SignPlacement(
                track_id=len(signs) + 1, kind=kind, limit_kmh=limit_kmh, x_m=x_m, z_m=z_m,
                height_m=float(rng.uniform(2.2, 2.6)), radius_m=radius_m,
                yaw_deg=float(rng.uniform(-20.0, 20.0)), roll_deg=float(rng.uniform(-4, 4)),
                fading=float(rng.uniform(0.0, 0.3))))
            exit_time_s += rng.uniform(2.6, 4.2)
        return tuple(signs)

    # ------------------------------------------------------------------ camera
    def _pose(self, time_s: float) -> _Pose:
        config = self.config
        p = self._phases
        omega = 2.0 * math.pi
        z_m = config.speed_mps * (time_s + self._speed_wobble
                                  * math.sin(omega * 0.07 * time_s + p[0]) / (omega * 0.07))
        x_m = 0.15 * math.sin(omega * 0.09 * time_s + p[1])
        yaw = math.radians(0.5 * math.sin(omega * 0.23 * time_s + p[2])
                           + 0.15 * math.sin(omega * 1.1 * time_s + p[3]))
        yaw_rate = math.radians(0.5 * omega * 0.23 * math.cos(omega * 0.23 * time_s + p[2])
                                + 0.15 * omega * 1.1 * math.cos(omega * 1.1 * time_s + p[3]))
        pitch = math.radians(config.base_pitch_deg + 0.25 * math.sin(omega * 1.7 * time_s + p[4])
                             + 0.12 * math.sin(omega * 4.3 * time_s + p[5]))
        pitch_rate = math.radians(0.25 * omega * 1.7 * math.cos(omega * 1.7 * time_s + p[4])
                                  + 0.12 * omega * 4.3 * math.cos(omega * 4.3 * time_s + p[5]))
        return _Pose(x_m, z_m, yaw, pitch, yaw_rate, pitch_rate)

    def _project(self, pose: _Pose, x_m: float, y_m: float, z_m: float
                 ) -> tuple[float, float, float] | None:
        """World point (Y down from the camera height) -> (u px, v px, depth m)."""
        dx, dz = x_m - pose.x_m, z_m - pose.z_m
        cos_yaw, sin_yaw = math.cos(pose.yaw_rad), math.sin(pose.yaw_rad)
        x1 = cos_yaw * dx - sin_yaw * dz
        z1 = sin_yaw * dx + cos_yaw * dz
        cos_p, sin_p = math.cos(pose.pitch_rad), math.sin(pose.pitch_rad)
        y2 = cos_p * y_m - sin_p * z1
        z2 = sin_p * y_m + cos_p * z1
        if z2 < 0.5:
            return None
        focal = self.config.focal_px
        return (self.config.width_px / 2.0 + focal * x1 / z2,
                self.config.height_px / 2.0 + focal * y2 / z2, z2)

    # ------------------------------------------------------------------ drawing
    def _background(self, pose: _Pose) -> np.ndarray:
        """Road, verges and far scene by casting a ray through every pixel."""
        config = self.config
        cos_p, sin_p = math.cos(pose.pitch_rad), math.sin(pose.pitch_rad)
        cos_y, sin_y = math.cos(pose.yaw_rad), math.sin(pose.yaw_rad)
        # Ray in camera coordinates (x, y, 1) -> world: yaw(pitch(ray)).
        ray_y = cos_p * self._ray_y + sin_p
        ray_z1 = -sin_p * self._ray_y + cos_p
        ray_x = cos_y * self._ray_x + sin_y * ray_z1
        ray_z = -sin_y * self._ray_x + cos_y * ray_z1
        horizontal = np.sqrt(ray_x * ray_x + ray_z * ray_z)
        # Far scene: azimuth and tan(elevation).
        azimuth = np.arctan2(ray_x, ray_z)
        tan_elevation = -ray_y / horizontal
        far_map_x = ((azimuth + FAR_AZIMUTH_RAD) / (2 * FAR_AZIMUTH_RAD) * FAR_SIZE[1]
                     ).astype(np.float32)
        far_map_y = ((FAR_TAN_HIGH - tan_elevation) / (FAR_TAN_HIGH - FAR_TAN_LOW)
                     * FAR_SIZE[0]).astype(np.float32)
        far = cv2.remap(self._far, far_map_x, far_map_y, cv2.INTER_LINEAR,
                        borderMode=cv2.BORDER_REPLICATE)
        # Ground: intersect with the plane Y = camera height.
        below = ray_y > 1e-4
        distance = np.where(below, config.camera_height_m / np.maximum(ray_y, 1e-4), 1e4)
        ground_x = pose.x_m + distance * ray_x
        ground_z = pose.z_m + distance * ray_z
        texels = 1.0 / GROUND_RESOLUTION_M
        map_x = np.clip((ground_x + GROUND_HALF_WIDTH_M) * texels, 0,
                        self._ground.shape[1] - 1).astype(np.float32)
        map_y = (np.mod(ground_z, GROUND_PERIOD_M) * texels).astype(np.float32)
        ground = cv2.remap(self._ground, map_x, map_y, cv2.INTER_LINEAR,
                           borderMode=cv2.BORDER_WRAP)
        weight = np.exp(-(distance * horizontal) / FOG_DISTANCE_M) * below
        weight = weight[..., None].astype(np.float32)
        return ground * weight + far * (1.0 - weight)

    def _sign_view(self, sign: SignPlacement, pose: _Pose) -> _SignView | None:
        """Where the sign appears, or None when it is behind the camera or off-image."""
        y_m = self.config.camera_height_m - sign.height_m
        projected = self._project(pose, sign.x_m, y_m, sign.z_m)
        if projected is None:
            return None
        u_px, v_px, depth_m = projected
        radius_px = self.config.focal_px * sign.radius_m / depth_m
        view_angle = math.atan2(sign.x_m - pose.x_m, sign.z_m - pose.z_m)
        width_factor = max(0.2, math.cos(view_angle - math.radians(sign.yaw_deg)))
        roll = math.radians(sign.roll_deg)
        half_w = radius_px * math.hypot(width_factor * math.cos(roll), math.sin(roll))
        half_h = radius_px * math.hypot(width_factor * math.sin(roll), math.cos(roll))
        width, height = self.config.width_px, self.config.height_px
        if (u_px + half_w < 0 or u_px - half_w > width or v_px + half_h < 0
                or v_px - half_h > height):
            return None
        box = (u_px - half_w, v_px - half_h, u_px + half_w, v_px + half_h)
        inside_w = max(0.0, min(box[2], width) - max(box[0], 0.0))
        inside_h = max(0.0, min(box[3], height) - max(box[1], 0.0))
        fraction = inside_w * inside_h / max((box[2] - box[0]) * (box[3] - box[1]), 1e-9)
        visible = (radius_px >= min_truth_radius_px(sign.kind)
                   and fraction >= MIN_TRUTH_VISIBLE_FRACTION)
        return _SignView(u_px, v_px, radius_px, width_factor, box if visible else None)

    def _draw_sign(self, image: np.ndarray, sign: SignPlacement, view: _SignView,
                   pose: _Pose, darkness: float, exposure_s: float) -> None:
        """Pole, then the plate: warped, motion-blurred, lit, alpha-composited."""
        u_px, v_px, radius_px, width_factor = (view.u_px, view.v_px, view.radius_px,
                                               view.width_factor)
        height_m = self.config.camera_height_m
        # Pole from the ground to the plate (part of the lit scene).
        ground = self._project(pose, sign.x_m, height_m, sign.z_m)
        night = float(np.clip((darkness - 0.5) * 2.0, 0.0, 1.0))
        gain = background_gain(darkness)
        if ground is not None:
            pole_half_w = max(0.6, 0.04 * self.config.focal_px / ground[2])
            fill_rect(image, u_px - pole_half_w, v_px, u_px + pole_half_w, ground[1],
                      tuple(c * gain for c in (120.0, 125.0, 125.0)))
        if radius_px < 1.5:
            return
        diameter = max(4, int(round(2.0 * radius_px)))
        sign_bgr, sign_alpha = sign_image(sign.kind, diameter)
        # Forward-motion blur: where the sign was at the start of the exposure.
        earlier = _Pose(pose.x_m, pose.z_m - self.config.speed_mps * exposure_s, pose.yaw_rad,
                        pose.pitch_rad, 0.0, 0.0)
        before = self._project(earlier, sign.x_m, height_m - sign.height_m, sign.z_m)
        blur = (u_px - before[0], v_px - before[1]) if before is not None else (0.0, 0.0)
        pad = int(math.ceil(abs(blur[0]) + abs(blur[1]))) + 3
        size = diameter + 2 * pad
        # Affine map from the rendered sign to the patch: roll, squeeze, sub-pixel shift.
        roll = math.radians(sign.roll_deg)
        scale = 2.0 * radius_px / diameter
        linear = np.array([[math.cos(roll), -math.sin(roll)], [math.sin(roll), math.cos(roll)]]
                          ) @ np.diag([width_factor * scale, scale])
        origin_u, origin_v = math.floor(u_px) - size // 2, math.floor(v_px) - size // 2
        centre_patch = np.array([u_px - origin_u, v_px - origin_v])
        offset = centre_patch - linear @ np.array([diameter / 2.0, diameter / 2.0])
        matrix = np.hstack([linear, offset[:, None]]).astype(np.float64)
        premultiplied = cv2.warpAffine(sign_bgr, matrix, (size, size), flags=cv2.INTER_LINEAR)
        alpha = cv2.warpAffine(sign_alpha, matrix, (size, size), flags=cv2.INTER_LINEAR)
        kernel = line_kernel(*blur)
        if kernel is not None:
            premultiplied = cv2.filter2D(premultiplied, -1, kernel)
            alpha = cv2.filter2D(alpha, -1, kernel)
        # Lighting of the plate: sun, dusk, or headlights on retro-reflecting foil.
        depth_m = self.config.focal_px * sign.radius_m / radius_px
        headlight_gain = 0.3 + 0.45 * min(1.0, 18.0 / depth_m)
        gain = (1.0 - night) * (1.0 - 0.45 * min(darkness, 0.5) * 2.0) + night * headlight_gain
        fading = sign.fading + 0.3 * night   # washed out and low contrast
        mean_colour = premultiplied.reshape(-1, 3).sum(axis=0) / max(float(alpha.sum()), 1e-6)
        lit = gain * ((1.0 - fading) * premultiplied + fading * alpha[..., None] * mean_colour)
        composite(image, origin_u, origin_v, lit, alpha)


def _shake_blur(image: np.ndarray, pose: _Pose, focal_px: float, exposure_s: float
                ) -> np.ndarray:
    """Blur along the image motion caused by the camera's rotation."""
    kernel = line_kernel(focal_px * pose.yaw_rate * exposure_s,
                         focal_px * pose.pitch_rate * exposure_s)
    return image if kernel is None else cv2.filter2D(image, -1, kernel)
