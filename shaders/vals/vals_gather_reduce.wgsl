// Step 1b — after a gather split over VAL slices: one invocation per point adds its slices'
// partial sums (in slice order, so the result does not depend on scheduling) and writes the
// point exactly as the unsplit gather does.
#include "vals_gather_partials.wgsl"

@compute @workgroup_size(64, 1, 1)
fn cs_main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let index = linear_index(gid, groups);
    if (index >= params.point_count) {
        return;
    }
    let count = min(val_count[0], arrayLength(&vals));
    // The buffer holds exactly the slices of this dispatch's gather.
    let slices = arrayLength(&partials) / (params.point_count * PARTIAL_VEC4S);
    var sums = Sums();
    for (var slice = 0u; slice < slices; slice++) {
        partial_add(&sums, (slice * params.point_count + index) * PARTIAL_VEC4S);
    }
    let point_meta = points_meta[index];
    let point = world_point(points_model[index], point_meta, instances[point_meta.y]);
    write_point(index, point, sums, count, (params.flags & FLAG_GLOSSY) != 0u);
}
