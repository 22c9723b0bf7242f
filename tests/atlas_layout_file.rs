//! The light-map layout stored beside a baked atlas (`FILE.exr.layout`): it is the layout the
//! scene rebuilds and renders the same image, a layout made for other geometry is refused, and
//! a damaged or foreign layout file is an error naming it.

mod common;

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use valgi::atlas::stored_layout::{self, LayoutKey, LookupLayout};
use valgi::atlas::{
    load_atlas, AtlasLayoutFile, AtlasMethod, BakeRequest, BakeSettings, LoadedAtlas,
};
use valgi::method::{Method, MethodOptions};
use valgi::raster::RenderError;
use valgi::scene::{self, builtin::BuiltinParams, Scene};

fn no_progress(_: &str, _: usize, _: usize) {}

/// `valgi bake` of a built-in scene into `dir/name.exr` (and its layout file).
fn bake_file(dir: &Path, name: &str, scene: &str, max_edge: f32, atlas_res: u32) -> PathBuf {
    let out = dir.join(format!("{name}.exr"));
    let request = BakeRequest {
        scene: scene.into(),
        max_edge,
        edits: Default::default(),
        settings: BakeSettings {
            vpls: 50,
            bounces: 1,
            atlas_res,
            near_rays: 4,
            ..Default::default()
        },
        from_bounce: 1,
        out: out.clone(),
    };
    valgi::atlas::bake_to_file(&request, &no_progress, &AtomicBool::new(false)).unwrap();
    out
}

fn load_scene(name: &str, max_edge: f32) -> Scene {
    scene::load(name, &BuiltinParams { max_edge }).unwrap()
}

fn method(
    ctx: &valgi::gpu::GpuContext,
    scene: &Scene,
    atlas: &Path,
) -> Result<AtlasMethod, RenderError> {
    let mut options = MethodOptions::default();
    options.set("atlas", atlas.display());
    AtlasMethod::new(ctx, scene, common::small_render_settings(48), &options)
}

fn stored(loaded: &LoadedAtlas) -> &stored_layout::StoredLayout {
    match &loaded.layout {
        AtlasLayoutFile::Stored { layout, .. } => layout,
        AtlasLayoutFile::Absent(why) => panic!("no stored layout: {why}"),
    }
}

fn bits(image: &valgi::image_io::Image) -> Vec<u32> {
    image.pixels.iter().flatten().map(|v| v.to_bits()).collect()
}

/// The corridor has both kinds of thing a layout adds to the unwrap: sheet faces (the
/// partition, the door) and contact cuts. The stored layout equals the one the scene
/// rebuilds, and the image rendered with it equals, bit for bit, the image rendered with the
/// rebuilt one (the same EXR without its layout file).
#[test]
fn a_stored_layout_is_the_rebuilt_one_and_renders_the_same_image() {
    let Some(ctx) = common::gpu() else { return };
    let dir = common::temp_dir("atlas-layout-round-trip");
    let (max_edge, res) = (0.1, 128);
    let atlas = bake_file(&dir, "corridor", "corridor", max_edge, res);
    assert!(stored_layout::layout_path(&atlas).exists());
    let scene = load_scene("corridor", max_edge);
    let world_from_node = scene.world_from_node();

    let loaded = load_atlas(&atlas).unwrap();
    let stored = stored(&loaded);
    let rebuilt = valgi::atlas::layout::build_layout(&scene, &world_from_node, res).unwrap();
    let rebuilt = LookupLayout::of(&rebuilt);
    assert!(rebuilt.meshes.iter().any(|m| m.sheet_face) && !rebuilt.cuts.is_empty());
    assert_eq!(
        stored.lookup, rebuilt,
        "the stored layout is the rebuilt one"
    );
    assert_eq!(stored.key, LayoutKey::of(&scene, &world_from_node, res));

    let plain = dir.join("plain.exr");
    std::fs::copy(&atlas, &plain).unwrap();
    assert!(matches!(
        load_atlas(&plain).unwrap().layout,
        AtlasLayoutFile::Absent(_)
    ));
    let camera = scene.camera_view(None, 1.0, &world_from_node).unwrap();
    let mut frames = Vec::new();
    for (path, from_file) in [(&atlas, true), (&plain, false)] {
        let mut m = method(&ctx, &scene, path).unwrap();
        assert_eq!(m.layer().layout_from_file, from_file, "{}", path.display());
        assert_eq!(m.layer().missing_texels, 0);
        frames.push(m.render(&ctx, &scene, &world_from_node, &camera).unwrap());
    }
    let lit = frames[0]
        .indirect
        .pixels
        .iter()
        .filter(|p| p[1] > 0.0)
        .count();
    // 770 of 2304: the view also holds background and the dark room behind the partition.
    assert!(lit * 5 > 48 * 48, "{lit} pixels with indirect light");
    assert_eq!(bits(&frames[0].indirect), bits(&frames[1].indirect));
    assert_eq!(bits(&frames[0].direct), bits(&frames[1].direct));
}

/// A layout made for other geometry (another scene, another `--max-edge`) is refused with a
/// message naming the layout file and what differs; the same scene is accepted; a layout made
/// by another version of the layout code for the same geometry is the one the atlas was baked
/// with, so it is used.
#[test]
fn a_layout_made_for_other_geometry_is_refused() {
    let Some(ctx) = common::gpu() else { return };
    let dir = common::temp_dir("atlas-layout-mismatch");
    let atlas = bake_file(&dir, "box", "box-point", 0.25, 64);
    let layout_file = stored_layout::layout_path(&atlas);

    let same = load_scene("box-point", 0.25);
    assert!(
        method(&ctx, &same, &atlas)
            .unwrap()
            .layer()
            .layout_from_file
    );

    let finer = load_scene("box-point", 0.125);
    let err = method(&ctx, &finer, &atlas).err().unwrap().to_string();
    assert!(
        err.contains("does not match this scene's light-map layout")
            && err.contains(&layout_file.display().to_string())
            && err.contains("triangles")
            && err.contains("--max-edge 0.25"),
        "{err}"
    );
    let cornell = load_scene("cornell", 0.25);
    let err = method(&ctx, &cornell, &atlas).err().unwrap().to_string();
    assert!(
        err.contains("does not match") && err.contains("scene 'box-point'"),
        "{err}"
    );

    // The same geometry under another layout version: rewritten with the version raised.
    let loaded = load_atlas(&atlas).unwrap();
    let mut other_version = stored(&loaded).clone();
    other_version.key.layout_version += 1;
    let versioned = dir.join("versioned.exr");
    valgi::atlas::write_atlas_with_layout(&loaded.image, &versioned, 1..=1, &other_version)
        .unwrap();
    let m = method(&ctx, &same, &versioned).unwrap();
    assert!(m.layer().layout_from_file);
}

/// A damaged or truncated layout file, and one from another bake, are errors naming the file;
/// a missing one is rebuilt from the scene.
#[test]
fn a_damaged_or_foreign_layout_file_is_a_clear_error() {
    let Some(ctx) = common::gpu() else { return };
    let dir = common::temp_dir("atlas-layout-damaged");
    let atlas = bake_file(&dir, "box", "box-point", 0.25, 64);
    let layout_file = stored_layout::layout_path(&atlas);
    let good = std::fs::read(&layout_file).unwrap();
    let named = layout_file.display().to_string();
    let error = || load_atlas(&atlas).err().unwrap().to_string();

    let mut flipped = good.clone();
    flipped[good.len() / 2] ^= 0x40;
    std::fs::write(&layout_file, &flipped).unwrap();
    let err = error();
    assert!(err.contains(&named) && err.contains("damaged"), "{err}");

    std::fs::write(&layout_file, &good[..good.len() * 2 / 3]).unwrap();
    let err = error();
    assert!(err.contains(&named) && err.contains("truncated"), "{err}");

    std::fs::write(&layout_file, b"not a layout").unwrap();
    let err = error();
    assert!(err.contains(&named) && err.contains("not a valgi"), "{err}");

    // Another bake's layout file (another --max-edge) beside this atlas.
    let other = bake_file(&dir, "other", "box-point", 0.5, 64);
    std::fs::copy(stored_layout::layout_path(&other), &layout_file).unwrap();
    let err = error();
    assert!(
        err.contains(&named) && err.contains("belongs to another bake"),
        "{err}"
    );

    std::fs::remove_file(&layout_file).unwrap();
    let loaded = load_atlas(&atlas).unwrap();
    assert!(
        matches!(&loaded.layout, AtlasLayoutFile::Absent(why) if why.contains("missing")),
        "{:?}",
        loaded.layout
    );
    let scene = load_scene("box-point", 0.25);
    let m = method(&ctx, &scene, &atlas).unwrap();
    assert!(!m.layer().layout_from_file);
}
