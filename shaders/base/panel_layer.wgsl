// Composites the viewer's cached panel layer over the views: the layer holds egui's output
// drawn onto transparent black with egui's own premultiplied blending, so drawing it with
// (One, OneMinusSrcAlpha) gives the pixels egui would have drawn over the views directly.
// The layer has the target's size and format; each fragment reads its own texel.

@group(0) @binding(0) var layer: texture_2d<f32>;

#include "fullscreen.wgsl"

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    return textureLoad(layer, vec2<i32>(floor(in.position.xy)), 0);
}
