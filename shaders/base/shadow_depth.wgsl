// Depth-only rendering of every instance into one layer of the shadow-map array.
#include "common.wgsl"

@group(0) @binding(0) var<uniform> view: ShadowView;
@group(0) @binding(1) var<storage, read> instances: array<InstanceData>;

@vertex
fn vs_main(@location(0) position_model: vec3<f32>, @builtin(instance_index) instance: u32) -> @builtin(position) vec4<f32> {
    let position_world = instances[instance].world_from_model * vec4<f32>(position_model, 1.0);
    return view.clip_from_world * position_world;
}
