// Step 2 — renormalize: replace each point's sums by point-light intensities that reproduce
// them at the point: I = E / max(c_min, f(x, l)), with the same f the apply pass evaluates, so
// the result is exact at x unless the clamp fires (counted per channel).
#include "vals_common.wgsl"

@group(0) @binding(0) var<storage, read> params: SparseParams;
@group(0) @binding(1) var<storage, read> instances: array<InstanceData>;
@group(0) @binding(2) var<storage, read> points_model: array<vec4<u32>>;
@group(0) @binding(3) var<storage, read> points_meta: array<vec2<u32>>;
@group(0) @binding(4) var<storage, read_write> point_diffuse: array<vec4<u32>>;
@group(0) @binding(5) var<storage, read_write> point_glossy: array<vec4<u32>>;
@group(0) @binding(6) var<storage, read> point_extra: array<vec2<u32>>;
// [0]: diffuse clamps, [1]: glossy clamps.
@group(0) @binding(7) var<storage, read_write> clamp_count: array<atomic<u32>>;

@compute @workgroup_size(64, 1, 1)
fn cs_main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let index = linear_index(gid, groups);
    if (index >= params.point_count) {
        return;
    }
    let point_meta = points_meta[index];
    let point = world_point(points_model[index], point_meta, instances[point_meta.y]);
    let d = point_diffuse[index];
    let s = point_glossy[index];
    let lights = decode_lights(point.position, d, s, point_extra[index]);
    let wo = normalize(params.eye.xyz - point.position);
    let r = reflect(-wo, point.normal);

    let ld = lights.diffuse_position - point.position;
    let fd = diffuse_point_factor(point.position, point.normal, lights.diffuse_position);
    let cd = COS_MIN / max(dot(ld, ld), 1e-30);
    let ls = lights.glossy_position - point.position;
    let fs = glossy_point_factor(point.position, point.normal, r, point.k, lights.glossy_position);
    let cs = COS_MIN / max(dot(ls, ls), 1e-30);
    let glossy_only = (params.flags & FLAG_GLOSSY_ONLY) != 0u;
    if (!glossy_only && fd < cd && max(lights.diffuse.r, max(lights.diffuse.g, lights.diffuse.b)) > 0.0) {
        atomicAdd(&clamp_count[0], 1u);
    }
    if (fs < cs && max(lights.glossy.r, max(lights.glossy.g, lights.glossy.b)) > 0.0) {
        atomicAdd(&clamp_count[1], 1u);
    }
    point_glossy[index] = vec4<u32>(rgb_bits(lights.glossy / max(fs, cs)), s.w);
    if (!glossy_only) {
        point_diffuse[index] = vec4<u32>(rgb_bits(lights.diffuse / max(fd, cd)), d.w);
    }
}
