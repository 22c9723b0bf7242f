// Step 3 — interpolate: every vertex of every instance takes the weighted mean of its 8 linked
// points' lights (positions and intensities, weights of paper eq. 12 precomputed in model space
// and stored normalized as unorm16 beside a mesh-local point index). The diffuse intensity is
// then capped so that the blended light gives the vertex at most BLEND_GAIN_MAX times the mean
// of its links' lights evaluated there (CPU twin: `vals::math::interpolate`): blending
// positions of lights that lie in different directions puts the light near the surface.
#include "vals_common.wgsl"

@group(0) @binding(0) var<storage, read> params: SparseParams;
@group(0) @binding(1) var<storage, read> instances: array<InstanceData>;
@group(0) @binding(2) var<storage, read> points_model: array<vec4<u32>>;
@group(0) @binding(3) var<storage, read> points_meta: array<vec2<u32>>;
@group(0) @binding(4) var<storage, read> point_diffuse: array<vec4<u32>>;
@group(0) @binding(5) var<storage, read> point_glossy: array<vec4<u32>>;
@group(0) @binding(6) var<storage, read> point_extra: array<vec2<u32>>;
@group(0) @binding(7) var<storage, read> ranges: array<InstanceRange>;
// Two vec4 per mesh vertex: 8 × (point index | weight << 16).
@group(0) @binding(8) var<storage, read> vertex_links: array<vec4<u32>>;
// One vec4 per link row: the vertex's model position (f32 bits) and octahedral normal.
@group(0) @binding(9) var<storage, read> link_vertices: array<vec4<u32>>;
// Three vec4 per instance vertex: (l_d.xyz, I_d.r), (I_d.gb, l_s.xy), (l_s.z, I_s.rgb).
@group(0) @binding(10) var<storage, read_write> vertex_lights: array<vec4<f32>>;

// The instance whose vertex range holds `v` (ranges are sorted by vertex_offset).
fn find_instance(v: u32) -> u32 {
    var lo = 0u;
    var hi = params.instance_count;
    while (hi - lo > 1u) {
        let mid = (lo + hi) / 2u;
        if (ranges[mid].vertex_offset <= v) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    return lo;
}

@compute @workgroup_size(64, 1, 1)
fn cs_main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let v = linear_index(gid, groups);
    if (v >= params.vertex_count || params.instance_count == 0u) {
        return;
    }
    let instance = find_instance(v);
    let range = ranges[instance];
    let local = v - range.vertex_offset;
    let packed = array<vec4<u32>, 2>(vertex_links[(range.link_offset + local) * 2u], vertex_links[(range.link_offset + local) * 2u + 1u]);
    // The vertex in world space (a point's meta without k and radius, which are not read).
    let vertex = world_point(link_vertices[range.link_offset + local], vec2<u32>(0u, instance), instances[instance]);
    var total = 0.0;
    // Σ w·I_j·f_d(v, l_j): what the links' own lights give the vertex.
    var ed = vec3<f32>(0.0);
    var ld = vec3<f32>(0.0);
    var id = vec3<f32>(0.0);
    var ls = vec3<f32>(0.0);
    var is = vec3<f32>(0.0);
    for (var j = 0u; j < 8u; j++) {
        let link = packed[j / 4u][j % 4u];
        let w = f32(link >> 16u) / 65535.0;
        if (w <= 0.0) {
            continue;
        }
        let p = range.point_offset + (link & 0xffffu);
        let point_meta = points_meta[p];
        let point = world_point(points_model[p], point_meta, instances[point_meta.y]);
        let lights = decode_lights(point.position, point_diffuse[p], point_glossy[p], point_extra[p]);
        total += w;
        ld += w * lights.diffuse_position;
        id += w * lights.diffuse;
        ed += w * lights.diffuse * diffuse_point_factor(vertex.position, vertex.normal, lights.diffuse_position);
        ls += w * lights.glossy_position;
        is += w * lights.glossy;
    }
    if (total < WEIGHT_EPSILON) {
        vertex_lights[v * 3u] = vec4<f32>(0.0);
        vertex_lights[v * 3u + 1u] = vec4<f32>(0.0);
        vertex_lights[v * 3u + 2u] = vec4<f32>(0.0);
        return;
    }
    ld /= total;
    id /= total;
    ls /= total;
    is /= total;
    let f = diffuse_point_factor(vertex.position, vertex.normal, ld);
    if (f > 0.0) {
        id = min(id, BLEND_GAIN_MAX * ed / (total * f));
    }
    vertex_lights[v * 3u] = vec4<f32>(ld, id.r);
    vertex_lights[v * 3u + 1u] = vec4<f32>(id.gb, ls.xy);
    vertex_lights[v * 3u + 2u] = vec4<f32>(ls.z, is);
}
