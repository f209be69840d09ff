"""Radial-symmetry voting on the GPU with moderngl (IVS 2011, section IV).

The same maths as :mod:`speed_sign_detector.detection.voting_numpy`, kept on the GPU:

1. the frame is uploaded once as an R8UI texture; one compute pass maps it through the
   contrast table (linear or log) into level 0 of a float pyramid and writes levels 1
   and 2 (2x2 box averages) in the same pass; further levels, if any, get one pass each;
2. per pyramid level, two compute passes find the edge pixels: the first takes the 3x3
   Sobel gradient, applies the threshold and the non-maximum suppression, writes each
   edge pixel's unit gradient direction into an RG32F image ((0, 0) elsewhere) and
   appends the pixel to a list; the second, an indirect dispatch over that list only,
   applies the neighbour-support test on the directions and appends the survivors to
   the edge list (SSBO) with ``atomicAdd`` on the vertex count of that level's indirect
   draw command (and on the group count of its indirect dispatch), so the CPU never
   sees the edges. The levels are independent: all first passes run, then all second
   passes;
3. the votes, one draw or dispatch per group of radius bands (two bands sharing edge
   and vote levels share it; a vote goes to a band by its distance), in one of two ways
   (``DetectorConfig.vote_method``):

   - ``raster``, the paper's: an indirect draw whose vertex shader reads edge
     ``gl_VertexID / 3`` and emits its vote triangle (apex at the edge pixel, far side at
     the group's largest radius, half-width ``r tan(pi/8)``); the fragment shader drops
     votes nearer than the smallest radius (so each band gets the trapezoid of the paper)
     and adds ``(profile / u, profile)`` with additive blending into an RGBA32F target
     (RG for the first band, BA for the second; RG32F for a lone band);
   - ``scatter``: an indirect compute dispatch, one invocation per edge, walks the
     pixels whose centres lie inside the edge's trapezoid (the numpy reference's scanline
     rule) and adds the same two values in fixed point with ``imageAtomicAdd``, both
     packed into one R32UI integer per pixel where the group's radii bound the sums
     (one atomic per vote; :mod:`speed_sign_detector.detection.vote_fixed_point`), else
     in two. Integer sums do not depend on the order of the edge list, so the votes are
     bit-reproducible. On a software renderer (Mesa llvmpipe) it is about twice as fast
     as the raster path: llvmpipe sets up every triangle on one CPU thread (about 0.7 us
     each), while compute work is spread over all cores;

   bands that vote toward both sides draw (or dispatch) twice;
4. one compute dispatch scores every vote pixel and keeps, per 8x8 full-resolution
   block, the best pixel over all bands (with a sub-pixel parabola fit); only that block
   list (``blocks x 32`` bytes) is read back for the top-N selection.

The calls that wait for the driver (dispatches, barriers, finish) are made through
ctypes so that they release the GIL
(:class:`~speed_sign_detector.detection.gl_unlocked_calls.UnlockedGLCalls`): on llvmpipe
the work runs on CPU threads, and other Python threads (the recognition of the previous
frame, a node's executor) keep running meanwhile.

One moderngl context per :class:`GLVoter`, created in its constructor and used on that
thread only; :meth:`GLVoter.close` releases it. Per-size resources are rebuilt when the
frame size changes.
"""
from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from speed_sign_detector.config import DetectorConfig
from speed_sign_detector.detection.candidates import BlockMaxima, score_normaliser
from speed_sign_detector.detection.gl_unlocked_calls import UnlockedGLCalls
from speed_sign_detector.detection.gradients import SUPPORT_ANGLE_DEG, gray_lookup
from speed_sign_detector.detection.vote_fixed_point import VoteFixedPoint, vote_fixed_point
from speed_sign_detector.detection.voting_numpy import (
    CHANNELS,
    SPREAD,
    RadiusBand,
    level_size,
    plan_bands,
    pyramid_levels,
    vote_signs,
)
from speed_sign_detector.detection.voting_shaders import (
    DOWNSAMPLE_SOURCE,
    EDGES_SOURCE,
    PYRAMID_SOURCE,
    REDUCE_SOURCE,
    RIDGE_SOURCE,
    SCATTER_SOURCE,
    VERTICES_PER_EDGE,
    VOTE_FRAGMENT_SOURCE,
    VOTE_VERTEX_SOURCE,
    VOTES_AT_RASTER,
    VOTES_AT_SCATTER,
    with_constants,
)
from speed_sign_detector.errors import DetectorError

if TYPE_CHECKING:
    import moderngl

_GROUP = 8
_FUSED_LEVELS = 3  # pyramid levels the fused upload pass writes
VOTE_METHODS = ('raster', 'scatter')
SOFTWARE_RENDERERS = ('llvmpipe', 'softpipe', 'swrast', 'swiftshader', 'lavapipe', 'software')
"""GL_RENDERER substrings of renderers that run on the CPU (the benchmarks label them)."""

@dataclass
class _LevelResources:
    """GPU objects of one pyramid level for one frame size."""

    width_px: int
    height_px: int
    image: object
    ridge: object
    edges: object
    command: object
    dispatch: object
    ridges: object


@dataclass
class _DrawGroup:
    """One or two adjacent bands with the same edge and vote levels: one draw/dispatch.

    Raster voting: an RGBA32F target holds ``(sum w, n)`` of the first band in RG and of
    the second in BA (the fragment shader routes a vote by its distance); a group of one
    band has an RG32F target (half the blending work). Scatter voting: one R32UI image,
    ``bands`` vote images wide, in the integer format ``fixed_point``: packed, one
    vote image high, band ``s`` keeping ``sum w`` and ``n`` in one integer at
    ``(x + s W, y)``; else two high, ``n`` at ``(x + s W, y + H)``. ``size`` is one
    band's ``(W, H)``; ``framebuffer`` has the texture attached (it clears it).
    """

    bands: tuple[RadiusBand, ...]
    size: tuple[int, int]
    texture: object
    framebuffer: object
    fixed_point: VoteFixedPoint | None
    """The scatter votes' integer format; None for raster votes (float sums)."""

    def band_votes(self, slot: int) -> tuple[int, int, tuple[int, int], tuple[int, int]]:
        """``(weight channel, count channel, weight offset, count offset)`` of band ``slot``
        in :attr:`texture` (offsets in texels)."""
        if self.fixed_point is not None:
            width, height = self.size
            count_row = 0 if self.fixed_point.packed else height
            return 0, 0, (slot * width, 0), (slot * width, count_row)
        return CHANNELS * slot, CHANNELS * slot + 1, (0, 0), (0, 0)

    def read_band(self, slot: int) -> np.ndarray:
        """Band ``slot``'s vote image, (H, W, CHANNELS) float32."""
        width, height = self.size
        fixed_point = self.fixed_point
        if fixed_point is not None:
            pixels = np.frombuffer(self.texture.read(), np.uint32).reshape(
                -1, len(self.bands) * width)
            band = pixels[:, slot * width:(slot + 1) * width]
            if fixed_point.packed:
                weight, count = band >> fixed_point.count_bits, band & fixed_point.count_mask
            else:
                weight, count = band[:height], band[height:]
            return np.stack([weight / fixed_point.weight_one, count / fixed_point.count_one],
                            axis=-1).astype(np.float32)
        pixels = np.frombuffer(self.texture.read(), np.float32).reshape(
            height, width, self.texture.components)
        return pixels[..., CHANNELS * slot:CHANNELS * (slot + 1)].copy()


def _draw_groups(config: DetectorConfig,
                 bands: tuple[RadiusBand, ...]) -> list[tuple[RadiusBand, ...]]:
    """Pairs of adjacent bands that share edge level, vote level and vote directions."""
    groups: list[tuple[RadiusBand, ...]] = []
    for band in bands:
        last = groups[-1] if groups else ()
        if (len(last) == 1 and last[0].level == band.level
                and last[0].target_level == band.target_level
                and vote_signs(config, last[0]) == vote_signs(config, band)):
            groups[-1] = (last[0], band)
        else:
            groups.append((band,))
    return groups


class GLVoter:
    """The GL voting backend for one :class:`DetectorConfig` (one context, one thread).

    Attributes:
        renderer: the GL_RENDERER string.
        vote_method: ``'raster'`` (triangles, additive blending: the paper's way) or
            ``'scatter'`` (a compute pass adds each edge's trapezoid with integer
            atomics); ``config.vote_method='auto'`` picks scatter, the faster on every
            renderer measured (see :func:`resolve_vote_method`).

    Raises:
        DetectorError: when no OpenGL 4.3 context can be created or shaders do not build.
    """

    def __init__(self, config: DetectorConfig) -> None:
        import moderngl

        self._config = config
        self._bands = plan_bands(config)
        try:
            self._ctx = moderngl.create_standalone_context(backend='egl', require=430)
        except Exception as err:  # moderngl raises plain Exception subclasses
            raise DetectorError(f'cannot create a headless OpenGL 4.3 context (EGL): {err}'
                                ) from err
        try:
            self._calls = UnlockedGLCalls()
        except DetectorError:
            self._ctx.release()
            raise
        try:
            self.renderer = str(self._ctx.info['GL_RENDERER'])
            self.vote_method = resolve_vote_method(config.vote_method)
            scatter = self.vote_method == 'scatter'
            self._pyramid = self._ctx.compute_shader(PYRAMID_SOURCE)
            self._downsample = self._ctx.compute_shader(DOWNSAMPLE_SOURCE)
            self._ridge = self._ctx.compute_shader(with_constants(RIDGE_SOURCE))
            self._extract = self._ctx.compute_shader(with_constants(EDGES_SOURCE))
            band_count = f'#version 430\n#define BAND_COUNT {len(self._bands)}'
            self._reduce = self._ctx.compute_shader(REDUCE_SOURCE.replace(
                '#version 430', band_count, 1).replace(
                'VOTE_SAMPLER', 'usampler2D' if scatter else 'sampler2D').replace(
                'VOTES_AT', VOTES_AT_SCATTER if scatter else VOTES_AT_RASTER).replace(
                'BAND_BLOCKS', ' '.join(f'BAND_BLOCK({band})' for band in range(
                    len(self._bands)))))
            # each draw group with its scatter votes' integer format (None: raster votes),
            # and a scatter shader per format in use, packed or not (compiled apart)
            self._group_formats = [(bands, vote_fixed_point(bands) if scatter else None)
                                   for bands in _draw_groups(config, self._bands)]
            formats = {fixed_point.packed for _, fixed_point in self._group_formats
                       if fixed_point is not None}
            self._scatter = {packed: self._ctx.compute_shader(
                with_constants(SCATTER_SOURCE).replace('PACKED_VOTES', str(int(packed))))
                for packed in formats} or None
            self._vote = None if scatter else self._ctx.program(
                vertex_shader=with_constants(VOTE_VERTEX_SOURCE),
                fragment_shader=VOTE_FRAGMENT_SOURCE)
            self._vote_array = None if scatter else self._ctx.vertex_array(self._vote, [])
        except Exception as err:
            self._ctx.release()
            raise DetectorError(f'GL voting shaders failed to build: {err}') from err
        self._pyramid['lookup'].write(gray_lookup(config.contrast,
                                                  config.log_offset_gray).tobytes())
        self._thread_id = threading.get_ident()
        self._size: tuple[int, int] | None = None
        self._frame = None
        self._levels: list[_LevelResources] = []
        self._groups: list[_DrawGroup] = []
        self._blocks = None
        self._blocks_shape = (0, 0)
        self._released = False
        self.stage_ms: dict[str, float] | None = None
        self._stage_start = 0.0

    def profile_stages(self, enabled: bool) -> None:
        """Record per-stage times in ``stage_ms`` (adds a GPU sync per stage, during which
        other Python threads run)."""
        self.stage_ms = {} if enabled else None

    def _stage(self, name: str | None) -> None:
        if self.stage_ms is None:
            return
        self._calls.finish()  # the GPU sync, without holding the GIL
        now = time.perf_counter()
        if name is not None:
            self.stage_ms[name] = self.stage_ms.get(name, 0.0) + 1e3 * (now - self._stage_start)
        self._stage_start = now

    @property
    def released(self) -> bool:
        """True once :meth:`close` has released the context."""
        return self._released

    def close(self) -> None:
        """Release every GPU object and the context (idempotent)."""
        if self._released:
            return
        with self._ctx:
            self._release_size_resources()
        self._ctx.release()
        self._released = True

    def block_maxima(self, gray: np.ndarray) -> BlockMaxima:
        """Vote on a validated (H, W) uint8 frame; every band's best pixel per block (see
        candidates)."""
        self._check_thread()
        with self._ctx:  # current on this thread (other detectors may have their own)
            self._run_votes(gray)
            self._reduce_blocks()
            self._calls.finish()  # wait here, without the GIL, rather than in the read
            raw = np.frombuffer(self._blocks.read(), dtype=np.float32)
            self._stage('readback')
        rows, cols = self._blocks_shape
        raw = raw.reshape(rows, cols, len(self._bands), 4)
        band = np.broadcast_to(np.arange(len(self._bands), dtype=np.int32), raw.shape[:3])
        return BlockMaxima(score=raw[..., 0].copy(), x_px=raw[..., 1].copy(),
                           y_px=raw[..., 2].copy(), radius_px=raw[..., 3].copy(),
                           band=band.copy())

    def vote_images(self, gray: np.ndarray) -> list[np.ndarray]:
        """Vote images of every band, (H_level, W_level, CHANNELS) float32 each."""
        self._check_thread()
        images = []
        with self._ctx:
            self._run_votes(gray)
            for group in self._groups:
                images.extend(group.read_band(slot) for slot in range(len(group.bands)))
        return images

    def edge_counts(self) -> list[int]:
        """Edge pixels per pyramid level of the last frame (reads 16 bytes per level)."""
        self._check_thread()
        with self._ctx:
            return [int(np.frombuffer(level.command.read(), np.uint32)[0]) // VERTICES_PER_EDGE
                    for level in self._levels]

    # -- internals ---------------------------------------------------------------------

    def _ensure_size(self, width: int, height: int) -> None:
        if self._size == (width, height):
            return
        self._release_size_resources()
        ctx = self._ctx
        self._frame = ctx.texture((width, height), 1, dtype='u1')
        self._levels = []
        level_width, level_height = width, height
        for _ in range(pyramid_levels(self._bands)):
            self._levels.append(_LevelResources(
                level_width, level_height,
                image=ctx.texture((level_width, level_height), 1, dtype='f4'),
                ridge=ctx.texture((level_width, level_height), 2, dtype='f4'),
                edges=ctx.buffer(reserve=16 * level_width * level_height),
                command=ctx.buffer(reserve=16),
                dispatch=ctx.buffer(reserve=12),
                ridges=ctx.buffer(reserve=16 + 8 * level_width * level_height)))
            level_width, level_height = level_width // 2, level_height // 2
        self._groups = []
        for bands, fixed_point in self._group_formats:
            size = level_size(width, height, bands[0].target_level)
            if fixed_point is not None:
                rows = size[1] if fixed_point.packed else CHANNELS * size[1]
                texture = ctx.texture((len(bands) * size[0], rows), 1, dtype='u4')
            else:
                texture = ctx.texture(size, CHANNELS * len(bands), dtype='f4')
            self._groups.append(_DrawGroup(bands, size, texture,
                                           ctx.framebuffer(color_attachments=[texture]),
                                           fixed_point))
        block = self._config.block_size_px
        self._blocks_shape = (-(-height // block), -(-width // block))
        self._blocks = ctx.buffer(reserve=16 * len(self._bands) * self._blocks_shape[0]
                                  * self._blocks_shape[1])
        self._size = (width, height)

    def _release_size_resources(self) -> None:
        objects = [self._frame, self._blocks]
        for level in self._levels:
            objects += [level.image, level.ridge, level.edges, level.command, level.dispatch,
                        level.ridges]
        for group in self._groups:
            objects += [group.framebuffer, group.texture]
        for item in objects:
            if item is not None:
                item.release()
        self._frame, self._blocks = None, None
        self._levels, self._groups = [], []
        self._size = None

    def _check_thread(self) -> None:
        if self._released:
            raise DetectorError('the GL detector has been closed')
        if threading.get_ident() != self._thread_id:
            raise DetectorError('the GL detector must be used on the thread that created it '
                                '(its OpenGL context is current there only)')

    def _run_votes(self, gray: np.ndarray) -> None:
        height, width = gray.shape
        self._stage(None)
        self._ensure_size(width, height)
        self._frame.write(gray.tobytes())
        self._frame.use(0)
        fused = self._levels[:_FUSED_LEVELS]
        # with fewer levels the spare units repeat the last level; 'levels' stops the
        # shader before it writes them
        for unit in range(_FUSED_LEVELS):
            fused[min(unit, len(fused) - 1)].image.bind_to_image(unit, read=False, write=True)
        for unit, name in enumerate(('size0', 'size1', 'size2')):
            level = fused[min(unit, len(fused) - 1)]
            self._pyramid[name] = (level.width_px, level.height_px)
        self._pyramid['levels'] = len(fused)
        self._calls.run(self._pyramid, _groups(-(-width // 4)), _groups(-(-height // 4)))
        self._calls.memory_barrier()
        for finer, coarser in zip(self._levels[_FUSED_LEVELS - 1:], self._levels[_FUSED_LEVELS:]):
            finer.image.bind_to_image(0, read=True, write=False)
            coarser.image.bind_to_image(1, read=False, write=True)
            self._downsample['size'] = (coarser.width_px, coarser.height_px)
            self._calls.run(self._downsample, _groups(coarser.width_px),
                            _groups(coarser.height_px))
            self._calls.memory_barrier()
        self._stage('upload_pyramid')
        self._extract['vertices_per_edge'] = VERTICES_PER_EDGE
        self._extract['min_support'] = self._config.edge_support
        self._extract['support_cosine'] = math.cos(math.radians(SUPPORT_ANGLE_DEG))
        self._ridge['threshold'] = float(self._config.gradient_threshold)
        self._ridge['thin'] = bool(self._config.thin_edges)
        # the levels are independent: every ridge pass, one barrier, every extraction
        for level in self._levels:
            level.image.bind_to_image(0, read=True, write=False)
            level.ridge.bind_to_image(2, read=False, write=True)
            level.ridges.write(_EMPTY_RIDGES)
            level.ridges.bind_to_storage_buffer(4)
            self._ridge['size'] = (level.width_px, level.height_px)
            self._calls.run(self._ridge, _groups(level.width_px), _groups(level.height_px))
            level.command.write(_EMPTY_DRAW)
            level.dispatch.write(_EMPTY_DISPATCH)
        self._calls.memory_barrier()
        for level in self._levels:
            level.ridge.bind_to_image(2, read=True, write=False)
            level.command.bind_to_storage_buffer(0)
            level.edges.bind_to_storage_buffer(1)
            level.dispatch.bind_to_storage_buffer(3)
            level.ridges.bind_to_storage_buffer(4)
            self._calls.run_indirect(self._extract, level.ridges)
        self._calls.memory_barrier()
        self._stage('edges')
        if self._scatter is not None:
            self._scatter_votes()
        else:
            self._draw_votes()
        self._stage('vote')

    def _draw_votes(self) -> None:
        """Raster voting: one indirect triangle draw per group and vote direction."""
        import moderngl

        ctx = self._ctx
        ctx.enable_only(moderngl.BLEND)
        ctx.blend_func = moderngl.ONE, moderngl.ONE
        ctx.blend_equation = moderngl.FUNC_ADD
        self._vote['spread'] = SPREAD
        self._vote['tent'] = self._config.vote_profile == 'tent'
        for group in self._groups:
            first, last = group.bands[0], group.bands[-1]
            level = self._levels[first.level]
            group.framebuffer.use()
            group.framebuffer.clear(0.0, 0.0, 0.0, 0.0)
            self._vote['size'] = tuple(float(extent) for extent in group.size)
            self._vote['shrink'] = first.shrink
            self._vote['min_radius'] = first.level_radii[0]
            self._vote['max_radius'] = last.level_radii[1]
            self._vote['split_radius'] = _split_radius(group.bands)
            level.edges.bind_to_storage_buffer(1)
            for sign in vote_signs(self._config, first):
                self._vote['vote_sign'] = sign
                self._vote_array.render_indirect(level.command, mode=moderngl.TRIANGLES,
                                                 count=1)
        ctx.disable(moderngl.BLEND)

    def _scatter_votes(self) -> None:
        """Scatter voting: one indirect compute dispatch per group and vote direction."""
        for group in self._groups:
            scatter = self._scatter[group.fixed_point.packed]
            scatter['spread'] = SPREAD
            scatter['tent'] = self._config.vote_profile == 'tent'
            first, last = group.bands[0], group.bands[-1]
            level = self._levels[first.level]
            group.framebuffer.clear(0.0, 0.0, 0.0, 0.0)
            group.texture.bind_to_image(0, read=True, write=True)
            scatter['size'] = group.size
            scatter['shrink'] = first.shrink
            scatter['min_radius'] = first.level_radii[0]
            scatter['max_radius'] = last.level_radii[1]
            scatter['split_radius'] = _split_radius(group.bands)
            if group.fixed_point.packed:
                scatter['count_bits'] = group.fixed_point.count_bits
            scatter['weight_one'] = group.fixed_point.weight_one
            scatter['count_one'] = group.fixed_point.count_one
            level.command.bind_to_storage_buffer(0)
            level.edges.bind_to_storage_buffer(1)
            for sign in vote_signs(self._config, first):
                scatter['vote_sign'] = sign
                self._calls.run_indirect(scatter, level.dispatch)
                self._calls.memory_barrier()

    def _reduce_blocks(self) -> None:
        """One dispatch: per 8x8 block, the best vote pixel of every band."""
        rows, cols = self._blocks_shape
        self._blocks.bind_to_storage_buffer(2)
        reduce = self._reduce
        reduce['blocks_size'] = (cols, rows)
        block = self._config.block_size_px
        bands = [(group, slot, band) for group in self._groups
                 for slot, band in enumerate(group.bands)]
        unit_values: dict[str, list] = {name: [] for name in (
            'level_size', 'block_level_px', 'scale', 'target_scale', 'weight_channel',
            'count_channel', 'weight_offset', 'count_offset', 'normaliser', 'band_index',
            'count_bits', 'weight_unit', 'count_unit')}
        for unit, (group, slot, band) in enumerate(bands):
            group.texture.use(unit)
            weight_channel, count_channel, weight_offset, count_offset = group.band_votes(slot)
            unit_values['level_size'].append(group.size)
            unit_values['block_level_px'].append(max(1, block // band.target_scale))
            unit_values['scale'].append(band.scale)
            unit_values['target_scale'].append(band.target_scale)
            unit_values['weight_channel'].append(weight_channel)
            unit_values['count_channel'].append(count_channel)
            unit_values['weight_offset'].append(weight_offset)
            unit_values['count_offset'].append(count_offset)
            unit_values['normaliser'].append(score_normaliser(len(vote_signs(self._config,
                                                                             band))))
            unit_values['band_index'].append(band.index)
            fixed_point = group.fixed_point
            unit_values['count_bits'].append(fixed_point.count_bits if fixed_point else 0)
            unit_values['weight_unit'].append(1.0 / fixed_point.weight_one if fixed_point
                                              else 1.0)
            unit_values['count_unit'].append(1.0 / fixed_point.count_one if fixed_point
                                             else 1.0)
        for name, values in unit_values.items():
            if name not in reduce:  # the raster reduction reads floats: no units
                continue
            uniform = reduce[name]
            padding = [values[0]] * (uniform.array_length - len(values))
            uniform.value = values + padding
        self._calls.run(reduce, _groups(cols), _groups(rows))
        self._calls.memory_barrier()
        self._stage('reduce')


_EMPTY_DRAW = np.array([0, 1, 0, 0], np.uint32).tobytes()
_EMPTY_DISPATCH = np.array([0, 1, 1], np.uint32).tobytes()
_EMPTY_RIDGES = np.array([0, 1, 1, 0], np.uint32).tobytes()  # dispatch (x, y, z), count


def resolve_vote_method(vote_method: str) -> str:
    """``'raster'`` or ``'scatter'`` for a config's ``vote_method``.

    ``'auto'`` is scatter on every renderer measured so far: on llvmpipe, whose triangle
    setup runs on one thread, and on an NVIDIA H100 (2026-11-24, bench/RESULTS.md), where
    in two runs the detector took 2.1-2.6 ms against raster's 5.0-5.2 ms at 640x480 and
    8.2-12.5 against 34.4-39.4 ms at 1920x1080, with the same votes and recall. (It used
    to depend on the renderer; should a renderer be measured to favour raster, the choice
    would take the renderer again.)
    """
    if vote_method in VOTE_METHODS:
        return vote_method
    return 'scatter'


def _split_radius(bands: tuple[RadiusBand, ...]) -> float:
    """Level-pixel distance from which a vote goes to the group's second band."""
    return bands[0].level_radii[1] if len(bands) == 2 else 3.0e38


def _groups(extent: int) -> int:
    return math.ceil(extent / _GROUP)
