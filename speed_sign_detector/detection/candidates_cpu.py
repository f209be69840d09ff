"""Block maxima of the CPU path, straight from its packed vote sums.

:func:`.candidates.block_maxima` (the numpy twin of the GL reduction) takes each band's
two-channel vote image and finds the best pixel of every block in every band.
:func:`packed_block_maxima` gives the same result, bit for bit, from the CPU path's
packed sums (:mod:`.voting_cpu`) with less work: a band's score is a non-decreasing
function of its packed sum, so it takes each band's block maxima on the sums themselves
(strided maxima, no score image) and scores only those, and it scores pixels (and
unpacks counts) only in the tiles of the maxima with votes. :func:`select_packed_candidates`
goes further for the detector: it locates only the (block, band) maxima the top-N
selection visits.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from speed_sign_detector.detection.candidates import (
    BlockMaxima,
    Candidate,
    select_best_first,
    subpixel_offsets,
)
from speed_sign_detector.detection.voting_cpu import VoteStencils


def packed_block_maxima(packed: Sequence[np.ndarray], stencils: Sequence[VoteStencils],
                        frame_shape: tuple[int, int], block_px: int,
                        normalisers: Sequence[float]) -> BlockMaxima:
    """Every band's best pixel per block, as :func:`.candidates.block_maxima` gives it
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
                             suppression_factor: float, enclosing_ring_ratio: float
                             ) -> tuple[Candidate, ...]:
    """:func:`.candidates.select_candidates` of :func:`packed_block_maxima`, the same
    candidates, locating the best pixel only in the (block, band) maxima the selection
    visits (:func:`.candidates.select_best_first`)."""
    blocks = _BandBlocks(packed, stencils, frame_shape, block_px, normalisers)
    return select_best_first(blocks.best.ravel(), blocks.locate, max_candidates, min_score,
                             suppression_factor, enclosing_ring_ratio)


class _BandBlocks:
    """Every band's block maxima, from the packed sums.

    A band's score is a non-decreasing function of its packed sum (:func:`_scores`: the
    weight field is the high bits, then float32 roundings and a positive factor), so the
    best score of a block is the score of its largest packed sum: the block maxima are
    taken on the sums (one pass, no score image) and only the located maxima's pixels are
    scored (where the first best pixel of a tile needs the scores themselves: pixels of
    equal score may hold different counts). A maximum is a flat index into the
    (rows, cols, bands) slots of :class:`~.candidates.BlockMaxima`.
    """

    def __init__(self, packed: Sequence[np.ndarray], stencils: Sequence[VoteStencils],
                 frame_shape: tuple[int, int], block_px: int,
                 normalisers: Sequence[float]) -> None:
        height, width = frame_shape
        rows, cols = -(-height // block_px), -(-width // block_px)
        self.packed, self.stencils = packed, stencils
        self.normalisers = tuple(np.float32(normaliser) for normaliser in normalisers)
        self.steps: list[int] = []
        self.best = np.full((rows, cols, len(packed)), -np.inf, np.float32)
        for index, (sums, band_stencils, normaliser) in enumerate(
                zip(packed, stencils, self.normalisers, strict=True)):
            step = max(1, block_px // band_stencils.band.target_scale)
            self.steps.append(step)
            # a band's image is never larger than its blocks (H_target = H >> level <=
            # rows x step); the blocks it does not reach stay -inf
            region = _block_max(sums[:rows * step, :cols * step], step)
            self.best[:region.shape[0], :region.shape[1], index] = _scores(
                region, band_stencils, normaliser)
        self.cols = cols

    def maxima(self, slots: np.ndarray) -> BlockMaxima:
        """The frame's :class:`~.candidates.BlockMaxima` with the flat (block, band)
        indices ``slots`` located (those with a positive score; the others empty)."""
        slots = slots[self.best.ravel()[slots] > 0.0]
        shape = self.best.shape
        score = np.full(shape, -1.0, np.float32)
        x_px, y_px, radius_px = (np.zeros(shape, np.float32) for _ in range(3))
        band_index = np.zeros(shape, np.int32)
        band_index[...] = [stencils.band.index for stencils in self.stencils]
        where = np.unravel_index(slots, shape)
        score[where], x_px[where], y_px[where], radius_px[where], band_index[where] = (
            self.locate(slots))
        return BlockMaxima(score, x_px, y_px, radius_px, band_index)

    def locate(self, slots: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                 np.ndarray, np.ndarray]:
        """(score, x_px, y_px, radius_px, band) arrays (N,) of the flat (block, band)
        indices ``slots`` (N,), in their order: each one's best pixel in its block (the
        first of equal scores, row-major, as the reference), sub-pixel centre and
        radius. Every slot listed must have a positive score."""
        score = np.empty(slots.size, np.float32)
        x_px, y_px, radius_px = (np.empty(slots.size, np.float32) for _ in range(3))
        band_index = np.empty(slots.size, np.int32)
        blocks, slot_bands = np.divmod(slots, len(self.packed))
        for index, (sums, stencils, normaliser, step) in enumerate(
                zip(self.packed, self.stencils, self.normalisers, self.steps)):
            won = slot_bands == index
            if not np.any(won):
                continue
            band = stencils.band
            block_rows, block_cols = np.divmod(blocks[won], self.cols)
            within = np.arange(step)
            tile_rows = (block_rows[:, None] * step + within)[:, :, None]   # (N, step, 1)
            tile_cols = (block_cols[:, None] * step + within)[:, None, :]   # (N, 1, step)
            inside = (tile_rows < sums.shape[0]) & (tile_cols < sums.shape[1])
            tiles = np.where(inside, _scores(
                sums[np.minimum(tile_rows, sums.shape[0] - 1),
                     np.minimum(tile_cols, sums.shape[1] - 1)], stencils, normaliser),
                np.float32(-np.inf))
            arg = tiles.reshape(-1, step * step).argmax(axis=1)  # row-major, as the reference
            qy = block_rows * step + arg // step
            qx = block_cols * step + arg % step
            centre, offset_x, offset_y = _peak(sums, stencils, normaliser, qy, qx)
            half_step = 0.5 * (band.target_scale - 1)
            score[won] = centre
            x_px[won] = band.target_scale * (qx + offset_x) + half_step
            y_px[won] = band.target_scale * (qy + offset_y) + half_step
            radius_px[won] = _radius_ratio(sums[qy, qx], stencils) * band.scale
            band_index[won] = band.index
        return score, x_px, y_px, radius_px, band_index


def _block_max(image: np.ndarray, step: int) -> np.ndarray:
    """(ceil(H / step), ceil(W / step)) maxima of the step x step blocks of an (H, W)
    image (the last row and column of blocks may be cut short), by strided maxima."""
    for axis in (0, 1):
        if step > 1:
            lines = [slice(None), slice(None)]
            lines[axis] = slice(0, None, step)
            best = image[tuple(lines)].copy()
            for start in range(1, min(step, image.shape[axis])):
                lines[axis] = slice(start, None, step)
                part = image[tuple(lines)]
                target = best[:part.shape[0]] if axis == 0 else best[:, :part.shape[1]]
                np.maximum(target, part, out=target)
            image = best
    return image


def _scores(sums: np.ndarray, stencils: VoteStencils, normaliser: np.float32) -> np.ndarray:
    """float32 scores of packed sums, rounded as the reference rounds them: the float32
    weight sum times the float32 normaliser (a non-decreasing function of the sums)."""
    weight = np.multiply(sums, 1.0 / stencils.count_scale)   # powers of two: exact
    np.floor(weight, out=weight)
    weight *= 1.0 / stencils.weight_one
    score = weight.astype(np.float32)
    score *= normaliser
    return score


_CROSS_DY = np.array([0, 0, 0, -1, 1])
_CROSS_DX = np.array([0, -1, 1, 0, 0])


def _peak(sums: np.ndarray, stencils: VoteStencils, normaliser: np.float32,
          rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Score and sub-pixel offsets ``(x, y)`` of the peaks at ``rows``, ``cols`` (N,) of a
    band's packed sums, as :func:`.candidates.subpixel_offsets` finds them in the score
    image: the scores of each peak's cross of 5 pixels (clamped to the image, as it
    clamps) are laid out as (N x 3, 3) patches, peak ``i`` at ``(3 i + 1, 1)``."""
    cross_rows = np.minimum(np.maximum(rows[:, None] + _CROSS_DY, 0), sums.shape[0] - 1)
    cross_cols = np.minimum(np.maximum(cols[:, None] + _CROSS_DX, 0), sums.shape[1] - 1)
    patches = np.zeros((rows.size, 3, 3), np.float32)
    patches[:, 1 + _CROSS_DY, 1 + _CROSS_DX] = _scores(sums[cross_rows, cross_cols],
                                                        stencils, normaliser)
    centres = np.arange(rows.size) * 3 + 1
    offset_x, offset_y = subpixel_offsets(patches.reshape(-1, 3), centres,
                                          np.ones_like(centres))
    return patches[:, 1, 1], offset_x, offset_y


def _radius_ratio(sums: np.ndarray, stencils: VoteStencils) -> np.ndarray:
    """``count / weight`` of packed sums, rounded as the reference's float32 vote
    images round them."""
    weight = np.floor(sums * (1.0 / stencils.count_scale))
    count = sums - weight * stencils.count_scale
    return ((count / stencils.count_one).astype(np.float32)
            / (weight / stencils.weight_one).astype(np.float32))
