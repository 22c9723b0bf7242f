// Light atlas lookup: rasterizes the light-map meshes from the camera and writes, per pixel,
// the atlas irradiance E (W/m²) at the surface's light-map UV. Bilinear filtering by hand
// (rgba32float is not filterable everywhere); texel centres sit at (i + 0.5) / R. Taps the
// pixel cannot reach without crossing a contact cut (where a wall stands on the floor) are
// left out and the other weights renormalized. CPU twin: `atlas::cuts::lookup`.
// `fs_debug` is the viewer's atlas debug view (`valgi view --debug atlas`): false colours in
// place of the irradiance, which the apply pass then writes as they are.

struct AtlasFrame {
    clip_from_world: mat4x4<f32>,
    atlas_size: vec2<u32>,
    pad: vec2<u32>,
}

@group(0) @binding(0) var<uniform> frame: AtlasFrame;
@group(0) @binding(1) var<storage, read> world_from_model: array<mat4x4<f32>>;
@group(0) @binding(2) var atlas: texture_2d<f32>;
// Per texel up to two cut pieces, texel-local endpoints in 1/255 steps (`cuts::pack_segment`).
@group(0) @binding(3) var cuts: texture_2d<u32>;

struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) uv: vec2<f32>,
}

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) uv: vec2<f32>,
    // The light-map mesh drawn (one per chart mesh of the layout).
    @location(1) @interpolate(flat) mesh: u32,
}

@vertex
fn vs_main(v: VertexIn, @builtin(instance_index) instance: u32) -> VertexOut {
    var out: VertexOut;
    let world = world_from_model[instance] * vec4<f32>(v.position, 1.0);
    out.clip = frame.clip_from_world * world;
    out.uv = v.uv;
    out.mesh = instance;
    return out;
}

fn clamped(p: vec2<i32>) -> vec2<i32> {
    return clamp(p, vec2<i32>(0), vec2<i32>(frame.atlas_size) - 1);
}

fn atlas_texel(p: vec2<i32>) -> vec3<f32> {
    return textureLoad(atlas, clamped(p), 0).rgb;
}

fn perp_dot(a: vec2<f32>, b: vec2<f32>) -> f32 {
    return a.x * b.y - a.y * b.x;
}

// Same test as `cuts::path_crosses`.
fn path_crosses(p: vec2<f32>, q: vec2<f32>, a: vec2<f32>, b: vec2<f32>) -> bool {
    let ab = b - a;
    let pq = q - p;
    let side_p = perp_dot(ab, p - a);
    let side_q = perp_dot(ab, q - a);
    let side_a = perp_dot(pq, a - p);
    let side_b = perp_dot(pq, b - p);
    return side_p * side_q < 0.0 && side_a * side_b <= 0.0;
}

const TAPS = array<vec2<i32>, 4>(vec2<i32>(0, 0), vec2<i32>(1, 0), vec2<i32>(0, 1), vec2<i32>(1, 1));

// Which of the four bilinear taps around p (texel units, centres at integers; `base` =
// floor(p)) the pixel reaches without crossing a contact cut piece of their texels.
fn reachable_taps(p: vec2<f32>, base: vec2<f32>) -> vec4<bool> {
    let b = vec2<i32>(base);
    // The cut pieces of the four texels (a straight path from p to a tap stays inside them).
    var piece_a: array<vec2<f32>, 8>;
    var piece_b: array<vec2<f32>, 8>;
    var pieces = 0u;
    for (var k = 0u; k < 4u; k++) {
        let t = clamped(b + TAPS[k]);
        let packed = textureLoad(cuts, t, 0).rg;
        let origin = vec2<f32>(t) - 0.5;
        for (var s = 0u; s < 2u; s++) {
            let v = packed[s];
            let a = vec2<f32>(f32(v & 0xffu), f32((v >> 8u) & 0xffu)) / 255.0;
            let e = vec2<f32>(f32((v >> 16u) & 0xffu), f32(v >> 24u)) / 255.0;
            if any(a != e) {
                piece_a[pieces] = origin + a;
                piece_b[pieces] = origin + e;
                pieces++;
            }
        }
    }
    var reach = vec4<bool>(true);
    for (var k = 0u; k < 4u; k++) {
        let centre = base + vec2<f32>(TAPS[k]);
        for (var s = 0u; s < pieces; s++) {
            if path_crosses(p, centre, piece_a[s], piece_b[s]) {
                reach[k] = false;
            }
        }
    }
    return reach;
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    // Texel units with texel centres at integers.
    let p = in.uv * vec2<f32>(frame.atlas_size) - 0.5;
    let base = floor(p);
    let f = p - base;
    let b = vec2<i32>(base);
    let weights = array<f32, 4>((1.0 - f.x) * (1.0 - f.y), f.x * (1.0 - f.y), (1.0 - f.x) * f.y, f.x * f.y);
    let reach = reachable_taps(p, base);
    var sum = vec3<f32>(0.0);
    var plain = vec3<f32>(0.0);
    var total = 0.0;
    for (var k = 0u; k < 4u; k++) {
        let v = atlas_texel(b + TAPS[k]);
        plain += v * weights[k];
        if reach[k] {
            sum += v * weights[k];
            total += weights[k];
        }
    }
    if total > 1e-6 {
        return vec4<f32>(sum / total, 1.0);
    }
    return vec4<f32>(plain, 1.0);
}

// A hue per chart mesh (golden-ratio steps round the colour wheel), saturation 0.6.
fn chart_colour(mesh: u32) -> vec3<f32> {
    let h = fract(f32(mesh) * 0.6180340) * 6.0;
    let c = vec3<f32>(abs(h - 3.0) - 1.0, 2.0 - abs(h - 2.0), 2.0 - abs(h - 4.0));
    return mix(vec3<f32>(1.0), clamp(c, vec3<f32>(0.0), vec3<f32>(1.0)), 0.6);
}

// The atlas debug view. Each chart mesh has its hue; the texel under the pixel is a square of
// a checkerboard (full or 0.6 brightness), so the texel size on the surface shows; a pixel
// whose texel holds no surface point (alpha 0: off the charts, a dilated value) is magenta,
// a hole in the coverage; where some bilinear tap is off the charts or behind a contact cut
// (the seams, where the lookup renormalizes its weights) the colour is mixed halfway to
// white.
@fragment
fn fs_debug(in: VertexOut) -> @location(0) vec4<f32> {
    let p = in.uv * vec2<f32>(frame.atlas_size) - 0.5;
    let base = floor(p);
    let b = vec2<i32>(base);
    let texel = clamped(vec2<i32>(floor(in.uv * vec2<f32>(frame.atlas_size))));
    if (textureLoad(atlas, texel, 0).a <= 0.0) {
        return vec4<f32>(1.0, 0.0, 1.0, 1.0);
    }
    let checker = select(0.6, 1.0, ((texel.x + texel.y) & 1) == 0);
    var colour = chart_colour(in.mesh) * checker;
    let reach = reachable_taps(p, base);
    var seam = false;
    for (var k = 0u; k < 4u; k++) {
        let covered = textureLoad(atlas, clamped(b + TAPS[k]), 0).a > 0.0;
        seam = seam || !covered || !reach[k];
    }
    if (seam) {
        colour = mix(colour, vec3<f32>(1.0), 0.5);
    }
    return vec4<f32>(colour, 1.0);
}
