// The strata of a depth sensor's image tiles and their sample candidates: shared by the pass
// that fills the sensor's ray samples (`depth_vals.wgsl`) and the visibility pass that reads
// them (`sensor_occluder.wgsl`). `light::sensor::stratum_pixel` is the CPU twin.

// Strata per tile side and sample candidates per stratum, as the RSM's tiles have
// (`light::rsm::CLUSTER_SAMPLE_SIDE`, `SAMPLE_CANDIDATES`).
const CLUSTER_SAMPLE_SIDE: u32 = 4u;
const SAMPLE_CANDIDATES: u32 = 5u;

// The pixel of candidate `k` of stratum `s` of tile `tile` in a `size` image cut into
// `tiles × tiles` tiles: the stratum's centre (k = 0), then its corners (first/last column,
// first/last row). Stratum g of the image's even grid spans ⌈g·n/side⌉ .. ⌈(g+1)·n/side⌉.
fn stratum_candidate_pixel(size: vec2<u32>, tiles: u32, tile: u32, s: u32, k: u32) -> vec2<u32> {
    let side = tiles * CLUSTER_SAMPLE_SIDE;
    let g = vec2<u32>(
        (tile % tiles) * CLUSTER_SAMPLE_SIDE + s % CLUSTER_SAMPLE_SIDE,
        (tile / tiles) * CLUSTER_SAMPLE_SIDE + s / CLUSTER_SAMPLE_SIDE,
    );
    if (k == 0u) {
        return (2u * g + 1u) * size / (2u * side);
    }
    let first = (g * size + side - 1u) / side;
    let last = ((g + 1u) * size + side - 1u) / side - 1u;
    return vec2<u32>(
        select(first.x, last.x, ((k - 1u) & 1u) == 1u),
        select(first.y, last.y, ((k - 1u) >> 1u) == 1u),
    );
}
