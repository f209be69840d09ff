"""Radial-symmetry voting on the GPU with moderngl (IVS 2011, section IV).

The same maths as :mod:`speed_sign_detector.detection.voting_numpy`, kept on the GPU:

1. the frame is uploaded once as an R8UI texture; one compute pass maps it through the
   contrast table (linear or log) into level 0 of a float pyramid and writes levels 1
   and 2 (2x2 box averages) in the same pass; further levels, if any, get one pass each;
2. per pyramid level, two compute passes mark edge pixels (3x3 Sobel gradient,
   threshold, non-maximum suppression into an R32F mask; then neighbour support) and
   append them to an edge list (SSBO) with ``atomicAdd`` on the vertex count of that
   level's indirect draw command, so the CPU never sees the edges. Both passes
   recompute the Sobel gradient from the level instead of storing an RGBA32F gradient
   image (on llvmpipe the image store costs more than the recomputation);
3. one indirect draw per group of radius bands (two bands sharing edge and vote levels
   share an RGBA32F target: RG for the first, BA for the second; a lone band has an
   RG32F target): the vertex shader reads
   edge ``gl_VertexID / 3`` and emits its vote triangle (apex at the edge pixel, far side
   at the band group's largest radius, half-width ``r tan(pi/8)``); the fragment shader
   drops votes nearer than the smallest radius (so each band gets the trapezoid of the
   paper) and adds ``(profile / u, profile)`` into the band's channels with additive
   blending; bands that vote toward both sides draw twice;
4. a compute shader scores every vote pixel and keeps, per 8x8 full-resolution block,
   the best pixel over all bands (with a sub-pixel parabola fit); only that block list
   (``blocks x 32`` bytes) is read back for the top-N selection.

One moderngl context per :class:`GLVoter`, created in its constructor and used on that
thread only; :meth:`GLVoter.close` releases it. Per-size resources are rebuilt when the
frame size changes.
"""
from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass

import numpy as np

from speed_sign_detector.config import DetectorConfig
from speed_sign_detector.detection.candidates import BlockMaxima, score_normaliser
from speed_sign_detector.detection.gradients import SUPPORT_ANGLE_DEG, gray_lookup
from speed_sign_detector.detection.voting_numpy import (
    CHANNELS,
    SPREAD,
    RadiusBand,
    level_size,
    plan_bands,
    pyramid_levels,
    vote_signs,
)
from speed_sign_detector.errors import DetectorError

_GROUP = 8
_VERTICES_PER_EDGE = 3
_FUSED_LEVELS = 3  # pyramid levels the fused upload pass writes

_PYRAMID_SRC = """
#version 430
layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0) uniform usampler2D frame;
layout(r32f, binding = 0) writeonly uniform image2D level0;
layout(r32f, binding = 1) writeonly uniform image2D level1;
layout(r32f, binding = 2) writeonly uniform image2D level2;
uniform ivec2 size0;
uniform ivec2 size1;
uniform ivec2 size2;
uniform int levels;
uniform float lookup[256];
// One invocation: a 4x4 block of level 0, its 2x2 block of level 1 and its level-2 pixel
// (the same 2x2 box averages as the separate downsample pass; 'precise' keeps the compiler
// from re-associating the sums, so the levels match that pass bit for bit).
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    ivec2 origin = 4 * p;
    if (origin.x >= size0.x || origin.y >= size0.y) return;
    float v[16];
    for (int dy = 0; dy < 4; ++dy) {
        for (int dx = 0; dx < 4; ++dx) {
            ivec2 q = origin + ivec2(dx, dy);
            float value = 0.0;
            if (q.x < size0.x && q.y < size0.y) {
                value = lookup[texelFetch(frame, q, 0).r];
                imageStore(level0, q, vec4(value));
            }
            v[4 * dy + dx] = value;
        }
    }
    if (levels < 2) return;
    float w[4];
    for (int dy = 0; dy < 2; ++dy) {
        for (int dx = 0; dx < 2; ++dx) {
            ivec2 q = 2 * p + ivec2(dx, dy);
            int i = 8 * dy + 2 * dx;
            precise float a = v[i] + v[i + 1];
            precise float b = v[i + 4] + v[i + 5];
            precise float value = 0.25 * (a + b);
            if (q.x < size1.x && q.y < size1.y) imageStore(level1, q, vec4(value));
            w[2 * dy + dx] = value;
        }
    }
    if (levels < 3 || p.x >= size2.x || p.y >= size2.y) return;
    precise float a = w[0] + w[1];
    precise float b = w[2] + w[3];
    precise float value = 0.25 * (a + b);
    imageStore(level2, p, vec4(value));
}
"""

_DOWNSAMPLE_SRC = """
#version 430
layout(local_size_x = 8, local_size_y = 8) in;
layout(r32f, binding = 0) readonly uniform image2D finer;
layout(r32f, binding = 1) writeonly uniform image2D coarser;
uniform ivec2 size;
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (p.x >= size.x || p.y >= size.y) return;
    ivec2 q = 2 * p;
    float a = imageLoad(finer, q).r + imageLoad(finer, q + ivec2(1, 0)).r;
    float b = imageLoad(finer, q + ivec2(0, 1)).r + imageLoad(finer, q + ivec2(1, 1)).r;
    imageStore(coarser, p, vec4(0.25 * (a + b)));
}
"""

# The 3x3 Sobel gradient of a pyramid level, recomputed where it is needed (writing an
# RGBA32F gradient image costs llvmpipe more than the eight loads); 'precise' keeps every
# call site bit-identical.
_SOBEL_GLSL = """
layout(r32f, binding = 0) readonly uniform image2D level;
float at(ivec2 p) { return imageLoad(level, p).r; }
// (gx, gy, magnitude) at an inner pixel p.
vec3 sobel(ivec2 p) {
    float tl = at(p + ivec2(-1, -1)), tc = at(p + ivec2(0, -1)), tr = at(p + ivec2(1, -1));
    float ml = at(p + ivec2(-1, 0)), mr = at(p + ivec2(1, 0));
    float bl = at(p + ivec2(-1, 1)), bc = at(p + ivec2(0, 1)), br = at(p + ivec2(1, 1));
    precise float gx = ((tr - tl) + 2.0 * (mr - ml)) + (br - bl);
    precise float gy = ((bl - tl) + 2.0 * (bc - tc)) + (br - tr);
    precise float magnitude = sqrt(gx * gx + gy * gy);
    return vec3(gx, gy, magnitude);
}
"""

_RIDGE_SRC = """
#version 430
layout(local_size_x = 8, local_size_y = 8) in;
SOBEL
layout(r32f, binding = 2) writeonly uniform image2D ridge;
uniform ivec2 size;
uniform float threshold;
uniform bool thin;
bool inner(ivec2 p) { return p.x >= 1 && p.y >= 1 && p.x < size.x - 1 && p.y < size.y - 1; }
// magnitude at p (0 on the frame border, where the gradient is not taken)
float magnitude_at(ivec2 p) { return inner(p) ? sobel(p).z : 0.0; }
bool is_ridge(ivec2 p) {
    if (!inner(p)) return false;
    vec3 g = sobel(p);
    if (!(g.z >= threshold)) return false;
    if (!thin) return true;
    float ax = abs(g.x), ay = abs(g.y);
    const float tan22 = 0.41421357;
    ivec2 d;
    if (ay <= tan22 * ax) d = ivec2(1, 0);
    else if (ax <= tan22 * ay) d = ivec2(0, 1);
    else if (g.x * g.y > 0.0) d = ivec2(1, 1);
    else d = ivec2(-1, 1);
    float m_ahead = magnitude_at(p + d);
    float m_behind = magnitude_at(p - d);
    return g.z > m_behind && g.z >= m_ahead;
}
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (p.x >= size.x || p.y >= size.y) return;
    imageStore(ridge, p, vec4(is_ridge(p) ? 1.0 : 0.0));
}
""".replace('SOBEL', _SOBEL_GLSL)

_EDGES_SRC = """
#version 430
layout(local_size_x = 8, local_size_y = 8) in;
SOBEL
layout(r32f, binding = 2) readonly uniform image2D ridge;
layout(std430, binding = 0) buffer Command { uint command[4]; };
layout(std430, binding = 1) writeonly buffer Edges { vec4 edges[]; };
uniform ivec2 size;
uniform uint vertices_per_edge;
uniform int min_support;
uniform float support_cosine;
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (p.x < 1 || p.y < 1 || p.x >= size.x - 1 || p.y >= size.y - 1) return;
    if (imageLoad(ridge, p).r == 0.0) return;
    vec3 g = sobel(p);
    vec2 direction = g.xy / g.z;
    if (min_support > 0) {
        int support = 0;
        for (int dy = -1; dy <= 1; ++dy) {
            for (int dx = -1; dx <= 1; ++dx) {
                ivec2 q = p + ivec2(dx, dy);
                if ((dx == 0 && dy == 0) || imageLoad(ridge, q).r == 0.0) continue;
                vec3 h = sobel(q);
                if (dot(direction, h.xy / h.z) >= support_cosine) support += 1;
            }
        }
        if (support < min_support) return;
    }
    uint index = atomicAdd(command[0], vertices_per_edge) / vertices_per_edge;
    edges[index] = vec4(vec2(p), direction);
}
""".replace('SOBEL', _SOBEL_GLSL)

_VOTE_VERTEX_SRC = """
#version 430
layout(std430, binding = 1) readonly buffer Edges { vec4 edges[]; };
uniform vec2 size;
uniform float max_radius;
uniform float spread;
uniform float vote_sign;
uniform float shrink;
noperspective out float distance_along;
noperspective out float distance_across;
void main() {
    vec4 edge = edges[gl_VertexID / VERTICES_PER_EDGE];
    int corner = gl_VertexID % VERTICES_PER_EDGE;
    vec2 direction = vote_sign * edge.zw;
    vec2 normal = vec2(-direction.y, direction.x);
    float r = corner == 0 ? 0.0 : max_radius;
    float side = corner == 1 ? 1.0 : -1.0;
    vec2 position = (edge.xy + 0.5) * shrink - 0.5
        + (r * shrink) * (direction + side * spread * normal);
    distance_along = r;
    distance_across = r * side * spread;
    gl_Position = vec4((position + 0.5) / size * 2.0 - 1.0, 0.0, 1.0);
}
"""

_VOTE_FRAGMENT_SRC = """
#version 430
noperspective in float distance_along;
noperspective in float distance_across;
uniform float min_radius;
uniform float split_radius;
uniform float spread;
uniform bool tent;
layout(location = 0) out vec4 votes;
void main() {
    if (distance_along < min_radius) discard;
    float profile = tent ? clamp(1.0 - abs(distance_across) / (spread * distance_along),
                                 0.0, 1.0) : 1.0;
    float weight = profile / distance_along;
    votes = distance_along < split_radius ? vec4(weight, profile, 0.0, 0.0)
                                          : vec4(0.0, 0.0, weight, profile);
}
"""

_REDUCE_SRC = """
#version 430
layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0) uniform sampler2D votes;
struct Best { vec4 score_x_y_radius; vec4 band_unused; };
layout(std430, binding = 2) buffer Blocks { Best blocks[]; };
uniform ivec2 blocks_size;
uniform ivec2 level_size;
uniform int block_level_px;
uniform int scale;
uniform int target_scale;
uniform int band;
uniform int slot;
uniform float normaliser;
float score_at(ivec2 q) {
    vec4 v = texelFetch(votes, q, 0);
    return (slot == 0 ? v.r : v.b) * normaliser;
}
float score_clamped(ivec2 q) {
    return score_at(clamp(q, ivec2(0), level_size - 1));
}
float offset(float minus, float centre, float plus) {
    float curvature = minus - 2.0 * centre + plus;
    if (curvature >= 0.0) return 0.0;
    return clamp(0.5 * (minus - plus) / curvature, -0.5, 0.5);
}
void main() {
    ivec2 block = ivec2(gl_GlobalInvocationID.xy);
    if (block.x >= blocks_size.x || block.y >= blocks_size.y) return;
    int index = block.y * blocks_size.x + block.x;
    float best = -1.0;
    ivec2 best_q = ivec2(0);
    ivec2 origin = block * block_level_px;
    for (int dy = 0; dy < block_level_px; ++dy) {
        for (int dx = 0; dx < block_level_px; ++dx) {
            ivec2 q = origin + ivec2(dx, dy);
            if (q.x >= level_size.x || q.y >= level_size.y) continue;
            float s = score_at(q);
            if (s > best) { best = s; best_q = q; }
        }
    }
    if (best <= 0.0 || !(best > blocks[index].score_x_y_radius.x)) return;
    float ox = offset(score_clamped(best_q - ivec2(1, 0)), best,
                      score_clamped(best_q + ivec2(1, 0)));
    float oy = offset(score_clamped(best_q - ivec2(0, 1)), best,
                      score_clamped(best_q + ivec2(0, 1)));
    vec4 v = texelFetch(votes, best_q, 0);
    vec2 band_votes = slot == 0 ? v.rg : v.ba;
    float radius = band_votes.y / band_votes.x * float(scale);
    float half_step = 0.5 * float(target_scale - 1);
    blocks[index].score_x_y_radius = vec4(best, float(target_scale) * (float(best_q.x) + ox) + half_step,
                                          float(target_scale) * (float(best_q.y) + oy) + half_step,
                                          radius);
    blocks[index].band_unused = vec4(float(band), 0.0, 0.0, 0.0);
}
"""


@dataclass
class _LevelResources:
    """GPU objects of one pyramid level for one frame size."""

    width_px: int
    height_px: int
    image: object
    ridge: object
    edges: object
    command: object


@dataclass
class _DrawGroup:
    """One or two adjacent bands with the same edge and vote levels: one draw.

    The RGBA32F target holds ``(sum w, n)`` of the first band in RG and of the second
    in BA; the fragment shader routes a vote by its distance. A group of one band has
    an RG32F target (half the blending work).
    """

    bands: tuple[RadiusBand, ...]
    target: object
    framebuffer: object


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
            self.renderer = str(self._ctx.info['GL_RENDERER'])
            self._pyramid = self._ctx.compute_shader(_PYRAMID_SRC)
            self._downsample = self._ctx.compute_shader(_DOWNSAMPLE_SRC)
            self._ridge = self._ctx.compute_shader(_RIDGE_SRC)
            self._extract = self._ctx.compute_shader(_EDGES_SRC)
            self._reduce = self._ctx.compute_shader(_REDUCE_SRC)
            vertices_per_edge = _VERTICES_PER_EDGE
            self._vote = self._ctx.program(
                vertex_shader=_VOTE_VERTEX_SRC.replace(
                    '#version 430',
                    f'#version 430\n#define VERTICES_PER_EDGE {vertices_per_edge}'),
                fragment_shader=_VOTE_FRAGMENT_SRC)
            self._vote_array = self._ctx.vertex_array(self._vote, [])
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
        """Record per-stage times in ``stage_ms`` (adds a GPU sync per stage; for benches)."""
        self.stage_ms = {} if enabled else None

    def _stage(self, name: str | None) -> None:
        if self.stage_ms is None:
            return
        self._ctx.finish()
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
        """Vote on a validated (H, W) uint8 frame; per-block best pixels (see candidates)."""
        self._check_thread()
        with self._ctx:  # current on this thread (other detectors may have their own)
            self._run_votes(gray)
            self._reduce_blocks()
            raw = np.frombuffer(self._blocks.read(), dtype=np.float32).reshape(-1, 8)
            self._stage('readback')
        rows, cols = self._blocks_shape
        return BlockMaxima(score=raw[:, 0].reshape(rows, cols).copy(),
                           x_px=raw[:, 1].reshape(rows, cols).copy(),
                           y_px=raw[:, 2].reshape(rows, cols).copy(),
                           radius_px=raw[:, 3].reshape(rows, cols).copy(),
                           band=raw[:, 4].reshape(rows, cols).astype(np.int32))

    def vote_images(self, gray: np.ndarray) -> list[np.ndarray]:
        """Vote images of every band, (H_level, W_level, CHANNELS) float32 each."""
        self._check_thread()
        images = []
        with self._ctx:
            self._run_votes(gray)
            for group in self._groups:
                width, height = group.target.size
                pixels = np.frombuffer(group.target.read(), np.float32).reshape(
                    height, width, group.target.components)
                for slot in range(len(group.bands)):
                    images.append(pixels[..., CHANNELS * slot:CHANNELS * (slot + 1)].copy())
        return images

    def edge_counts(self) -> list[int]:
        """Edge pixels per pyramid level of the last frame (reads 16 bytes per level)."""
        self._check_thread()
        with self._ctx:
            return [int(np.frombuffer(level.command.read(), np.uint32)[0]) // _VERTICES_PER_EDGE
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
                ridge=ctx.texture((level_width, level_height), 1, dtype='f4'),
                edges=ctx.buffer(reserve=16 * level_width * level_height),
                command=ctx.buffer(reserve=16)))
            level_width, level_height = level_width // 2, level_height // 2
        self._groups = []
        for bands in _draw_groups(self._config, self._bands):
            size = level_size(width, height, bands[0].target_level)
            target = ctx.texture(size, CHANNELS * len(bands), dtype='f4')
            self._groups.append(_DrawGroup(bands, target,
                                           ctx.framebuffer(color_attachments=[target])))
        block = self._config.block_size_px
        self._blocks_shape = (-(-height // block), -(-width // block))
        self._blocks = ctx.buffer(reserve=32 * self._blocks_shape[0] * self._blocks_shape[1])
        self._size = (width, height)

    def _release_size_resources(self) -> None:
        objects = [self._frame, self._blocks]
        for level in self._levels:
            objects += [level.image, level.ridge, level.edges, level.command]
        for group in self._groups:
            objects += [group.framebuffer, group.target]
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
        ctx = self._ctx
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
        self._pyramid.run(_groups(-(-width // 4)), _groups(-(-height // 4)))
        ctx.memory_barrier()
        for finer, coarser in zip(self._levels[_FUSED_LEVELS - 1:], self._levels[_FUSED_LEVELS:]):
            finer.image.bind_to_image(0, read=True, write=False)
            coarser.image.bind_to_image(1, read=False, write=True)
            self._downsample['size'] = (coarser.width_px, coarser.height_px)
            self._downsample.run(_groups(coarser.width_px), _groups(coarser.height_px))
            ctx.memory_barrier()
        self._stage('upload_pyramid')
        self._extract['vertices_per_edge'] = _VERTICES_PER_EDGE
        self._extract['min_support'] = self._config.edge_support
        self._extract['support_cosine'] = math.cos(math.radians(SUPPORT_ANGLE_DEG))
        self._ridge['threshold'] = float(self._config.gradient_threshold)
        self._ridge['thin'] = bool(self._config.thin_edges)
        for level in self._levels:
            level.image.bind_to_image(0, read=True, write=False)
            level.command.write(np.array([0, 1, 0, 0], np.uint32).tobytes())
            level.ridge.bind_to_image(2, read=False, write=True)
            self._ridge['size'] = (level.width_px, level.height_px)
            self._ridge.run(_groups(level.width_px), _groups(level.height_px))
            ctx.memory_barrier()
            level.ridge.bind_to_image(2, read=True, write=False)
            level.command.bind_to_storage_buffer(0)
            level.edges.bind_to_storage_buffer(1)
            self._extract['size'] = (level.width_px, level.height_px)
            self._extract.run(_groups(level.width_px), _groups(level.height_px))
            self._stage('edges')
        ctx.memory_barrier()
        import moderngl

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
            self._vote['size'] = tuple(float(extent) for extent in group.target.size)
            self._vote['shrink'] = first.shrink
            self._vote['min_radius'] = first.level_radii[0]
            self._vote['max_radius'] = last.level_radii[1]
            self._vote['split_radius'] = (first.level_radii[1] if len(group.bands) == 2
                                          else 3.0e38)
            level.edges.bind_to_storage_buffer(1)
            for sign in vote_signs(self._config, first):
                self._vote['vote_sign'] = sign
                self._vote_array.render_indirect(level.command, mode=moderngl.TRIANGLES,
                                                 count=1)
        ctx.disable(moderngl.BLEND)
        ctx.memory_barrier()
        self._stage('vote')

    def _reduce_blocks(self) -> None:
        rows, cols = self._blocks_shape
        initial = np.zeros((rows * cols, 8), np.float32)
        initial[:, 0] = -1.0
        self._blocks.write(initial.tobytes())
        self._blocks.bind_to_storage_buffer(2)
        block = self._config.block_size_px
        self._reduce['blocks_size'] = (cols, rows)
        for group in self._groups:
            group.target.use(0)
            for slot, band in enumerate(group.bands):
                self._reduce['slot'] = slot
                self._reduce['level_size'] = group.target.size
                self._reduce['block_level_px'] = max(1, block // band.target_scale)
                self._reduce['scale'] = band.scale
                self._reduce['target_scale'] = band.target_scale
                self._reduce['band'] = band.index
                self._reduce['normaliser'] = score_normaliser(
                    len(vote_signs(self._config, band)))
                self._reduce.run(_groups(cols), _groups(rows))
                self._ctx.memory_barrier()
        self._stage('reduce')


def _groups(extent: int) -> int:
    return math.ceil(extent / _GROUP)
