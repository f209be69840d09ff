"""Candidate sign centres: block-max reduction, non-maximum suppression, top-N.

The result type :class:`Candidate` is shared by every backend.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from speed_sign_detector.detection.voting_numpy import RadiusBand


@dataclass(frozen=True)
class Candidate:
    """One possible sign found by radial-symmetry voting.

    Attributes:
        x_px: centre column in pixels (0 = left edge of the frame, pixel centres at +0.5
            are *not* used: pixel (i, j) has centre (j, i)).
        y_px: centre row in pixels.
        radius_px: estimated radius of the sign, in pixels: the radius of the edge that
            voted (harmonic mean voting distance) divided by
            ``DetectorConfig.voting_edge_radius_ratio``. With the defaults (ratio 1,
            both polarities) that lies between the inner and the outer edge of the red
            ring, about 0.77 of the outer radius (median on GTSDB; with bright_inside
            mostly the inner edge, about 0.7).
        score: detector score (normalised vote; larger is more sign-like). Comparable
            between candidates of one frame, not an absolute probability.
        band: index of the radius band that won (0 = smallest radii).
    """

    x_px: float
    y_px: float
    radius_px: float
    score: float
    band: int = 0


@dataclass(frozen=True)
class BlockMaxima:
    """Best vote pixel of every radius band in every block of the frame (IVS 2011 IV,
    8x8 max reduction, once per band of III-D).

    All arrays are (rows, cols, bands) = (ceil(H / block), ceil(W / block), B), the bands
    in the order of their index; a slot without any positive score has ``score <= 0``.
    Every band keeps its own maximum rather than the block keeping its best band: where a
    large sign's digits fill the blocks at its centre, their loops (small circles of a
    smaller band) outscore the ring around them in every block, and the ring would never
    reach the selection (a 50 of 38 px in gtsdb-dev, 00006, found only at its loops).

    Attributes:
        score: the band's best score in the block (see :func:`band_scores`).
        x_px, y_px: its centre in full-resolution pixels (sub-pixel parabola fit).
        radius_px: the radius estimate there (harmonic mean voting distance), pixels.
        band: the band's index.
    """

    score: np.ndarray
    x_px: np.ndarray
    y_px: np.ndarray
    radius_px: np.ndarray
    band: np.ndarray


def score_normaliser(vote_directions: int) -> float:
    """Factor making a complete circle score 1: ``1 / (2 pi x vote_directions)``.

    Every edge pixel of a circle of radius R votes ``1 / R`` at its centre, and there are
    about ``2 pi R`` of them; a band whose edges vote toward both sides (two directions)
    collects up to twice that (inner and outer edge of the ring), and so does clutter.
    """
    return 1.0 / (2.0 * math.pi * vote_directions)


def band_scores(votes: np.ndarray, normaliser: float) -> np.ndarray:
    """Score of a band's vote image (H, W, CHANNELS) -> (H, W) float32: ``sum w x normaliser``.

    With :func:`score_normaliser`, about the fraction of a complete circle that voted for
    the pixel (1 = complete).
    """
    return (votes[..., 0] * np.float32(normaliser)).astype(np.float32)


def block_maxima(votes: Sequence[np.ndarray], bands: Sequence[RadiusBand],
                 frame_shape: tuple[int, int], block_px: int,
                 normalisers: Sequence[float]) -> BlockMaxima:
    """Every band's best pixel per block, the numpy twin of the GL reduction shader.

    ``votes[b]`` is band ``bands[b]``'s vote image and ``normalisers[b]`` scales its votes
    to its score (see :func:`score_normaliser`); slot ``b`` of the result is that band's.
    """
    height, width = frame_shape
    rows, cols = -(-height // block_px), -(-width // block_px)
    shape = (rows, cols, len(bands))
    best = np.full(shape, -1.0, np.float32)
    x_px, y_px, radius_px = (np.zeros(shape, np.float32) for _ in range(3))
    band_index = np.broadcast_to(np.array([band.index for band in bands], np.int32),
                                 shape).copy()
    for slot, (band, image, normaliser) in enumerate(zip(bands, votes, normalisers,
                                                          strict=True)):
        score = band_scores(image, normaliser)
        level_height, level_width = score.shape
        step = max(1, block_px // band.target_scale)
        padded = np.full((rows * step, cols * step), -np.inf, np.float32)
        used_rows, used_cols = min(level_height, rows * step), min(level_width, cols * step)
        padded[:used_rows, :used_cols] = score[:used_rows, :used_cols]
        tiles = padded.reshape(rows, step, cols, step).transpose(0, 2, 1, 3)
        tiles = tiles.reshape(rows, cols, step * step)
        arg = tiles.argmax(axis=-1)   # the first of equal pixels, row-major
        value = np.take_along_axis(tiles, arg[..., None], axis=-1)[..., 0]
        voted = value > 0.0
        if not np.any(voted):
            continue
        block_rows, block_cols = np.nonzero(voted)
        qy = block_rows * step + arg[voted] // step
        qx = block_cols * step + arg[voted] % step
        offset_x, offset_y = subpixel_offsets(score, qy, qx)
        half_step = 0.5 * (band.target_scale - 1)
        best[voted, slot] = score[qy, qx]
        x_px[voted, slot] = band.target_scale * (qx + offset_x) + half_step
        y_px[voted, slot] = band.target_scale * (qy + offset_y) + half_step
        radius_px[voted, slot] = image[qy, qx, 1] / image[qy, qx, 0] * band.scale
    return BlockMaxima(best, x_px, y_px, radius_px, band_index)


def _clamped(image: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """``image[rows, cols]`` with indices clamped to the image (edge pixels repeat)."""
    return image[np.clip(rows, 0, image.shape[0] - 1), np.clip(cols, 0, image.shape[1] - 1)]


def subpixel_offsets(score: np.ndarray, rows: np.ndarray, columns: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) sub-pixel offsets, pixels in [-0.5, 0.5], of the peaks of ``score`` (H, W)
    at ``rows``, ``columns`` (N,): the vertex of a parabola through each peak and its two
    neighbours along each axis (the border repeated)."""
    centre = score[rows, columns]
    offset_x = _parabola_offset(_clamped(score, rows, columns - 1), centre,
                                _clamped(score, rows, columns + 1))
    offset_y = _parabola_offset(_clamped(score, rows - 1, columns), centre,
                                _clamped(score, rows + 1, columns))
    return offset_x, offset_y


def _parabola_offset(minus: np.ndarray, centre: np.ndarray, plus: np.ndarray) -> np.ndarray:
    """Sub-pixel peak offset in [-0.5, 0.5] of a 3-point parabola (0 when not concave)."""
    curvature = minus - 2.0 * centre + plus
    with np.errstate(divide='ignore', invalid='ignore'):
        offset = np.where(curvature < 0.0, 0.5 * (minus - plus) / curvature, 0.0)
    return np.clip(offset, -0.5, 0.5).astype(np.float32)


#: A candidate encloses a better one (:func:`select_candidates`' ``enclosing_ring_ratio``)
#: where the better one's centre lies within this fraction of its radius of its centre (a
#: digit's loop sits within about 0.4 of the voting radius of a sign's ring).
ENCLOSED_CENTRE_FRACTION = 0.6


def is_same_sign(candidate: Candidate, better: Candidate, suppression_factor: float,
                 enclosing_ring_ratio: float = 0.0) -> bool:
    """Whether ``candidate`` is the sign of the ``better`` candidate already accepted: its
    centre lies within ``suppression_factor x`` the larger of the two radii, and it is not
    a ring of at least ``enclosing_ring_ratio x`` that one's radius around it (its centre
    within :data:`ENCLOSED_CENTRE_FRACTION` of its radius; 0: no such exception). A large
    sign's digits (the 0 of an 80, the loops of its 8) vote for small circles of their
    own that outscore the ring around them: suppressed by them, the sign's ring was lost
    and the sign read at a loop's radius (two 80s of 56 and 62 px in gtsdb-dev)."""
    distance = math.hypot(candidate.x_px - better.x_px, candidate.y_px - better.y_px)
    if distance >= suppression_factor * max(candidate.radius_px, better.radius_px):
        return False
    return not (enclosing_ring_ratio > 0.0
                and candidate.radius_px >= enclosing_ring_ratio * better.radius_px
                and distance < ENCLOSED_CENTRE_FRACTION * candidate.radius_px)


def select_candidates(maxima: BlockMaxima, max_candidates: int, min_score: float,
                      suppression_factor: float, enclosing_ring_ratio: float
                      ) -> tuple[Candidate, ...]:
    """Top-N block maxima, best first, with non-maximum suppression.

    A block maximum is dropped when it is the sign of an already accepted (better)
    candidate (:func:`is_same_sign`: its centre within ``suppression_factor x`` the larger
    of the two radii, unless it is a ring of at least ``enclosing_ring_ratio x`` the
    better one's radius around it), so two candidates are never the same sign.
    """
    fields = (maxima.score.ravel(), maxima.x_px.ravel(), maxima.y_px.ravel(),
              maxima.radius_px.ravel(), maxima.band.ravel())
    return select_best_first(fields[0], lambda slots: tuple(field[slots] for field in fields),
                             max_candidates, min_score, suppression_factor,
                             enclosing_ring_ratio)


#: ``locate(slots)`` of :func:`select_best_first`: for the flat slots (N,) given, their
#: (score, x_px, y_px, radius_px, band) arrays (N,), in the order given.
Locate = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                      np.ndarray]]


def select_best_first(scores: np.ndarray, locate: Locate, max_candidates: int,
                      min_score: float, suppression_factor: float,
                      enclosing_ring_ratio: float) -> tuple[Candidate, ...]:
    """:func:`select_candidates` over the flat block-maximum ``scores`` (N,), locating
    (``locate``) only the maxima it visits: the best :data:`FIRST_VISITED` first, then
    four times as many each time suppression leaves too few candidates. The CPU path
    finds a maximum's pixel only when it is located (:mod:`.candidates_cpu`)."""
    accepted: list[Candidate] = []
    visited, count = 0, FIRST_VISITED
    while True:
        order = best_first(scores, count)   # its first `visited` are those visited already
        fresh = order[visited:]
        fresh_scores = scores[fresh]
        failing = np.flatnonzero((fresh_scores <= 0.0) | (fresh_scores < min_score))
        usable = fresh[:failing[0]] if failing.size else fresh
        score, xs, ys, radii, bands = locate(usable)
        for index in range(usable.size):
            if len(accepted) >= max_candidates:
                return tuple(accepted)
            candidate = Candidate(float(xs[index]), float(ys[index]), float(radii[index]),
                                  float(score[index]), int(bands[index]))
            if not any(is_same_sign(candidate, other, suppression_factor,
                                    enclosing_ring_ratio) for other in accepted):
                accepted.append(candidate)
        if failing.size or order.size >= scores.size or len(accepted) >= max_candidates:
            return tuple(accepted)
        visited, count = order.size, 4 * count


FIRST_VISITED = 64
"""Block maxima :func:`select_best_first` visits first (more, four times as many each
time, when suppression leaves too few candidates)."""


def best_first(scores: np.ndarray, count: int) -> np.ndarray:
    """Indices of the flat ``scores`` (N,) in the selection's visiting order (best first,
    the first index of equal scores first: a stable sort), at least its first ``count``
    of them (all N where ``count >= N``): the scores at or above the ``count``-th best,
    found by a partition, then sorted. A frame holds 4 bands x 4,800 blocks at 640x480,
    and a full sort of them cost about 1 ms of the detector's 16."""
    if count >= scores.size:
        return np.argsort(-scores, kind='stable')
    count = max(count, 1)
    threshold = np.partition(scores, scores.size - count)[scores.size - count]
    chosen = np.flatnonzero(scores >= threshold)
    return chosen[np.argsort(-scores[chosen], kind='stable')]
