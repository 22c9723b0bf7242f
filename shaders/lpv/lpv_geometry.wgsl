// The geometry volume: (N+1)³ cells centred on the LPV cells' corners (offset by half a
// cell), 4 SH coefficients each of the blocking potential Σ A/h²·max(0, n·ω) of the surfels
// nearest that corner. Surfels come from the RSM VALs (cs_rsm; area = the texel footprint)
// and from the camera's G-buffer (cs_camera; one per stride² pixels, area = the pixels'
// footprint on the surface). CPU twin of cs_rsm: math::geometry.
#include "lpv_common.wgsl"

@group(0) @binding(0) var<uniform> params: LpvParams;
@group(0) @binding(1) var<storage, read> vals: array<Val>;
@group(0) @binding(2) var<storage, read> val_count: array<u32>;
@group(0) @binding(3) var<storage, read_write> gv: array<atomic<u32>>;
@group(0) @binding(4) var<uniform> frame: Frame;
@group(0) @binding(5) var gbuffer_depth: texture_depth_2d;
@group(0) @binding(6) var gbuffer_normal: texture_2d<f32>;
@group(0) @binding(7) var gbuffer_specular: texture_2d<f32>;

fn add_f32(index: u32, value: f32) {
    var old = atomicLoad(&gv[index]);
    loop {
        let r = atomicCompareExchangeWeak(&gv[index], old, bitcast<u32>(bitcast<f32>(old) + value));
        if (r.exchanged) {
            break;
        }
        old = r.old_value;
    }
}

fn add_surfel(p: vec3<f32>, n: vec3<f32>, area: f32) {
    let h = params.origin_cell.w;
    let g = vec3<i32>(floor((p - params.origin_cell.xyz) / h + 0.5));
    let gd = vec3<i32>(params.dims.xyz) + 1;
    if (any(g < vec3<i32>(0)) || any(g >= gd) || !(area > 0.0)) {
        return;
    }
    let index = u32(g.x + gd.x * (g.y + gd.y * g.z)) * 4u;
    let y = sh9(n);
    let scale = area / (h * h);
    for (var k = 0u; k < 4u; k++) {
        add_f32(index + k, scale * clamped_cosine_factor(k) * y[k]);
    }
}

@compute @workgroup_size(64, 1, 1)
fn cs_rsm(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = id.x + id.y * groups.x * 64u;
    if (i >= min(val_count[0], arrayLength(&vals))) {
        return;
    }
    let val = vals[i];
    add_surfel(val.position_area.xyz, val.normal.xyz, val.position_area.w);
}

fn unproject(pixel: vec2<f32>, depth: f32) -> vec3<f32> {
    let uv = pixel / vec2<f32>(frame.render_size);
    let world = frame.world_from_clip * vec4<f32>(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, depth, 1.0);
    return world.xyz / world.w;
}

@compute @workgroup_size(8, 8, 1)
fn cs_camera(@builtin(global_invocation_id) id: vec3<u32>) {
    let stride = max(params.surfel_stride, 1u);
    let pixel = id.xy * stride + stride / 2u;
    if (any(pixel >= frame.render_size)) {
        return;
    }
    let ip = vec2<i32>(pixel);
    if (textureLoad(gbuffer_specular, ip, 0).a < 0.5) {
        return;
    }
    let depth = textureLoad(gbuffer_depth, ip, 0);
    let center = vec2<f32>(pixel) + 0.5;
    let p = unproject(center, depth);
    let n = normalize(textureLoad(gbuffer_normal, ip, 0).xyz);
    // The stride² pixels' footprint on the constant-depth plane, then on the surface.
    let s = f32(stride);
    let plane = cross(unproject(center + vec2<f32>(s, 0.0), depth) - p, unproject(center + vec2<f32>(0.0, s), depth) - p);
    let plane_area = length(plane);
    let ray = normalize(p - frame.camera_position.xyz);
    let cos_plane = abs(dot(plane / max(plane_area, 1e-30), ray));
    let cos_surface = max(abs(dot(n, ray)), 0.2);
    add_surfel(p, n, plane_area * cos_plane / cos_surface);
}
