//! The WGSL sources, embedded in the binary. They live under `shaders/<part>/`, one folder
//! per part that owns them (base, light, vals, brute, lpv, atlas, bench, negative,
//! mixed_reality), and are named by
//! file name. A line `#include "file.wgsl"` is replaced by that file's text (once per
//! shader), because WGSL has no include of its own; tests validate every resolved shader
//! with naga.

/// Every shader file, by name.
pub const FILES: &[(&str, &str)] = &[
    ("common.wgsl", include_str!("../shaders/base/common.wgsl")),
    (
        "shadow_depth.wgsl",
        include_str!("../shaders/base/shadow_depth.wgsl"),
    ),
    ("gbuffer.wgsl", include_str!("../shaders/base/gbuffer.wgsl")),
    (
        "direct_light.wgsl",
        include_str!("../shaders/base/direct_light.wgsl"),
    ),
    ("resolve.wgsl", include_str!("../shaders/base/resolve.wgsl")),
    ("bvh.wgsl", include_str!("../shaders/base/bvh.wgsl")),
    ("present.wgsl", include_str!("../shaders/base/present.wgsl")),
    (
        "fullscreen.wgsl",
        include_str!("../shaders/base/fullscreen.wgsl"),
    ),
    (
        "panel_layer.wgsl",
        include_str!("../shaders/base/panel_layer.wgsl"),
    ),
    (
        "vals_visibility.wgsl",
        include_str!("../shaders/vals/vals_visibility.wgsl"),
    ),
    (
        "vals_common.wgsl",
        include_str!("../shaders/vals/vals_common.wgsl"),
    ),
    (
        "vals_rsm.wgsl",
        include_str!("../shaders/light/vals_rsm.wgsl"),
    ),
    (
        "vals_from_rsm.wgsl",
        include_str!("../shaders/light/vals_from_rsm.wgsl"),
    ),
    (
        "val_windows.wgsl",
        include_str!("../shaders/light/val_windows.wgsl"),
    ),
    (
        "vals_append.wgsl",
        include_str!("../shaders/light/vals_append.wgsl"),
    ),
    (
        "sensor_occluder.wgsl",
        include_str!("../shaders/light/sensor_occluder.wgsl"),
    ),
    (
        "sensor_strata.wgsl",
        include_str!("../shaders/light/sensor_strata.wgsl"),
    ),
    (
        "depth_vals.wgsl",
        include_str!("../shaders/mixed_reality/depth_vals.wgsl"),
    ),
    (
        "vals_gather.wgsl",
        include_str!("../shaders/vals/vals_gather.wgsl"),
    ),
    (
        "vals_gather_common.wgsl",
        include_str!("../shaders/vals/vals_gather_common.wgsl"),
    ),
    (
        "vals_gather_partials.wgsl",
        include_str!("../shaders/vals/vals_gather_partials.wgsl"),
    ),
    (
        "vals_gather_reduce.wgsl",
        include_str!("../shaders/vals/vals_gather_reduce.wgsl"),
    ),
    (
        "vals_gather_raster.wgsl",
        include_str!("../shaders/vals/vals_gather_raster.wgsl"),
    ),
    (
        "vals_renormalize.wgsl",
        include_str!("../shaders/vals/vals_renormalize.wgsl"),
    ),
    (
        "vals_occlusion.wgsl",
        include_str!("../shaders/vals/vals_occlusion.wgsl"),
    ),
    (
        "vals_occluder_bounds.wgsl",
        include_str!("../shaders/vals/vals_occluder_bounds.wgsl"),
    ),
    (
        "vals_interpolate.wgsl",
        include_str!("../shaders/vals/vals_interpolate.wgsl"),
    ),
    (
        "vals_apply.wgsl",
        include_str!("../shaders/vals/vals_apply.wgsl"),
    ),
    (
        "vals_debug_splats.wgsl",
        include_str!("../shaders/vals/vals_debug_splats.wgsl"),
    ),
    (
        "vals_debug_occluders.wgsl",
        include_str!("../shaders/vals/vals_debug_occluders.wgsl"),
    ),
    (
        "vals_occluder_share.wgsl",
        include_str!("../shaders/vals/vals_occluder_share.wgsl"),
    ),
    (
        "debug_lines.wgsl",
        include_str!("../shaders/base/debug_lines.wgsl"),
    ),
    (
        "negative_common.wgsl",
        include_str!("../shaders/negative/negative_common.wgsl"),
    ),
    (
        "negative_positives.wgsl",
        include_str!("../shaders/negative/negative_positives.wgsl"),
    ),
    (
        "negative_view.wgsl",
        include_str!("../shaders/negative/negative_view.wgsl"),
    ),
    (
        "brute_vals.wgsl",
        include_str!("../shaders/brute/brute_vals.wgsl"),
    ),
    (
        "bench_fma.wgsl",
        include_str!("../shaders/bench/bench_fma.wgsl"),
    ),
    (
        "atlas_render.wgsl",
        include_str!("../shaders/atlas/atlas_render.wgsl"),
    ),
    (
        "atlas_apply.wgsl",
        include_str!("../shaders/atlas/atlas_apply.wgsl"),
    ),
    (
        "lpv_common.wgsl",
        include_str!("../shaders/lpv/lpv_common.wgsl"),
    ),
    (
        "lpv_inject.wgsl",
        include_str!("../shaders/lpv/lpv_inject.wgsl"),
    ),
    (
        "lpv_geometry.wgsl",
        include_str!("../shaders/lpv/lpv_geometry.wgsl"),
    ),
    (
        "lpv_propagate.wgsl",
        include_str!("../shaders/lpv/lpv_propagate.wgsl"),
    ),
    (
        "lpv_propagate_cell.wgsl",
        include_str!("../shaders/lpv/lpv_propagate_cell.wgsl"),
    ),
    (
        "lpv_faces.wgsl",
        include_str!("../shaders/lpv/lpv_faces.wgsl"),
    ),
    (
        "lpv_pack.wgsl",
        include_str!("../shaders/lpv/lpv_pack.wgsl"),
    ),
    (
        "lpv_lookup.wgsl",
        include_str!("../shaders/lpv/lpv_lookup.wgsl"),
    ),
];

/// Files that are only included by others (no entry points of their own).
pub const INCLUDES: &[&str] = &[
    "common.wgsl",
    "vals_common.wgsl",
    "vals_gather_common.wgsl",
    "lpv_common.wgsl",
];

fn raw(name: &str) -> &'static str {
    let embedded = FILES
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, s)| *s)
        .unwrap_or_else(|| panic!("shader '{name}' is not listed in shaders::FILES"));
    match std::env::var_os(SHADER_DIR_VAR) {
        Some(dir) => from_dir(std::path::Path::new(&dir), name).unwrap_or(embedded),
        None => embedded,
    }
}

/// Names a `shaders/` folder whose files replace the embedded ones at run time, so that a
/// shader can be edited and timed without rebuilding the binary (a release build of the
/// crate takes minutes). A development aid: the embedded text is what ships and what the
/// tests validate.
pub const SHADER_DIR_VAR: &str = "VALGI_SHADER_DIR";

/// `dir/<part>/name`, read once per process (the text must live as long as the embedded one).
fn from_dir(dir: &std::path::Path, name: &str) -> Option<&'static str> {
    use std::collections::HashMap;
    use std::sync::{Mutex, OnceLock};
    static CACHE: OnceLock<Mutex<HashMap<String, &'static str>>> = OnceLock::new();
    let mut cache = CACHE.get_or_init(Default::default).lock().ok()?;
    if let Some(text) = cache.get(name) {
        return Some(text);
    }
    let text = std::fs::read_dir(dir)
        .ok()?
        .flatten()
        .find_map(|part| std::fs::read_to_string(part.path().join(name)).ok())?;
    let text: &'static str = Box::leak(text.into_boxed_str());
    cache.insert(name.to_string(), text);
    Some(text)
}

/// The shader's source with its includes resolved.
pub fn source(name: &str) -> String {
    let mut seen = Vec::new();
    let mut out = String::new();
    expand(name, &mut seen, &mut out);
    out
}

fn expand(name: &str, seen: &mut Vec<String>, out: &mut String) {
    if seen.iter().any(|s| s == name) {
        return;
    }
    seen.push(name.to_string());
    for line in raw(name).lines() {
        match line.trim().strip_prefix("#include") {
            Some(rest) => expand(rest.trim().trim_matches('"'), seen, out),
            None => {
                out.push_str(line);
                out.push('\n');
            }
        }
    }
}

/// Parses and validates a shader with naga, returning the module for reflection.
pub fn validate(name: &str) -> Result<naga::Module, String> {
    let src = source(name);
    let module = naga::front::wgsl::parse_str(&src)
        .map_err(|e| format!("{name}: {}", e.emit_to_string(&src)))?;
    naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::all(),
    )
    .validate(&module)
    .map_err(|e| format!("{name}: {}", e.emit_to_string(&src)))?;
    Ok(module)
}
