// A trivial kernel that only chains fused multiply-adds: the device's FMA throughput, the
// yardstick the benchmark holds the gather's throughput against. Four independent vec4 chains
// per thread keep the pipelines full; the result is stored so nothing is optimized away.
// The loop body is written out eight times (FMAS_PER_ITERATION = 4 chains × 4 lanes × 8 in
// `src/gpu/peak.rs`): with one step per iteration llvmpipe spent more than half the time on
// the loop itself (its exit mask, its iteration limit), and the "peak" read 26.7 GFMA/s on a
// 2-core machine whose FMA units give 61 with this body (16 copies measured 53).

struct FmaParams {
    iterations: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<uniform> params: FmaParams;
@group(0) @binding(1) var<storage, read_write> sink: array<vec4<f32>>;

@compute @workgroup_size(256, 1, 1)
fn cs_main(@builtin(global_invocation_id) id: vec3<u32>) {
    let seed = f32(id.x) * 1e-7;
    var a = vec4<f32>(seed, 1.0, 0.5, 0.25);
    var b = vec4<f32>(0.75, seed, 0.125, 0.5);
    var c = vec4<f32>(0.3, 0.6, seed, 0.9);
    var d = vec4<f32>(0.2, 0.4, 0.8, seed);
    let m = vec4<f32>(0.99999);
    let k = vec4<f32>(1e-5);
    for (var i = 0u; i < params.iterations; i++) {
        a = fma(a, m, k);
        b = fma(b, m, k);
        c = fma(c, m, k);
        d = fma(d, m, k);
        a = fma(a, m, k);
        b = fma(b, m, k);
        c = fma(c, m, k);
        d = fma(d, m, k);
        a = fma(a, m, k);
        b = fma(b, m, k);
        c = fma(c, m, k);
        d = fma(d, m, k);
        a = fma(a, m, k);
        b = fma(b, m, k);
        c = fma(c, m, k);
        d = fma(d, m, k);
        a = fma(a, m, k);
        b = fma(b, m, k);
        c = fma(c, m, k);
        d = fma(d, m, k);
        a = fma(a, m, k);
        b = fma(b, m, k);
        c = fma(c, m, k);
        d = fma(d, m, k);
        a = fma(a, m, k);
        b = fma(b, m, k);
        c = fma(c, m, k);
        d = fma(d, m, k);
        a = fma(a, m, k);
        b = fma(b, m, k);
        c = fma(c, m, k);
        d = fma(d, m, k);
    }
    sink[id.x] = a + b + c + d;
}
