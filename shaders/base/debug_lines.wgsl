// `valgi view`'s world-space line overlay (the links debug view): segments the CPU lays out
// (the picked vertex to each point it interpolates), drawn over the view with no depth test,
// so a link behind a surface still shows. Colours are display values, not radiances.
#include "common.wgsl"

@group(0) @binding(0) var<uniform> frame: Frame;

struct LineVertex {
    @location(0) position: vec3<f32>,
    @location(1) colour: vec3<f32>,
}

struct LineOut {
    @builtin(position) position: vec4<f32>,
    @location(0) colour: vec3<f32>,
}

@vertex
fn vs_main(v: LineVertex) -> LineOut {
    var out: LineOut;
    out.position = frame.clip_from_world * vec4<f32>(v.position, 1.0);
    out.colour = v.colour;
    return out;
}

@fragment
fn fs_main(in: LineOut) -> @location(0) vec4<f32> {
    return vec4<f32>(in.colour, 1.0);
}
