//! Methods composed of registered layers, not special cases: `sparse+atlas` is the sparse
//! method with the atlas as an [`crate::frame::IndirectLayer`] on top. This module is the
//! only place that names two techniques together; neither technique imports the other.

use std::path::Path;

use crate::atlas::{
    bake_in_memory, load_atlas, AtlasLayer, AtlasOnVals, LoadedAtlas, ATLAS_OPTION,
    FIRST_BOUNCE_ATTRIBUTE,
};
use crate::frame::{IndirectLayer, Method};
use crate::gpu::GpuContext;
use crate::method::{Entry, MethodOptions, OptionSpec};
use crate::raster::{RenderError, RenderSettings};
use crate::scene::Scene;
use crate::vals::SparseMethod;

/// Every option of the sparse method, plus the atlas file.
const SPARSE_ATLAS_OPTIONS: [OptionSpec; crate::vals::OPTIONS.len() + 1] = {
    let mut all = [ATLAS_OPTION; crate::vals::OPTIONS.len() + 1];
    let mut i = 0;
    while i < crate::vals::OPTIONS.len() {
        all[i] = crate::vals::OPTIONS[i];
        i += 1;
    }
    all
};

pub static SPARSE_ATLAS_ENTRY: Entry = Entry {
    name: "sparse+atlas",
    help: "direct + bounce 1 from the VALs (the sparse method and its options) + bounces 2.. from an atlas baked with --from-bounce 2 (without --atlas: baked in memory first)",
    options: &SPARSE_ATLAS_OPTIONS,
    create: create_sparse_atlas,
};

/// `--method sparse+atlas --atlas FILE` (every sparse option, plus `atlas`). The atlas should
/// be baked with `--from-bounce 2`: bounce 1 comes from the VALs.
pub fn create_sparse_atlas(
    ctx: &GpuContext,
    scene: &Scene,
    render: RenderSettings,
    options: &MethodOptions,
) -> Result<Box<dyn Method>, RenderError> {
    Ok(Box::new(sparse_atlas(ctx, scene, render, options)?))
}

/// [`create_sparse_atlas`] as the concrete sparse method with its atlas layer (for tests).
pub fn sparse_atlas(
    ctx: &GpuContext,
    scene: &Scene,
    render: RenderSettings,
    options: &MethodOptions,
) -> Result<SparseMethod, RenderError> {
    let path: String = options.get("atlas", String::new())?;
    if path.is_empty() {
        let atlas = bake_in_memory(scene, 2)?;
        return with_atlas(ctx, scene, render, options, &atlas);
    }
    let atlas = load_atlas(Path::new(&path))?;
    match &atlas.bounces {
        // The sparse method computes bounce 1 itself: an atlas holding it would count it twice.
        Some(bounces) if *bounces.start() == 1 => {
            return Err(RenderError::Settings(format!(
                "--atlas {path} holds bounces 1..={}, and 'sparse+atlas' computes bounce 1 \
                 itself (it would count twice): bake it with `valgi bake --from-bounce 2`",
                bounces.end()
            )))
        }
        Some(_) => {}
        None => log::warn!(
            "--atlas {path} does not say which bounces it holds (no {FIRST_BOUNCE_ATTRIBUTE} \
             header attribute); assuming it starts at bounce 2"
        ),
    }
    with_atlas(ctx, scene, render, options, &atlas)
}

/// The sparse method (every one of its options, `--quality auto` included) with `atlas`
/// (bounces from 2) as its indirect layer.
fn with_atlas(
    ctx: &GpuContext,
    scene: &Scene,
    render: RenderSettings,
    options: &MethodOptions,
    atlas: &LoadedAtlas,
) -> Result<SparseMethod, RenderError> {
    let layer = AtlasLayer::from_loaded(ctx, scene, atlas)?;
    let layer: Box<dyn IndirectLayer> = Box::new(AtlasOnVals::new(ctx, layer, "sparse+atlas"));
    // Built first: budget mode's timing pilots time the sparse light with its layer.
    SparseMethod::from_options_with_layer(ctx, scene, render, options, Some(layer))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `sparse+atlas` is the sparse method with a layer: it takes every sparse option (a
    /// user of `render`'s default passes `--occlusion`, `--quality` and the rest), and the
    /// atlas file.
    #[test]
    fn sparse_atlas_takes_every_sparse_option() {
        let names: Vec<&str> = SPARSE_ATLAS_ENTRY.options.iter().map(|o| o.name).collect();
        for spec in crate::vals::OPTIONS {
            assert!(
                names.contains(&spec.name),
                "sparse+atlas lacks {}",
                spec.name
            );
        }
        assert!(names.contains(&"atlas"));
        assert_eq!(names.len(), crate::vals::OPTIONS.len() + 1);
    }
}
