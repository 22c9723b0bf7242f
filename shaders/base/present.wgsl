// Draws one view's resolved output into a window region with the PNG tone map of
// `image_io` (radiance · 2^exposure, clamped, sRGB OETF), so the window shows what
// `valgi render` writes. The viewport is the view's region and has the view's size, so each
// fragment reads exactly one output texel. With `difference` set (the reference debug view) it
// draws the signed luminance difference to the cached path-traced reference of the same
// components instead: red where the method is brighter, blue where it is darker, through the
// same tone map, so a difference reads on the image's own scale.

struct PresentParams {
    // 2^exposure.
    exposure_scale: f32,
    // Bit 0: direct light, bit 1: indirect light.
    components: u32,
    // 1 when the target stores encoded values (a non-sRGB surface format); 0 when the
    // format's hardware encode applies the OETF.
    encode_srgb: u32,
    // 1: draw method − reference (luminance; red > 0, blue < 0) instead of the method.
    difference: u32,
    // Top-left pixel of the view's region in the target.
    origin: vec2<u32>,
    size: vec2<u32>,
}

@group(0) @binding(0) var<uniform> params: PresentParams;
@group(0) @binding(1) var output_direct: texture_2d<f32>;
@group(0) @binding(2) var output_indirect: texture_2d<f32>;
// The reference of the view (the view's size), or 1×1 black textures when there is none.
@group(0) @binding(3) var reference_direct: texture_2d<f32>;
@group(0) @binding(4) var reference_indirect: texture_2d<f32>;

#include "fullscreen.wgsl"

fn srgb_oetf(x: f32) -> f32 {
    if (x <= 0.0031308) {
        return 12.92 * x;
    }
    return 1.055 * pow(x, 1.0 / 2.4) - 0.055;
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    // Fragment positions are in target pixels, not relative to the viewport.
    let texel = vec2<u32>(in.position.xy) - params.origin;
    let clamped = min(texel, params.size - vec2<u32>(1u));
    var radiance = vec3<f32>(0.0);
    if ((params.components & 1u) != 0u) {
        radiance += textureLoad(output_direct, clamped, 0).rgb;
    }
    if ((params.components & 2u) != 0u) {
        radiance += textureLoad(output_indirect, clamped, 0).rgb;
    }
    if (params.difference != 0u) {
        var reference = vec3<f32>(0.0);
        if ((params.components & 1u) != 0u) {
            reference += textureLoad(reference_direct, clamped, 0).rgb;
        }
        if ((params.components & 2u) != 0u) {
            reference += textureLoad(reference_indirect, clamped, 0).rgb;
        }
        let luminance = vec3<f32>(0.2126, 0.7152, 0.0722);
        let d = dot(radiance, luminance) - dot(reference, luminance);
        radiance = vec3<f32>(max(d, 0.0), 0.0, max(-d, 0.0));
    }
    // Non-finite channels are written as black, as `Image::sanitize` does for files.
    let finite = (radiance == radiance) & (abs(radiance) <= vec3<f32>(3.0e38));
    let sanitized = select(vec3<f32>(0.0), radiance, finite);
    var mapped = clamp(sanitized * params.exposure_scale, vec3<f32>(0.0), vec3<f32>(1.0));
    if (params.encode_srgb != 0u) {
        mapped = vec3<f32>(srgb_oetf(mapped.r), srgb_oetf(mapped.g), srgb_oetf(mapped.b));
    }
    return vec4<f32>(mapped, 1.0);
}
