// One occluder disc's share of a point's light sphere (DESIGN §4, the paper's occlusion):
// seen from x, the sphere and the disc are projected onto x's unit tangent disc and treated as
// axis-aligned squares of their projected areas; the disc hides overlap / sphere area of the
// light, ramped to 0 between the sphere's front and its centre. Shared by the occlusion pass
// and the viewer's occluder view; CPU twin `vals::math::occluder_share`.
#include "vals_common.wgsl"

struct Disc {
    // xyz: centre; w: radius.
    center_radius: vec4<f32>,
    normal: vec4<f32>,
}

fn square_overlap(a: vec2<f32>, area_a: f32, b: vec2<f32>, area_b: f32) -> f32 {
    let ha = 0.5 * sqrt(area_a);
    let hb = 0.5 * sqrt(area_b);
    let o = max(min(a + ha, b + hb) - max(a - ha, b - hb), vec2<f32>(0.0));
    return o.x * o.y;
}

// One disc's share of the sphere (centre `light`, radius `sphere`) as seen from x.
fn occluder_share(x: vec3<f32>, n: vec3<f32>, t: vec3<f32>, b: vec3<f32>, light: vec3<f32>, sphere: f32, disc: Disc) -> f32 {
    let to_light = light - x;
    let light_distance = length(to_light);
    let to_disc = disc.center_radius.xyz - x;
    let disc_distance = length(to_disc);
    let radius = disc.center_radius.w;
    if (sphere <= 0.0 || light_distance <= 0.0 || disc_distance <= 0.0 || radius <= 0.0) {
        return 0.0;
    }
    let wl = to_light / light_distance;
    let wd = to_disc / disc_distance;
    if (dot(n, wd) <= 0.0 || disc_distance >= light_distance) {
        return 0.0;
    }
    let ramp = min((light_distance - disc_distance) / sphere, 1.0);
    let sphere_area = PI * sphere * sphere / (sphere * sphere + light_distance * light_distance);
    let disc_area = PI * radius * radius / (radius * radius + disc_distance * disc_distance) * abs(dot(disc.normal.xyz, wd));
    let overlap = square_overlap(vec2<f32>(dot(wl, t), dot(wl, b)), sphere_area, vec2<f32>(dot(wd, t), dot(wd, b)), disc_area);
    return min(overlap / sphere_area, 1.0) * ramp;
}
