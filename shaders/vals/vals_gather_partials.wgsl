// The gather split over slices of the VAL list (`gather-slices`, dispatch z): a point's sums
// are plain sums over VALs, so each slice's workgroups gather their own part of the list and
// store the partial sums here, slice-major (`partials[(slice · points + point) · 5 ..]`), and
// `vals_gather_reduce.wgsl` adds the slices and writes the point. This is what fills a GPU
// when the points alone are too few: 4096 points are 16 workgroups of the unsplit gather.
#include "vals_gather_common.wgsl"

@group(1) @binding(0) var<storage, read_write> partials: array<vec4<f32>>;

// The window form of the gather (`cs_window`) keeps each point's running sums here between
// its windows, as slice 0.
//
// vec4 words per (slice, point): the 20 floats of `Sums`. `GATHER_PARTIAL_VEC4S` in
// `src/vals/sparse.rs`.
const PARTIAL_VEC4S: u32 = 5u;

fn partial_store(at: u32, s: Sums) {
    partials[at] = vec4<f32>(s.diffuse, s.md.weight);
    partials[at + 1u] = vec4<f32>(s.md.sum, s.ms.weight);
    partials[at + 2u] = vec4<f32>(s.md.sum_squares, s.glossy.r);
    partials[at + 3u] = vec4<f32>(s.ms.sum, s.glossy.g);
    partials[at + 4u] = vec4<f32>(s.ms.sum_squares, s.glossy.b);
}

// The sums `partial_store` stored at `at`, as they were.
fn partial_load(at: u32) -> Sums {
    let a = partials[at];
    let b = partials[at + 1u];
    let c = partials[at + 2u];
    let d = partials[at + 3u];
    let e = partials[at + 4u];
    var s: Sums;
    s.diffuse = a.xyz;
    s.md.weight = a.w;
    s.md.sum = b.xyz;
    s.ms.weight = b.w;
    s.md.sum_squares = c.xyz;
    s.ms.sum = d.xyz;
    s.ms.sum_squares = e.xyz;
    s.glossy = vec3<f32>(c.w, d.w, e.w);
    return s;
}

fn partial_add(sums: ptr<function, Sums>, at: u32) {
    let p = partial_load(at);
    (*sums).diffuse += p.diffuse;
    (*sums).md.weight += p.md.weight;
    (*sums).md.sum += p.md.sum;
    (*sums).ms.weight += p.ms.weight;
    (*sums).md.sum_squares += p.md.sum_squares;
    (*sums).ms.sum += p.ms.sum;
    (*sums).ms.sum_squares += p.ms.sum_squares;
    (*sums).glossy += p.glossy;
}
