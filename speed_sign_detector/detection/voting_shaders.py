"""The GLSL sources of the GL voting backend (:mod:`speed_sign_detector.detection.voting_gl`).

One compute shader or program per step of that module's pipeline: the pyramid upload,
the 3x3 Sobel edge pixels (ridge pass, then the neighbour-support extraction), the
votes (raster: a vertex and a fragment shader; scatter: a compute shader adding fixed-
point integers, :mod:`speed_sign_detector.detection.vote_fixed_point`) and the per-block
reduction. :func:`with_constants` defines the shared constants after ``#version``.
"""
from __future__ import annotations

VERTICES_PER_EDGE = 3
"""Vertices per edge pixel in the raster draw (one vote triangle)."""
SCATTER_GROUP = 64
"""Edges per work group of the scatter pass."""
EXTRACT_GROUP = 64
"""Edge pixels per work group of the extraction (support test)."""

PYRAMID_SOURCE = """
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

DOWNSAMPLE_SOURCE = """
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
SOBEL_GLSL = """
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

RIDGE_SOURCE = """
#version 430
layout(local_size_x = 8, local_size_y = 8) in;
SOBEL
// an edge pixel's unit gradient direction g / |g|; (0, 0) elsewhere
layout(rg32f, binding = 2) writeonly uniform image2D ridge;
// the edge pixels in a list, and the group count of the extraction over them
layout(std430, binding = 4) buffer Ridges {
    uint ridge_dispatch[3];
    uint ridge_count;
    ivec2 ridge_pixels[];
};
uniform ivec2 size;
uniform float threshold;
uniform bool thin;
bool inner(ivec2 p) { return p.x >= 1 && p.y >= 1 && p.x < size.x - 1 && p.y < size.y - 1; }
// magnitude at p (0 on the frame border, where the gradient is not taken)
float magnitude_at(ivec2 p) { return inner(p) ? sobel(p).z : 0.0; }
bool is_ridge(ivec2 p, vec3 g) {
    if (!inner(p)) return false;
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
    vec3 g = inner(p) ? sobel(p) : vec3(0.0);
    if (is_ridge(p, g)) {
        imageStore(ridge, p, vec4(g.xy / g.z, 0.0, 0.0));
        uint index = atomicAdd(ridge_count, 1u);
        ridge_pixels[index] = p;
        if (index % uint(EXTRACT_GROUP) == 0u) atomicAdd(ridge_dispatch[0], 1u);
    } else {
        imageStore(ridge, p, vec4(0.0));
    }
}
""".replace('SOBEL', SOBEL_GLSL)

EDGES_SOURCE = """
#version 430
layout(local_size_x = EXTRACT_GROUP) in;
layout(rg32f, binding = 2) readonly uniform image2D ridge;
layout(std430, binding = 4) readonly buffer Ridges {
    uint ridge_dispatch[3];
    uint ridge_count;
    ivec2 ridge_pixels[];
};
layout(std430, binding = 0) buffer Command { uint command[4]; };
layout(std430, binding = 1) writeonly buffer Edges { vec4 edges[]; };
layout(std430, binding = 3) buffer Dispatch { uint dispatch[3]; };
uniform uint vertices_per_edge;
uniform int min_support;
uniform float support_cosine;
// one invocation per edge pixel of the ridge pass (all inner pixels)
void main() {
    if (gl_GlobalInvocationID.x >= ridge_count) return;
    ivec2 p = ridge_pixels[gl_GlobalInvocationID.x];
    vec2 direction = imageLoad(ridge, p).xy;
    if (min_support > 0) {
        int support = 0;
        for (int dy = -1; dy <= 1; ++dy) {
            for (int dx = -1; dx <= 1; ++dx) {
                vec2 other = imageLoad(ridge, p + ivec2(dx, dy)).xy;
                if ((dx == 0 && dy == 0) || other == vec2(0.0)) continue;
                if (dot(direction, other) >= support_cosine) support += 1;
            }
        }
        if (support < min_support) return;
    }
    uint index = atomicAdd(command[0], vertices_per_edge) / vertices_per_edge;
    edges[index] = vec4(vec2(p), direction);
    // the scatter pass runs one invocation per edge in groups of SCATTER_GROUP
    if (index % uint(SCATTER_GROUP) == 0u) atomicAdd(dispatch[0], 1u);
}
"""

VOTE_VERTEX_SOURCE = """
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

VOTE_FRAGMENT_SOURCE = """
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

SCATTER_SOURCE = """
#version 430
layout(local_size_x = SCATTER_GROUP) in;
layout(std430, binding = 0) readonly buffer Command { uint command[4]; };
layout(std430, binding = 1) readonly buffer Edges { vec4 edges[]; };
// the group's votes, band slot s at (x + s W, y): with PACKED_VOTES, one integer with
// sum w in the high bits and n in the low count_bits; else sum w there and n at
// (x + s W, y + H) (a compile-time choice: llvmpipe runs both sides of a uniform branch
// around the atomics, which cost it a fifth of the pass)
layout(r32ui, binding = 0) uniform uimage2D votes;
#if PACKED_VOTES
uniform int count_bits;
#endif
uniform float weight_one;
uniform float count_one;
uniform ivec2 size;
uniform float shrink;
uniform float min_radius;
uniform float max_radius;
uniform float split_radius;
uniform float vote_sign;
uniform float spread;
uniform bool tent;
// One invocation per edge: the pixels whose centres lie inside its trapezoid, row by
// row (the scanline rule of the numpy reference), each vote added as fixed-point
// integers (order-independent sums: the result does not depend on the edge order).
void main() {
    uint index = gl_GlobalInvocationID.x;
    if (index >= command[0] / uint(VERTICES_PER_EDGE)) return;
    vec4 edge = edges[index];
    vec2 centre = (edge.xy + 0.5) * shrink - 0.5;
    vec2 direction = vote_sign * edge.zw;
    vec2 normal = vec2(-direction.y, direction.x);
    float near = min_radius * shrink;
    float far = max_radius * shrink;
    vec2 corners[4] = vec2[4](centre + near * (direction + spread * normal),
                              centre + far * (direction + spread * normal),
                              centre + far * (direction - spread * normal),
                              centre + near * (direction - spread * normal));
    float low = min(min(corners[0].y, corners[1].y), min(corners[2].y, corners[3].y));
    float high = max(max(corners[0].y, corners[1].y), max(corners[2].y, corners[3].y));
    int first_row = max(int(ceil(low)), 0);
    int last_row = min(int(floor(high)), size.y - 1);
    for (int row = first_row; row <= last_row; ++row) {
        float y = float(row);
        float left = 3.0e38;
        float right = -3.0e38;
        for (int side = 0; side < 4; ++side) {
            vec2 a = corners[side];
            vec2 b = corners[(side + 1) & 3];
            if ((y - a.y) * (y - b.y) <= 0.0 && a.y != b.y) {
                float x = a.x + (y - a.y) * (b.x - a.x) / (b.y - a.y);
                left = min(left, x);
                right = max(right, x);
            }
        }
        if (left > right) continue;
        int first_col = max(int(ceil(left)), 0);
        int last_col = min(int(floor(right)), size.x - 1);
        for (int col = first_col; col <= last_col; ++col) {
            vec2 offset = vec2(float(col), y) - centre;
            float along = dot(offset, direction);
            float profile = 1.0;
            if (tent) {
                profile = along > 0.0
                    ? clamp(1.0 - abs(dot(offset, normal)) / (spread * along), 0.0, 1.0) : 0.0;
            }
            uint count = uint(profile * count_one + 0.5);
            if (count == 0u) continue;
            float distance = max(along / shrink, 0.5 * min_radius);
            uint weight = uint(profile / distance * weight_one + 0.5);
            ivec2 q = ivec2(distance < split_radius ? col : col + size.x, row);
#if PACKED_VOTES
            imageAtomicAdd(votes, q, (weight << uint(count_bits)) | count);
#else
            imageAtomicAdd(votes, q, weight);
            imageAtomicAdd(votes, ivec2(q.x, row + size.y), count);
#endif
        }
    }
}
"""

REDUCE_SOURCE = """
#version 430
#define MAX_BANDS 8
layout(local_size_x = 8, local_size_y = 8) in;
// band b's (sum w, n) votes, at q + weight_offset[b] in votes[b]: raster, channels
// weight_channel[b] and count_channel[b] of the group's RGBA32F/RG32F target; scatter,
// fixed-point integers in the band's part of the group's R32UI image, packed into one
// integer when count_bits[b] > 0, else n at q + count_offset[b]
layout(binding = 0) uniform VOTE_SAMPLER votes[MAX_BANDS];
// per block and band (index block * BAND_COUNT + band): score, centre x, y, radius
layout(std430, binding = 2) writeonly buffer Blocks { vec4 blocks[]; };
uniform ivec2 blocks_size;
uniform ivec2 level_size[MAX_BANDS];
uniform int block_level_px[MAX_BANDS];
uniform int scale[MAX_BANDS];
uniform int target_scale[MAX_BANDS];
uniform int weight_channel[MAX_BANDS];
uniform int count_channel[MAX_BANDS];
uniform ivec2 weight_offset[MAX_BANDS];
uniform ivec2 count_offset[MAX_BANDS];
uniform float normaliser[MAX_BANDS];
uniform int band_index[MAX_BANDS];
uniform int count_bits[MAX_BANDS];
uniform float weight_unit[MAX_BANDS];
uniform float count_unit[MAX_BANDS];
VOTES_AT
float score_at(int b, ivec2 q) {
    return votes_at(b, q).x * normaliser[b];
}
float score_clamped(int b, ivec2 q) {
    return score_at(b, clamp(q, ivec2(0), level_size[b] - 1));
}
float offset(float minus, float centre, float plus) {
    float curvature = minus - 2.0 * centre + plus;
    if (curvature >= 0.0) return 0.0;
    return clamp(0.5 * (minus - plus) / curvature, -0.5, 0.5);
}
// the best pixel of band B in this block (the first of equal scores, row-major; B a
// constant: llvmpipe indexes sampler arrays with a constant fast, with a variable very
// slowly), refined to sub-pixel with a parabola through its neighbours, written to the
// band's slot of the block (score -1: no positive score)
#define BAND_BLOCK(B) { \\
    float best = -1.0; \\
    ivec2 best_q = ivec2(0); \\
    int side = block_level_px[B]; \\
    ivec2 origin = block * side; \\
    for (int dy = 0; dy < side; ++dy) { \\
        for (int dx = 0; dx < side; ++dx) { \\
            ivec2 q = origin + ivec2(dx, dy); \\
            if (q.x >= level_size[B].x || q.y >= level_size[B].y) continue; \\
            float s = score_at(B, q); \\
            if (s > best) { best = s; best_q = q; } \\
        } \\
    } \\
    int slot = index * BAND_COUNT + band_index[B]; \\
    if (best > 0.0) { \\
        float ox = offset(score_clamped(B, best_q - ivec2(1, 0)), best, \\
                          score_clamped(B, best_q + ivec2(1, 0))); \\
        float oy = offset(score_clamped(B, best_q - ivec2(0, 1)), best, \\
                          score_clamped(B, best_q + ivec2(0, 1))); \\
        vec2 band_votes = votes_at(B, best_q); \\
        float step = float(target_scale[B]); \\
        float half_step = 0.5 * (step - 1.0); \\
        blocks[slot] = vec4(best, step * (vec2(best_q) + vec2(ox, oy)) + half_step, \\
                            band_votes.y / band_votes.x * float(scale[B])); \\
    } else { \\
        blocks[slot] = vec4(-1.0, 0.0, 0.0, 0.0); \\
    } \\
}
// One invocation per block: the best vote pixel of every band.
void main() {
    ivec2 block = ivec2(gl_GlobalInvocationID.xy);
    if (block.x >= blocks_size.x || block.y >= blocks_size.y) return;
    int index = block.y * blocks_size.x + block.x;
    BAND_BLOCKS
}
"""


def with_constants(source: str) -> str:
    """Shader source with the module's constants defined after its #version line."""
    return source.replace('#version 430', '#version 430\n'
                          f'#define VERTICES_PER_EDGE {VERTICES_PER_EDGE}\n'
                          f'#define SCATTER_GROUP {SCATTER_GROUP}\n'
                          f'#define EXTRACT_GROUP {EXTRACT_GROUP}', 1)

VOTES_AT_RASTER = """
vec2 votes_at(int b, ivec2 q) {
    return vec2(texelFetch(votes[b], q + weight_offset[b], 0)[weight_channel[b]],
                texelFetch(votes[b], q + count_offset[b], 0)[count_channel[b]]);
}
"""
"""``votes_at`` of the reduction for raster votes (float sums)."""

VOTES_AT_SCATTER = """
vec2 votes_at(int b, ivec2 q) {
    uint value = texelFetch(votes[b], q + weight_offset[b], 0).r;
    if (count_bits[b] > 0) {
        uint count = value & ((1u << uint(count_bits[b])) - 1u);
        return vec2(float(value >> uint(count_bits[b])) * weight_unit[b],
                    float(count) * count_unit[b]);
    }
    uint count = texelFetch(votes[b], q + count_offset[b], 0).r;
    return vec2(float(value) * weight_unit[b], float(count) * count_unit[b]);
}
"""
"""``votes_at`` of the reduction for scatter votes (fixed-point integers, maybe packed)."""
