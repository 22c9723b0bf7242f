// The vertex stage of a pass that covers its viewport with one triangle (no vertex buffers):
// `vs_main` and the `VertexOut` its fragment stage receives. Included by the full-viewport
// passes (present, panel layer).

struct VertexOut {
    @builtin(position) position: vec4<f32>,
}

// One triangle that covers the viewport.
@vertex
fn vs_main(@builtin(vertex_index) index: u32) -> VertexOut {
    let corner = vec2<f32>(f32((index << 1u) & 2u), f32(index & 2u));
    var out: VertexOut;
    out.position = vec4<f32>(corner * 2.0 - 1.0, 0.0, 1.0);
    return out;
}
