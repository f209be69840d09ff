"""Radial-symmetry voting, numpy reference (IVS 2011, III-B and III-D).

Every edge pixel votes along its gradient for centres at distances ``r0 .. r1`` of a
radius band, spread perpendicular to the gradient by ``+/- r tan(pi/8)`` (the octagon
approximation of a circle), i.e. it "draws" a trapezoid with corners
``p + r0 (g +/- t n)`` and ``p + r1 (g +/- t n)``. A pixel receives the vote when its
centre lies inside the trapezoid (the rasterization rule of the GL backend, which draws
the triangle ``p, p + r1 (g +/- t n)`` and discards fragments nearer than ``r0``).

A vote at distance ``u`` along the gradient and ``v`` across it weighs
``profile / u`` with ``profile = 1 - |v| / (t u)`` (``vote_profile='tent'``; 1 with
``'flat'``, the paper's uniform spread). ``1 / u``: a complete circle of radius ``R``
gives its centre ``2 pi`` whatever ``R`` is (its ``2 pi R`` edge pixels each add
``1 / R``), so radius bands compete fairly. The tent: on the gradient line the weight
is full, so the votes of a circle pile up in a sharp peak at its centre instead of a
plateau as wide as the band (where ``1 / u`` would even favour the plateau's rim).

Radius bands are geometric between ``min_radius_px`` and ``max_radius_px``; band ``b``
votes on the coarsest pyramid level on which its smallest radius is still at least
``level_min_radius_px`` level pixels (fewer edges, 4x fewer fragments per octave).

The vote image of one band has ``CHANNELS = 2`` channels per pixel:
``(sum profile / u, sum profile)`` over the votes it received; their ratio is the
(profile-weighted) harmonic mean voting distance, the radius estimate. (A
direction-balance term, the resultant of the vote directions, was tried and lowered
recall on GTSDB: isotropic clutter such as foliage votes from all sides too.)
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from speed_sign_detector.config import DetectorConfig
from speed_sign_detector.detection.gradients import (
    EdgeList,
    build_pyramid,
    extract_edges,
    gray_lookup,
)

CHANNELS = 2
"""Channels of a band's vote image: ``(sum profile / u, sum profile)``."""
SPREAD = math.tan(math.pi / 8.0)
"""Half-width of the vote spread per unit distance (octagon, n = 8)."""


@dataclass(frozen=True)
class RadiusBand:
    """One radius band and the pyramid level it votes on.

    Attributes:
        index: band number, 0 = smallest radii.
        level: pyramid level whose edges vote for this band.
        target_level: pyramid level whose size the band's vote image has (>= level).
        min_radius_px, max_radius_px: the band's radii in full-resolution pixels.
    """

    index: int
    level: int
    target_level: int
    min_radius_px: float
    max_radius_px: float

    @property
    def scale(self) -> int:
        """Full-resolution pixels per edge-level pixel."""
        return 1 << self.level

    @property
    def target_scale(self) -> int:
        """Full-resolution pixels per vote-image pixel."""
        return 1 << self.target_level

    @property
    def shrink(self) -> float:
        """Vote-image pixels per edge-level pixel (1, 1/2, 1/4)."""
        return 1.0 / (1 << (self.target_level - self.level))

    @property
    def level_radii(self) -> tuple[float, float]:
        """``(r0, r1)`` in level pixels."""
        return self.min_radius_px / self.scale, self.max_radius_px / self.scale


def plan_bands(config: DetectorConfig) -> tuple[RadiusBand, ...]:
    """The radius bands of a config, smallest first."""
    ratio = (config.max_radius_px / config.min_radius_px) ** (1.0 / config.radius_bands)
    bands = []
    for index in range(config.radius_bands):
        low = config.min_radius_px * ratio ** index
        high = config.min_radius_px * ratio ** (index + 1)
        level = 0
        coarsest = min(config.max_pyramid_level, int(math.log2(config.block_size_px)))
        while (level < coarsest
               and low / (1 << (level + 1)) >= config.level_min_radius_px):
            level += 1
        target_level = level
        if config.vote_pixels_per_radius > 0.0:
            while (target_level < coarsest
                   and (1 << (target_level + 1)) <= low / config.vote_pixels_per_radius):
                target_level += 1
        bands.append(RadiusBand(index, level, target_level, low, high))
    return tuple(bands)


def min_frame_size_px(config: DetectorConfig) -> int:
    """Smallest frame side the detector accepts: one voting window (2 max radii + 3)."""
    bands = plan_bands(config)
    coarsest = max(band.target_level for band in bands)
    return max(math.ceil(2.0 * config.max_radius_px) + 3, 3 << coarsest)


def pyramid_levels(bands: tuple[RadiusBand, ...]) -> int:
    """Number of pyramid levels whose edges vote."""
    return max(band.level for band in bands) + 1


def level_size(width_px: int, height_px: int, level: int) -> tuple[int, int]:
    """``(width, height)`` of pyramid level ``level`` of a frame (halved, rounded down)."""
    return width_px >> level, height_px >> level


def compute_edges(gray: np.ndarray, config: DetectorConfig) -> list[EdgeList]:
    """Edge lists of every pyramid level the config needs (index = level)."""
    bands = plan_bands(config)
    pyramid = build_pyramid(gray, pyramid_levels(bands),
                            gray_lookup(config.contrast, config.log_offset_gray))
    return [extract_edges(image, level, config.gradient_threshold, config.thin_edges,
                          config.edge_support)
            for level, image in enumerate(pyramid)]


def vote_signs(config: DetectorConfig, band: RadiusBand) -> tuple[float, ...]:
    """Directions that vote for a band: +1 toward the bright side, -1 toward the dark side.

    ``config.polarity`` sets them; with ``bright_inside``, bands whose smallest radius is
    at least ``config.dark_side_min_radius_px`` (> 0) vote toward both sides: the outer
    edge of a sign's ring against a brighter background (sky) then votes as well, which
    pays off for signs large enough to show that edge clearly.
    """
    if config.polarity == 'both':
        return (1.0, -1.0)
    if config.polarity == 'dark_inside':
        return (-1.0,)
    if 0.0 < config.dark_side_min_radius_px <= band.min_radius_px:
        return (1.0, -1.0)
    return (1.0,)


def vote_band(edges: EdgeList, band: RadiusBand, signs: tuple[float, ...],
              frame_size: tuple[int, int], tent: bool = True) -> np.ndarray:
    """Vote image of one band: (H_target, W_target, CHANNELS) float32.

    ``frame_size`` is the full-resolution ``(width, height)``. Edge-level coordinates
    ``x`` map to vote-image coordinates ``(x + 0.5) s - 0.5`` with ``s = band.shrink``;
    distances (and so the ``1 / u`` weights) stay in edge-level pixels.
    """
    width, height = level_size(frame_size[0], frame_size[1], band.target_level)
    accumulator = np.zeros(height * width * CHANNELS, dtype=np.float64)
    if edges.count:
        magnitude = np.sqrt(edges.gx * edges.gx + edges.gy * edges.gy)
        r0, r1 = band.level_radii
        shrink = band.shrink
        x = (edges.x_px.astype(np.float64) + 0.5) * shrink - 0.5
        y = (edges.y_px.astype(np.float64) + 0.5) * shrink - 0.5
        for sign in signs:
            direction_x = (sign * (edges.gx / magnitude)).astype(np.float64)
            direction_y = (sign * (edges.gy / magnitude)).astype(np.float64)
            _rasterize(accumulator, x, y, direction_x, direction_y, r0, r1, shrink,
                       width, height, tent)
    return accumulator.reshape(height, width, CHANNELS).astype(np.float32)


def _rasterize(accumulator: np.ndarray, px: np.ndarray, py: np.ndarray,
               dx: np.ndarray, dy: np.ndarray, r0: float, r1: float, shrink: float,
               width: int, height: int, tent: bool) -> None:
    """Add the trapezoid votes of all edges to ``accumulator`` (flat H*W*CHANNELS).

    ``px, py`` are in vote-image pixels, ``r0, r1`` in edge-level pixels, ``shrink`` the
    vote-image pixels per edge-level pixel.
    """
    nx, ny = -dy, dx
    weight_r0 = r0
    r0, r1 = r0 * shrink, r1 * shrink
    corners_x = np.stack([px + r0 * (dx + SPREAD * nx), px + r1 * (dx + SPREAD * nx),
                          px + r1 * (dx - SPREAD * nx), px + r0 * (dx - SPREAD * nx)], axis=1)
    corners_y = np.stack([py + r0 * (dy + SPREAD * ny), py + r1 * (dy + SPREAD * ny),
                          py + r1 * (dy - SPREAD * ny), py + r0 * (dy - SPREAD * ny)], axis=1)
    first_row = np.maximum(np.ceil(corners_y.min(axis=1)), 0).astype(np.int64)
    last_row = np.minimum(np.floor(corners_y.max(axis=1)), height - 1).astype(np.int64)
    row_counts = np.maximum(last_row - first_row + 1, 0)
    edge_of_row = np.repeat(np.arange(px.shape[0]), row_counts)
    row_starts = np.cumsum(row_counts) - row_counts
    rows = first_row[edge_of_row] + (np.arange(edge_of_row.shape[0])
                                     - row_starts[edge_of_row])
    row_y = rows.astype(np.float64)
    left = np.full(row_y.shape, np.inf)
    right = np.full(row_y.shape, -np.inf)
    for side in range(4):
        ax, ay = corners_x[edge_of_row, side], corners_y[edge_of_row, side]
        bx, by = corners_x[edge_of_row, (side + 1) % 4], corners_y[edge_of_row, (side + 1) % 4]
        crosses = ((row_y - ay) * (row_y - by) <= 0.0) & (ay != by)
        with np.errstate(divide='ignore', invalid='ignore'):
            x_at = ax + (row_y - ay) * (bx - ax) / (by - ay)
        left = np.where(crosses, np.minimum(left, x_at), left)
        right = np.where(crosses, np.maximum(right, x_at), right)
    valid = np.isfinite(left)
    first_col = np.where(valid, np.maximum(np.ceil(left), 0), 0).astype(np.int64)
    last_col = np.where(valid, np.minimum(np.floor(right), width - 1), -1).astype(np.int64)
    col_counts = np.maximum(last_col - first_col + 1, 0)
    row_of_pixel = np.repeat(np.arange(rows.shape[0]), col_counts)
    col_starts = np.cumsum(col_counts) - col_counts
    cols = first_col[row_of_pixel] + (np.arange(row_of_pixel.shape[0])
                                      - col_starts[row_of_pixel])
    pixel_rows = rows[row_of_pixel]
    edge_of_pixel = edge_of_row[row_of_pixel]
    offset_x = cols - px[edge_of_pixel]
    offset_y = pixel_rows - py[edge_of_pixel]
    along = offset_x * dx[edge_of_pixel] + offset_y * dy[edge_of_pixel]
    if tent:
        across = offset_x * nx[edge_of_pixel] + offset_y * ny[edge_of_pixel]
        with np.errstate(divide='ignore', invalid='ignore'):
            profile = np.clip(1.0 - np.abs(across) / (SPREAD * along), 0.0, 1.0)
        profile = np.where(along > 0.0, profile, 0.0)
    else:
        profile = np.ones_like(along)
    distance = np.maximum(along / shrink, 0.5 * weight_r0)
    base = (pixel_rows * width + cols) * CHANNELS
    size = accumulator.shape[0]
    accumulator += np.bincount(base, weights=profile / distance, minlength=size)
    accumulator += np.bincount(base + 1, weights=profile, minlength=size)


def vote_images(gray: np.ndarray, config: DetectorConfig) -> list[np.ndarray]:
    """Vote images of every band of a validated frame (see :func:`vote_band`)."""
    edges = compute_edges(gray, config)
    frame_size = (gray.shape[1], gray.shape[0])
    tent = config.vote_profile == 'tent'
    return [vote_band(edges[band.level], band, vote_signs(config, band), frame_size, tent)
            for band in plan_bands(config)]
