"""Block maxima of the CPU path, straight from its packed vote sums.

:func:`.candidates.block_maxima` (the numpy twin of the GL reduction) takes each band's
two-channel vote image, finds the best pixel of every block in every band and keeps the
best band per block. :func:`packed_block_maxima` gives the same result, bit for bit,
from the CPU path's packed sums (:mod:`.voting_cpu`) with less work: it unpacks only
the weight channel (the score) of every pixel and the count at the chosen pixels; it
takes each band's block maxima with two reductions (no tile copies), chooses the winning
band per block first, and looks for the best pixel's place only in the blocks a band
wins. :func:`select_packed_candidates` goes further for the detector: it locates only
the blocks the top-N selection visits.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from speed_sign_detector.detection.candidates import (
    BlockMaxima,
    Candidate,
    select_candidates,
    subpixel_offsets,
)
from speed_sign_detector.detection.voting_cpu import VoteStencils


def packed_block_maxima(packed: Sequence[np.ndarray], stencils: Sequence[VoteStencils],
                        frame_shape: tuple[int, int], block_px: int,
                        normalisers: Sequence[float]) -> BlockMaxima:
    """Per-block best pixel over all bands, as :func:`.candidates.block_maxima` gives it
    for the unpacked vote images.

    Args:
        packed: per band, (H_target, W_target) float64 packed vote sums.
        stencils: per band, its stencils (the fixed-point format and the band).
        frame_shape: ``(H, W)`` of the frame voted on, full-resolution pixels.
        block_px: block size, full-resolution pixels.
        normalisers: per band, the factor from its weight sum to its score.
    """
    blocks = _BandBlocks(packed, stencils, frame_shape, block_px, normalisers)
    return blocks.maxima(np.flatnonzero(blocks.best > 0.0))


def select_packed_candidates(packed: Sequence[np.ndarray],
                             stencils: Sequence[VoteStencils], frame_shape: tuple[int, int],
                             block_px: int, normalisers: Sequence[float],
                             max_candidates: int, min_score: float,
                             suppression_factor: float) -> tuple[Candidate, ...]:
    """:func:`.candidates.select_candidates` of :func:`packed_block_maxima`, the same
    candidates, locating the best pixel only in the blocks the selection visits (the best
    :data:`FIRST_BLOCKS`, more when suppression leaves too few)."""
    blocks = _BandBlocks(packed, stencils, frame_shape, block_px, normalisers)
    scores = blocks.best.ravel()
    order = np.argsort(-scores, kind='stable')   # the reference's visiting order
    visited = FIRST_BLOCKS
    while True:
        maxima = blocks.maxima(order[:visited], shape=(1, min(visited, order.size)))
        candidates = select_candidates(maxima, max_candidates, min_score,
                                       suppression_factor)
        if (len(candidates) >= max_candidates or visited >= order.size
                or scores[order[visited]] <= 0.0 or scores[order[visited]] < min_score):
            return candidates
        visited *= 4


FIRST_BLOCKS = 64
"""Blocks located first by :func:`select_packed_candidates`, best first."""


class _BandBlocks:
    """Every band's score image and block maxima, and the winning band per block."""

    def __init__(self, packed: Sequence[np.ndarray], stencils: Sequence[VoteStencils],
                 frame_shape: tuple[int, int], block_px: int,
                 normalisers: Sequence[float]) -> None:
        height, width = frame_shape
        rows, cols = -(-height // block_px), -(-width // block_px)
        self.packed, self.stencils = packed, stencils
        self.scores: list[np.ndarray] = []
        self.tiles: list[np.ndarray] = []
        band_best = np.full((len(packed), rows, cols), -np.inf, np.float32)
        for index, (sums, band_stencils, normaliser) in enumerate(
                zip(packed, stencils, normalisers, strict=True)):
            weight = np.multiply(sums, 1.0 / band_stencils.count_scale)
            np.floor(weight, out=weight)
            weight *= 1.0 / band_stencils.weight_one   # a power of two: exact
            step = max(1, block_px // band_stencils.band.target_scale)
            # the score image is the top left of the padded one (a band's image is never
            # larger than its blocks: H_target = H >> level <= rows x step)
            padded = np.empty((rows * step, cols * step), np.float32)
            score = padded[:sums.shape[0], :sums.shape[1]]
            # as the reference: float32 weight sum, times the float32 normaliser
            np.copyto(score, weight, casting='same_kind')
            score *= np.float32(normaliser)
            padded[sums.shape[0]:] = -np.inf
            padded[:sums.shape[0], sums.shape[1]:] = -np.inf
            # rows of each block first (contiguous rows), then the columns
            band_best[index] = padded.reshape(rows, step, cols * step).max(axis=1).reshape(
                rows, cols, step).max(axis=2)
            self.scores.append(score)
            self.tiles.append(padded.reshape(rows, step, cols, step))
        self.winner = np.argmax(band_best, axis=0)   # the first band on ties, as the reference
        self.best = np.take_along_axis(band_best, self.winner[None], axis=0)[0]
        self.cols = cols

    def maxima(self, blocks: np.ndarray, shape: tuple[int, int] | None = None
               ) -> BlockMaxima:
        """The block maxima of the flat block indices ``blocks`` (located), in an array
        of ``shape`` (default: the frame's blocks, those not listed empty) or, with a
        ``shape``, in the order listed."""
        blocks = blocks[self.best.ravel()[blocks] > 0.0]
        if shape is None:
            shape, slots = self.best.shape, blocks
        else:
            slots = np.arange(blocks.size)
        score = np.full(shape, -1.0, np.float32)
        x_px, y_px, radius_px = (np.zeros(shape, np.float32) for _ in range(3))
        band_index = np.zeros(shape, np.int32)
        winners = self.winner.ravel()[blocks]
        for index, (sums, stencils, score_image, tiles) in enumerate(
                zip(self.packed, self.stencils, self.scores, self.tiles)):
            won = winners == index
            if not np.any(won):
                continue
            band = stencils.band
            step = tiles.shape[1]
            block_rows, block_cols = np.divmod(blocks[won], self.cols)
            chosen = tiles[block_rows, :, block_cols, :].reshape(-1, step * step)
            arg = chosen.argmax(axis=1)             # row-major in the tile, as the reference
            qy = block_rows * step + arg // step
            qx = block_cols * step + arg % step
            centre = score_image[qy, qx]
            offset_x, offset_y = subpixel_offsets(score_image, qy, qx)
            half_step = 0.5 * (band.target_scale - 1)
            where = np.unravel_index(slots[won], shape)
            score[where] = centre
            x_px[where] = band.target_scale * (qx + offset_x) + half_step
            y_px[where] = band.target_scale * (qy + offset_y) + half_step
            radius_px[where] = _radius_ratio(sums[qy, qx], stencils) * band.scale
            band_index[where] = band.index
        return BlockMaxima(score, x_px, y_px, radius_px, band_index)


def _radius_ratio(sums: np.ndarray, stencils: VoteStencils) -> np.ndarray:
    """``count / weight`` of packed sums, rounded as the reference's float32 vote
    images round them."""
    weight = np.floor(sums * (1.0 / stencils.count_scale))
    count = sums - weight * stencils.count_scale
    return ((count / stencils.count_one).astype(np.float32)
            / (weight / stencils.weight_one).astype(np.float32))
