"""Radial-symmetry voting on the CPU, vectorised: precomputed vote stencils.

The numpy reference (:mod:`speed_sign_detector.detection.voting_numpy`) rasterizes every
edge pixel's vote trapezoid anew: a few dozen array passes per vote. Here each trapezoid
is looked up instead. An edge pixel's votes depend only on

- its gradient direction, quantised to :data:`DIRECTION_BINS` angles (0.35 degrees
  apart: at 12 level pixels, the largest radius of a default band, a trapezoid turns by
  at most 0.04 px), and
- where it falls between vote-image pixels (its *phase*): one phase when the band votes
  at its edge level, ``n x n`` when its vote image is ``n`` times coarser (an edge pixel
  ``x`` maps to ``(x + 0.5) / n - 0.5``),

so each band keeps one *stencil* per (phase, direction): the vote-image offsets the
reference's rasterization rule (:func:`voting_numpy._rasterize`) gives, and their
``(profile / u, profile)``, both rounded to fixed point and packed into one float64
integer (count in the low bits), whose sums are exact whatever the order. Voting is then
a table look-up per edge, one addition of its position and one ``np.bincount`` per chunk
of edges. Chunks of :data:`EDGES_PER_CHUNK` row-ordered edges keep the temporaries and the
rows they touch in the CPU caches (4x faster than one pass over a whole frame).

The vote images equal the reference's up to the direction quantisation and the
fixed-point units (:data:`FIXED_POINT_ONE` per 1.0). The quantisation moves a vote
pixel whose centre lies within a few hundredths of a pixel of a trapezoid's edge to the
other side, and changes a vote's tent weight by up to 0.007 (the weight changes by about
``1 / tan(pi/8)`` per radian of direction): on real scenes the images correlate with the
reference's above 0.9997 and their totals agree to 0.2 %, with the same candidates;
``test_voting_cpu.py`` checks them against the reference.

A band that votes toward both sides of its edges keeps both directions' stencils side
by side in one table row, so that each chunk costs one look-up and one ``np.bincount``.
On hosts of more than 2 cores the bands are split over two threads
(:data:`VOTING_THREADS`).
"""
from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import cv2
import numpy as np

from speed_sign_detector.config import DetectorConfig
from speed_sign_detector.detection.gradients import EdgeList
from speed_sign_detector.detection.vote_fixed_point import votes_per_pixel_bound
from speed_sign_detector.detection.voting_numpy import (
    CHANNELS,
    SPREAD,
    RadiusBand,
    _rasterize,
    level_size,
    plan_bands,
    vote_signs,
)

DIRECTION_BINS = 1024
"""Gradient directions a stencil is kept for (a power of two; 2 pi / 1024 = 0.35 deg)."""
EDGES_PER_CHUNK = 4096
"""Edge pixels voted per ``np.bincount`` (their stencils' temporaries stay in the cache)."""
VOTING_THREADS = 2 if (os.cpu_count() or 1) > 2 else 1
"""Threads that vote (bands split between them; numpy's take and bincount release the
GIL). One on a host of 2 cores or fewer: there the pipeline recognizes the previous frame
on the other core, and a voting helper thread took its time (on the 2-core host, eval
bag with 2 voting threads against 1, interleaved: detection no faster (43-75 ms either
way), the classifier 2-48 % slower, 4-26 % fewer frames per second)."""
FIXED_POINT_ONE = 1 << 16
"""Integer units per 1.0 of a vote's weight and count (finer when the bound allows)."""
_MANTISSA_BITS = 52  # float64 holds every integer below 2^53 exactly


@dataclass(frozen=True)
class VoteStencils:
    """Every vote stencil of one radius band.

    ``K = phases^2 x DIRECTION_BINS`` stencils, row ``(phase_y * phases + phase_x) *
    DIRECTION_BINS + direction_bin``, each padded to ``S`` entries (padding votes 0 at
    offset (0, 0)).

    Attributes:
        band: the radius band.
        phases: edge-level pixels per vote-image pixel (1, 2, 4, ...).
        phase_floor: (phases,) int64: floor of the vote-image coordinate of edge-level
            coordinate ``p`` (``0 <= p < phases``); edge coordinate ``q * phases + p`` maps
            to ``q + phase_floor[p]`` plus the stencil's offsets.
        reach: largest offset of any stencil entry on either axis, vote-image pixels.
        offset_x, offset_y: (K, S) int64 vote-image pixel offsets.
        packed_votes: (K, S) float64 integers ``round(weight x weight_one) x count_scale +
            round(count x count_one)``.
        weight_one, count_one: integer units per 1.0 of ``sum profile / u`` and
            ``sum profile``.
        count_scale: ``2^count_bits``; the count sum is the packed sum modulo it.
    """

    band: RadiusBand
    phases: int
    phase_floor: np.ndarray
    reach: int
    offset_x: np.ndarray
    offset_y: np.ndarray
    packed_votes: np.ndarray
    weight_one: float
    count_one: float
    count_scale: float

    def unpack(self, sums: np.ndarray) -> np.ndarray:
        """Packed vote sums (H, W) float64 -> (H, W, CHANNELS) float32 ``(sum w, count)``."""
        weight = np.floor(sums / self.count_scale)
        count = sums - weight * self.count_scale
        votes = np.empty(sums.shape + (CHANNELS,), np.float32)
        votes[..., 0] = weight / self.weight_one
        votes[..., 1] = count / self.count_one
        return votes


def fixed_point_units(band: RadiusBand) -> tuple[float, float, float]:
    """``(weight_one, count_one, count_scale)`` of a band's packed votes.

    The finest power-of-two unit (at most :data:`FIXED_POINT_ONE`, at least 1/64 of it)
    for which both fields' largest per-pixel sums (:func:`votes_per_pixel_bound` votes,
    each at most 1 in count and ``2 / r0`` in weight, plus half a unit of rounding) fit
    in float64's 52 mantissa bits together.
    """
    r0, r1 = band.level_radii
    votes = votes_per_pixel_bound(r0, r1)
    one = float(FIXED_POINT_ONE)
    while True:
        count_bits = math.ceil(math.log2(votes * (one + 0.5) + 1.0))
        weight_bits = math.ceil(math.log2(votes * (one * 2.0 / r0 + 0.5) + 1.0))
        if count_bits + weight_bits <= _MANTISSA_BITS or one <= FIXED_POINT_ONE / 64:
            return one, one, float(1 << count_bits)
        one /= 2.0


def build_stencils(band: RadiusBand, tent: bool) -> VoteStencils:
    """The vote stencils of one band, rasterized by the reference's rule.

    All ``K`` stencils are drawn in one call of :func:`voting_numpy._rasterize`, each in
    a cell of its own of a large canvas, then read out of the cells.
    """
    r0, r1 = band.level_radii
    shrink = band.shrink
    phases = max(1, round(1.0 / shrink))
    coordinates = [(p + 0.5) * shrink - 0.5 for p in range(phases)]
    phase_floor = np.array([math.floor(c) for c in coordinates], np.int64)
    fractions = np.array(coordinates) - phase_floor
    reach = math.ceil(r1 * shrink * math.hypot(1.0, SPREAD)) + 2
    cell = 2 * reach + 1
    count = phases * phases * DIRECTION_BINS
    cells_per_row = math.ceil(math.sqrt(count))
    cell_rows = -(-count // cells_per_row)
    width, height = cells_per_row * cell, cell_rows * cell
    index = np.arange(count)
    direction_bin = index % DIRECTION_BINS
    phase = index // DIRECTION_BINS
    angle = direction_bin * (2.0 * math.pi / DIRECTION_BINS)
    centre_x = (index % cells_per_row) * cell + reach + fractions[phase % phases]
    centre_y = (index // cells_per_row) * cell + reach + fractions[phase // phases]
    canvas = np.zeros(height * width * CHANNELS)
    _rasterize(canvas, centre_x.astype(np.float64), centre_y.astype(np.float64),
               np.cos(angle), np.sin(angle), r0, r1, shrink, width, height, tent)
    cells = canvas.reshape(cell_rows, cell, cells_per_row, cell, CHANNELS)
    cells = cells.transpose(0, 2, 1, 3, 4).reshape(-1, cell * cell, CHANNELS)[:count]
    voted = cells[..., 1] > 0.0
    entries = int(voted.sum(axis=1).max())
    order = np.argsort(~voted, axis=1, kind='stable')[:, :entries]
    kept = np.take_along_axis(voted, order, axis=1)
    weight = np.where(kept, np.take_along_axis(cells[..., 0], order, axis=1), 0.0)
    profile = np.where(kept, np.take_along_axis(cells[..., 1], order, axis=1), 0.0)
    offset_y = np.where(kept, order // cell - reach, 0).astype(np.int64)
    offset_x = np.where(kept, order % cell - reach, 0).astype(np.int64)
    weight_one, count_one, count_scale = fixed_point_units(band)
    packed = (np.rint(weight * weight_one) * count_scale + np.rint(profile * count_one))
    return VoteStencils(band, phases, phase_floor, reach, offset_x, offset_y, packed,
                        weight_one, count_one, count_scale)


class CPUVoter:
    """The vote images of a config's bands from edge lists, by stencil look-up.

    Args:
        config: detector settings (bands, polarity, vote profile).

    Building the stencils takes about 0.1-0.3 s per config; flat offsets are cached per
    vote-image width. With ``threads`` 2 the bands are split into two groups of about
    equal work, one voted on a helper thread; :meth:`close` ends it.
    """

    def __init__(self, config: DetectorConfig, threads: int = VOTING_THREADS) -> None:
        self.config = config
        self.bands = plan_bands(config)
        tent = config.vote_profile == 'tent'
        self.stencils = tuple(build_stencils(band, tent) for band in self.bands)
        # per band, the stencils of all its vote directions side by side (one look-up and
        # one bincount per chunk of edges whether it votes toward one side or both)
        self._tables = tuple(_directions_table(stencils, vote_signs(config, band))
                             for band, stencils in zip(self.bands, self.stencils))
        self._flat_offsets: dict[tuple[int, int], np.ndarray] = {}
        self._helper = (ThreadPoolExecutor(1, thread_name_prefix='cpu-voting')
                        if threads > 1 and len(self.bands) > 1 else None)
        self._helper_pid = os.getpid()   # a forked child has no helper thread

    def close(self) -> None:
        """End the helper thread (idempotent); voting goes on in the calling thread."""
        if self._helper is not None:
            self._helper.shutdown()
            self._helper = None

    def vote_images(self, edges: list[EdgeList], frame_size: tuple[int, int]
                    ) -> list[np.ndarray]:
        """One (H_target, W_target, CHANNELS) float32 vote image per band, equal to
        :func:`voting_numpy.vote_band`'s up to the direction quantisation.

        ``edges[level]`` are the edge pixels of pyramid level ``level`` (as
        :func:`voting_numpy.compute_edges` gives them); ``frame_size`` is the
        ``(width, height)`` of level 0.
        """
        return [stencils.unpack(sums) for stencils, sums
                in zip(self.stencils, self.packed_votes(edges, frame_size))]

    def packed_votes(self, edges: list[EdgeList], frame_size: tuple[int, int]
                     ) -> list[np.ndarray]:
        """One (H_target, W_target) float64 image of packed vote sums per band (see
        :meth:`VoteStencils.unpack`); arguments as :meth:`vote_images`."""
        levels = {band.level for band in self.bands}
        bins = {level: direction_bins(level_edges) for level, level_edges in enumerate(edges)
                if level in levels}

        def vote(indices: list[int]) -> list[np.ndarray]:
            return [self.packed_band(edges[self.bands[index].level], index, frame_size,
                                     bins[self.bands[index].level]) for index in indices]

        if self._helper is None or os.getpid() != self._helper_pid:
            return vote(list(range(len(self.bands))))
        mine, helpers = self._split_bands(edges)
        helped = self._helper.submit(vote, helpers)
        packed = dict(zip(mine, vote(mine)))
        packed.update(zip(helpers, helped.result()))
        return [packed[index] for index in range(len(self.bands))]

    def _split_bands(self, edges: list[EdgeList]) -> tuple[list[int], list[int]]:
        """Band indices in two groups of about equal voting work (edges x stencil entries
        x vote directions), the larger first."""
        work = [edges[band.level].count * table[2].shape[1]
                for band, table in zip(self.bands, self._tables)]
        groups: tuple[list[int], list[int]] = ([], [])
        loads = [0, 0]
        for index in sorted(range(len(work)), key=lambda item: -work[item]):
            lighter = 0 if loads[0] <= loads[1] else 1
            groups[lighter].append(index)
            loads[lighter] += work[index]
        return groups

    def packed_band(self, edges: EdgeList, band_index: int, frame_size: tuple[int, int],
                    bins: np.ndarray) -> np.ndarray:
        """Packed vote sums of band ``band_index``: (H_target, W_target) float64 (a view
        into a padded image); ``bins`` are the edges' :func:`direction_bins`."""
        stencils = self.stencils[band_index]
        band = stencils.band
        width, height = level_size(frame_size[0], frame_size[1], band.target_level)
        margin = stencils.reach + 1  # the phase floor is up to one pixel before the edge
        padded_width, padded_height = width + 2 * margin, height + 2 * margin
        sums = np.zeros(padded_width * padded_height)
        if edges.count:
            offsets = self._offsets(band_index, padded_width)
            base, keys = self._edge_keys(edges, bins, stencils, padded_width, margin)
            _accumulate(sums, base, keys, offsets, self._tables[band_index][2],
                        stencils.reach * (padded_width + 1))
        return sums.reshape(padded_height, padded_width)[margin:margin + height,
                                                         margin:margin + width]

    def _offsets(self, band_index: int, padded_width: int) -> np.ndarray:
        """(K, S) int64 flat offsets of a band's stencils in a padded vote image."""
        key = (band_index, padded_width)
        if key not in self._flat_offsets:
            offset_x, offset_y, _ = self._tables[band_index]
            self._flat_offsets[key] = offset_y * padded_width + offset_x
        return self._flat_offsets[key]

    @staticmethod
    def _edge_keys(edges: EdgeList, bins: np.ndarray, stencils: VoteStencils,
                   padded_width: int, margin: int) -> tuple[np.ndarray, np.ndarray]:
        """Each edge's flat base pixel in the padded vote image and its stencil row
        (for the vote toward its gradient; the opposite direction is ``key ^ BINS/2``)."""
        phases = stencils.phases
        x = edges.x_px.astype(np.int64)
        y = edges.y_px.astype(np.int64)
        phase_x, phase_y = x % phases, y % phases
        column = x // phases + stencils.phase_floor[phase_x] + margin
        row = y // phases + stencils.phase_floor[phase_y] + margin
        keys = (phase_y * phases + phase_x) * DIRECTION_BINS + bins
        return row * padded_width + column, keys


def direction_bins(edges: EdgeList) -> np.ndarray:
    """(E,) int64: each edge's gradient direction as the nearest of the
    :data:`DIRECTION_BINS` stencil angles (``cv2.phase``: within 2e-4 rad of ``atan2``,
    a 15th of a bin, at a 40th of its time)."""
    if not edges.count:
        return np.zeros(0, np.int64)
    angle = cv2.phase(edges.gx, edges.gy).ravel()   # [0, 2 pi)
    direction_bin = np.rint(angle * np.float32(DIRECTION_BINS / (2.0 * math.pi)))
    return direction_bin.astype(np.int64) & (DIRECTION_BINS - 1)


def _directions_table(stencils: VoteStencils, signs: tuple[float, ...]
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(offset_x, offset_y, packed_votes)``, each (K, S x len(signs)): row ``key`` holds
    the stencil of an edge of that key voting along its gradient (sign +1) and/or against
    it (-1: the stencil of the opposite direction, ``key ^ DIRECTION_BINS / 2``)."""
    rows = np.arange(stencils.packed_votes.shape[0])
    chosen = [rows if sign > 0 else rows ^ (DIRECTION_BINS // 2) for sign in signs]
    return tuple(np.concatenate([array[choice] for choice in chosen], axis=1)
                 for array in (stencils.offset_x, stencils.offset_y, stencils.packed_votes))


def _accumulate(sums: np.ndarray, base: np.ndarray, keys: np.ndarray,
                offsets: np.ndarray, packed_votes: np.ndarray, reach_flat: int) -> None:
    """Add the stencils ``keys`` at flat pixels ``base`` (row-ordered) into ``sums``.

    ``reach_flat`` bounds how far before its base pixel a stencil reaches (flat index).
    """
    for start in range(0, base.shape[0], EDGES_PER_CHUNK):
        chunk_base = base[start:start + EDGES_PER_CHUNK]
        chunk_keys = keys[start:start + EDGES_PER_CHUNK]
        low = int(chunk_base.min()) - reach_flat
        pixels = np.take(offsets, chunk_keys, axis=0)
        pixels += (chunk_base - low)[:, None]
        votes = np.take(packed_votes, chunk_keys, axis=0)
        part = np.bincount(pixels.ravel(), votes.ravel())
        sums[low:low + part.shape[0]] += part
