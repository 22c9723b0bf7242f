//! The static base: a multi-bounce light atlas (seed 000, DESIGN §5). `bake` computes it on
//! the CPU; [`AtlasLayer`] looks it up on the GPU and writes indirect radiance ρ_d/π·E; the
//! `atlas` method is direct light plus that layer. See `src/atlas/README.md`.

pub mod bake;
pub mod bench;
pub mod compose;
pub mod cuts;
pub mod depth;
pub mod layout;
pub mod patches;
pub mod polygon;
pub mod stored_layout;

use std::path::Path;
use std::sync::{Arc, Mutex};

use bytemuck::{Pod, Zeroable};
use glam::Mat4;

pub use bake::{bake, Bake, BakeError, BakeSettings, Baker, EnergyAccount, Lights};
pub use compose::AtlasOnVals;

use crate::frame::{FrameInput, Method, View, ViewCache, ViewResult};
use crate::gpu::bindings::{GroupLayout, Slot};
use crate::gpu::{GpuBytes, GpuContext, Passes};
use crate::image_io::Image;
use crate::method::{Entry, MethodOptions, OptionKind, OptionSpec};
use crate::raster::{
    compute_pipeline, Rasterizer, RenderError, RenderSettings, DEPTH_FORMAT, RADIANCE_FORMAT,
};

/// `atlas_render.wgsl`: the view's frame (vertex and fragment), the light-map meshes'
/// transforms, the atlas and its contact cuts.
const LOOKUP_BINDINGS: &[Slot] = &[
    Slot::Uniform,
    Slot::Storage,
    Slot::Texture,
    Slot::UintTexture,
];

/// `atlas_apply.wgsl`'s `cs_main`: parameters, the looked-up irradiance, the G-buffer's
/// diffuse albedo and the indirect target.
const APPLY_BINDINGS: &[Slot] = &[
    Slot::Uniform,
    Slot::Texture,
    Slot::Texture,
    Slot::StorageTexture(RADIANCE_FORMAT),
];

/// `cs_add`: [`APPLY_BINDINGS`] plus the underlying method's indirect light it adds to.
pub(crate) const ADD_BINDINGS: &[Slot] = &[
    Slot::Uniform,
    Slot::Texture,
    Slot::Texture,
    Slot::StorageTexture(RADIANCE_FORMAT),
    Slot::Texture,
];
use crate::scene::Scene;

/// One `valgi bake` invocation.
#[derive(Clone, Debug)]
pub struct BakeRequest {
    /// Built-in scene name or a `.gltf`/`.glb` path.
    pub scene: String,
    /// Built-in scenes' tessellation; render with the same value (the layout depends on it).
    pub max_edge: f32,
    /// Lights added to the scene (`--light`); render with the same ones.
    pub edits: crate::scene::edits::SceneEdits,
    pub settings: BakeSettings,
    /// First bounce written (1 = all); bounces `from_bounce..=bounces` go into the file.
    pub from_bounce: u32,
    pub out: std::path::PathBuf,
}

/// Loads the scene, bakes, and writes the atlas EXR (through a temporary file renamed into
/// place, so a failed or cancelled bake leaves no file). Returns the JSON summary.
pub fn bake_to_file(
    request: &BakeRequest,
    progress: bake::Progress,
    cancel: &std::sync::atomic::AtomicBool,
) -> Result<serde_json::Value, BakeError> {
    let started = std::time::Instant::now();
    if !matches!(
        request
            .out
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .as_deref(),
        Some("exr")
    ) {
        return Err(BakeError::Settings(format!(
            "{}: the atlas is written as .exr",
            request.out.display()
        )));
    }
    crate::image_io::prepare_output(&request.out)?;
    request.settings.check_budget()?;
    if request.from_bounce == 0 || request.from_bounce > request.settings.bounces {
        return Err(BakeError::Settings(format!(
            "--from-bounce {} must be between 1 and --bounces {}",
            request.from_bounce, request.settings.bounces
        )));
    }
    let mut scene = crate::scene::load(
        &request.scene,
        &crate::scene::builtin::BuiltinParams {
            max_edge: request.max_edge,
        },
    )?;
    request.edits.apply(&mut scene, None, 1.0)?;
    let world_from_node = scene.world_from_node();
    let result = bake(
        &scene,
        &world_from_node,
        &request.settings,
        progress,
        cancel,
    )?;
    let image = result.atlas(request.from_bounce, request.settings.bounces);
    if cancel.load(std::sync::atomic::Ordering::Relaxed) {
        return Err(BakeError::Cancelled);
    }
    let write_started = std::time::Instant::now();
    let stored = stored_layout::StoredLayout::of_bake(
        &result,
        &scene,
        &world_from_node,
        Some(request.max_edge),
    );
    write_atlas_with_layout(
        &image,
        &request.out,
        request.from_bounce..=request.settings.bounces,
        &stored,
    )?;
    let mut summary = result.summary();
    if let Some(obj) = summary.as_object_mut() {
        obj.insert("scene".into(), serde_json::json!(scene.name));
        obj.insert("from_bounce".into(), serde_json::json!(request.from_bounce));
        obj.insert(
            "out".into(),
            serde_json::json!(request.out.display().to_string()),
        );
        if let Some(stages) = obj.get_mut("stages_ms").and_then(|s| s.as_object_mut()) {
            stages.insert(
                "write".into(),
                serde_json::json!(write_started.elapsed().as_secs_f64() * 1000.0),
            );
        }
        obj.insert(
            "wall_ms".into(),
            serde_json::json!((started.elapsed().as_secs_f64() * 1e6).round() / 1000.0),
        );
    }
    Ok(summary)
}

/// Mirrors `AtlasFrame` in `shaders/atlas/atlas_render.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct AtlasFrame {
    pub clip_from_world: [[f32; 4]; 4],
    pub atlas_size: [u32; 2],
    pub pad: [u32; 2],
}

/// Mirrors `ApplyParams` in `shaders/atlas/atlas_apply.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct ApplyParams {
    pub render_size: [u32; 2],
    pub debug: u32,
    pub pad: u32,
}

/// The atlas's structs shared with WGSL, for the layout test (same form as
/// `raster::types::shared_layouts`).
pub fn shared_layouts() -> Vec<crate::raster::types::SharedLayout> {
    use crate::raster::types::SharedLayout;
    use std::mem::{offset_of, size_of};
    vec![
        SharedLayout {
            wgsl_name: "AtlasFrame",
            file: "atlas_render.wgsl",
            size: size_of::<AtlasFrame>(),
            fields: vec![
                ("clip_from_world", offset_of!(AtlasFrame, clip_from_world)),
                ("atlas_size", offset_of!(AtlasFrame, atlas_size)),
                ("pad", offset_of!(AtlasFrame, pad)),
            ],
        },
        SharedLayout {
            wgsl_name: "ApplyParams",
            file: "atlas_apply.wgsl",
            size: size_of::<ApplyParams>(),
            fields: vec![
                ("render_size", offset_of!(ApplyParams, render_size)),
                ("debug", offset_of!(ApplyParams, debug)),
                ("pad", offset_of!(ApplyParams, pad)),
            ],
        },
    ]
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct AtlasVertex {
    position: [f32; 3],
    uv: [f32; 2],
}

struct LayerMesh {
    vertices: wgpu::Buffer,
    indices: wgpu::Buffer,
    index_count: u32,
    node: usize,
    /// One face of a two-sided sheet: drawn with back faces culled.
    sheet_face: bool,
}

/// EXR header attributes of a baked atlas: the first and last bounce it holds.
pub const FIRST_BOUNCE_ATTRIBUTE: &str = "valgiFirstBounce";
pub const LAST_BOUNCE_ATTRIBUTE: &str = "valgiLastBounce";

/// Writes a baked atlas: its light-map layout file (`FILE.exr.layout`, [`stored_layout`])
/// first, then the EXR with the bounce range and the layout file's checksum in its header.
/// Both go through temporary files renamed into place; when the EXR cannot be written, the
/// layout file is removed again.
pub fn write_atlas_with_layout(
    image: &Image,
    path: &Path,
    bounces: std::ops::RangeInclusive<u32>,
    layout: &stored_layout::StoredLayout,
) -> Result<(), crate::image_io::ImageError> {
    let checksum = stored_layout::write(path, layout)?;
    let written = image.write_exr_with(
        path,
        &[
            (FIRST_BOUNCE_ATTRIBUTE, *bounces.start() as i32),
            (LAST_BOUNCE_ATTRIBUTE, *bounces.end() as i32),
            (
                stored_layout::LAYOUT_CHECKSUM_ATTRIBUTE,
                i32::from_le_bytes(checksum.to_le_bytes()),
            ),
        ],
    );
    if written.is_err() {
        // Without its atlas the layout file would only ever be refused as another bake's.
        let _ = std::fs::remove_file(stored_layout::layout_path(path));
    }
    written
}

/// Where an atlas's light-map layout comes from.
#[derive(Debug)]
pub enum AtlasLayoutFile {
    /// Read from the layout file beside the atlas (its checksum is the one the atlas's header
    /// names).
    Stored {
        path: std::path::PathBuf,
        layout: Box<stored_layout::StoredLayout>,
    },
    /// None stored (why, for the warning): the layout is rebuilt from the scene.
    Absent(String),
}

/// An atlas read from disk.
pub struct LoadedAtlas {
    pub path: std::path::PathBuf,
    pub image: Image,
    /// The bounces it holds, from its header; `None` for a file without them (written before
    /// the range was stored, or by another tool).
    pub bounces: Option<std::ops::RangeInclusive<u32>>,
    pub layout: AtlasLayoutFile,
}

/// Reads an atlas EXR written by `valgi bake`, with its bounce range and its stored layout. A
/// layout file that is damaged, or that belongs to another bake than the EXR's header names,
/// is an error; a missing one (an atlas baked before layouts were stored) is not.
pub fn load_atlas(path: &Path) -> Result<LoadedAtlas, RenderError> {
    let fail = |e: crate::image_io::ImageError| RenderError::Settings(format!("--atlas: {e}"));
    let image = Image::read_exr(path).map_err(fail)?;
    let attribute = |name: &str| crate::image_io::read_exr_int_attribute(path, name).map_err(fail);
    let first = attribute(FIRST_BOUNCE_ATTRIBUTE)?;
    let last = attribute(LAST_BOUNCE_ATTRIBUTE)?;
    let bounces = match (first, last) {
        (Some(first), Some(last)) if 1 <= first && first <= last => {
            Some(first as u32..=last as u32)
        }
        _ => None,
    };
    let layout_path = stored_layout::layout_path(path);
    let layout = match attribute(stored_layout::LAYOUT_CHECKSUM_ATTRIBUTE)? {
        None => AtlasLayoutFile::Absent(format!(
            "its header has no {} attribute: baked before layouts were stored, or written by \
             another tool",
            stored_layout::LAYOUT_CHECKSUM_ATTRIBUTE
        )),
        Some(_) if !layout_path.exists() => {
            AtlasLayoutFile::Absent(format!("{} is missing", layout_path.display()))
        }
        Some(named) => {
            let named = u32::from_le_bytes(named.to_le_bytes());
            let (layout, checksum) = stored_layout::read(&layout_path)
                .map_err(|e| RenderError::Settings(format!("--atlas {}: {e}", path.display())))?;
            if checksum != named {
                return Err(RenderError::Settings(format!(
                    "--atlas {}: {} belongs to another bake (checksum {checksum:08x}, the \
                     atlas's header names {named:08x}): bake the atlas again, or delete the \
                     layout file to rebuild the layout from the scene",
                    path.display(),
                    layout_path.display()
                )));
            }
            AtlasLayoutFile::Stored {
                path: layout_path,
                layout: Box::new(layout),
            }
        }
    };
    Ok(LoadedAtlas {
        path: path.to_path_buf(),
        image,
        bounces,
        layout,
    })
}

/// What an atlas method uses when it is given no `--atlas` file: `scene`'s atlas baked now, in
/// memory, with `valgi bake`'s default settings, holding bounces `from_bounce..=B` (2 for
/// `sparse+atlas`, whose VALs give bounce 1). The layout is the bake's own, so it matches the
/// scene exactly; nothing is written. Progress goes to stderr as the bake's stages; Ctrl-C
/// stops it. A bake the layout refuses (charts that need a larger atlas) is an error that
/// says how to bake the file instead.
///
/// The last bake is kept, by the scene's content ([`Scene::content_key`]): the viewer builds
/// the method again on every change of a knob, and `valgi eval` builds each method twice (a
/// warm-up instance), over the same scene, and the bake was 2.0 of the 2.5 s such a build of
/// `sparse+atlas` took on the Cornell box.
pub fn bake_in_memory(scene: &Scene, from_bounce: u32) -> Result<Arc<LoadedAtlas>, RenderError> {
    type LastBake = Mutex<Option<(u64, u32, Arc<LoadedAtlas>)>>;
    static LAST_BAKE: LastBake = Mutex::new(None);
    let key = scene.content_key();
    if let Ok(last) = LAST_BAKE.lock() {
        if let Some((_, _, atlas)) = last
            .as_ref()
            .filter(|(k, bounce, _)| *k == key && *bounce == from_bounce)
        {
            log::info!("atlas: the in-memory bake of scene '{}' again", scene.name);
            return Ok(atlas.clone());
        }
    }
    let atlas = Arc::new(bake_anew(scene, from_bounce)?);
    if let Ok(mut last) = LAST_BAKE.lock() {
        *last = Some((key, from_bounce, atlas.clone()));
    }
    Ok(atlas)
}

/// [`bake_in_memory`] without the kept bake.
fn bake_anew(scene: &Scene, from_bounce: u32) -> Result<LoadedAtlas, RenderError> {
    let settings = BakeSettings::default();
    let world_from_node = scene.world_from_node();
    let stages = crate::progress::Stages::new("atlas bake (no --atlas given)");
    let progress = |stage: &str, done: usize, total: usize| stages.report(stage, done, total);
    let result = bake(
        scene,
        &world_from_node,
        &settings,
        &progress,
        crate::progress::cancel_flag(),
    );
    stages.finish();
    let result = result.map_err(|e| match e {
        BakeError::Cancelled => RenderError::Cancelled(crate::progress::Cancelled),
        e => RenderError::AtlasBake(format!(
            "no --atlas given, and baking one for scene '{}' failed: {e}; bake it with \
             `valgi bake --scene … --out FILE.exr --from-bounce {from_bounce}` (its options \
             set the atlas size) and pass --atlas FILE.exr",
            scene.name
        )),
    })?;
    let bounces = from_bounce..=settings.bounces;
    let layout = stored_layout::StoredLayout::of_bake(&result, scene, &world_from_node, None);
    Ok(LoadedAtlas {
        path: std::path::PathBuf::from("(baked in memory)"),
        image: result.atlas(*bounces.start(), *bounces.end()),
        bounces: Some(bounces),
        layout: AtlasLayoutFile::Stored {
            path: std::path::PathBuf::from("(the bake's own layout)"),
            layout: Box::new(layout),
        },
    })
}

fn check_square(atlas: &Image) -> Result<(), RenderError> {
    if atlas.width != atlas.height {
        return Err(RenderError::Settings(format!(
            "the atlas is {}×{}; a baked atlas is square",
            atlas.width, atlas.height
        )));
    }
    Ok(())
}

/// GPU lookup of a baked atlas: rasterizes the light-map meshes from a view's camera into an
/// irradiance target (pass "atlas lookup"), then writes ρ_d/π·E into the view's
/// `radiance_indirect` (pass "atlas apply"). A layer for any method that wants the atlas's
/// bounces (`atlas`, `sparse+atlas`). The atlas itself is shared; the irradiance target and
/// its depth belong to each view.
pub struct AtlasLayer {
    meshes: Vec<LayerMesh>,
    transforms: wgpu::Buffer,
    render_pipeline: wgpu::RenderPipeline,
    /// The same with back faces culled, for the two faces of sheets.
    sheet_pipeline: wgpu::RenderPipeline,
    /// The two with `fs_debug`: the atlas debug view's colours.
    debug_pipeline: wgpu::RenderPipeline,
    debug_sheet_pipeline: wgpu::RenderPipeline,
    /// Draw the debug view's colours (charts, texels, coverage holes, seams) instead of the
    /// light (`valgi view --debug atlas`).
    pub debug: bool,
    render_bgl: GroupLayout,
    apply_pipeline: wgpu::ComputePipeline,
    apply_bgl: GroupLayout,
    atlas_view: wgpu::TextureView,
    cuts_view: wgpu::TextureView,
    atlas_size: u32,
    views: ViewCache<AtlasView>,
    /// The view recorded last (tests read its irradiance).
    last_view: Option<u64>,
    pub bytes: GpuBytes,
    /// Layout texels missing from the atlas file (0 when it matches the scene).
    pub missing_texels: usize,
    /// Whether the light-map layout came from the atlas's layout file (else it was built
    /// from the scene).
    pub layout_from_file: bool,
}

/// One view's share of the lookup: camera uniform, irradiance target and depth.
pub struct AtlasView {
    frame_buffer: wgpu::Buffer,
    pub apply_buffer: wgpu::Buffer,
    /// Per-pixel atlas irradiance E (render resolution, Rgba32Float, alpha 1 on surfaces).
    pub irradiance: wgpu::TextureView,
    irradiance_texture: wgpu::Texture,
    depth: wgpu::TextureView,
    render_group: wgpu::BindGroup,
    render_size: [u32; 2],
    bytes: GpuBytes,
}

impl AtlasLayer {
    /// The lookup of `atlas`, with the scene's light-map layout built (or taken from this
    /// process's cache) for it.
    pub fn new(ctx: &GpuContext, scene: &Scene, atlas: &Image) -> Result<Self, RenderError> {
        check_square(atlas)?;
        let layout = layout::layout(scene, &scene.world_from_node(), atlas.width)
            .map_err(|e| RenderError::Settings(format!("atlas layout: {e}")))?;
        Self::with_layout(
            ctx,
            scene,
            atlas,
            &stored_layout::LookupLayout::of(&layout),
            false,
        )
    }

    /// The lookup of an atlas read by [`load_atlas`]: its stored layout when it has one made
    /// for this scene's geometry and resolution (refused when made for other geometry), the
    /// layout rebuilt from the scene when it has none.
    pub fn from_loaded(
        ctx: &GpuContext,
        scene: &Scene,
        atlas: &LoadedAtlas,
    ) -> Result<Self, RenderError> {
        check_square(&atlas.image)?;
        let (layout_path, stored) = match &atlas.layout {
            AtlasLayoutFile::Stored { path, layout } => (path, layout),
            AtlasLayoutFile::Absent(why) => {
                log::warn!(
                    "--atlas {}: no stored light-map layout ({why}); rebuilding it from the \
                     scene (minutes on large scenes: bake the atlas again to store it)",
                    atlas.path.display()
                );
                return Self::new(ctx, scene, &atlas.image);
            }
        };
        let scene_key =
            stored_layout::LayoutKey::of(scene, &scene.world_from_node(), atlas.image.width);
        if !stored.key.same_geometry(&scene_key) || stored.lookup.resolution != atlas.image.width {
            return Err(RenderError::Settings(format!(
                "--atlas {}: the atlas does not match this scene's light-map layout: {} was \
                 made for {} ({}); bake it for the same scene and --max-edge",
                atlas.path.display(),
                layout_path.display(),
                stored.describe(),
                stored.key.differences(&scene_key).join("; ")
            )));
        }
        if stored.key.layout_version != scene_key.layout_version {
            // The stored layout is the one the atlas was baked with, so it stays right for
            // the atlas; a layout rebuilt by this build would not.
            log::info!(
                "--atlas {}: its layout was made by layout version {}, this build makes \
                 version {}; using the stored one, which the atlas was baked with",
                atlas.path.display(),
                stored.key.layout_version,
                scene_key.layout_version
            );
        }
        Self::with_layout(ctx, scene, &atlas.image, &stored.lookup, true)
    }

    fn with_layout(
        ctx: &GpuContext,
        scene: &Scene,
        atlas: &Image,
        layout: &stored_layout::LookupLayout,
        layout_from_file: bool,
    ) -> Result<Self, RenderError> {
        let device = &ctx.device;
        check_square(atlas)?;
        let res = atlas.width;
        if layout.resolution != res {
            return Err(RenderError::Settings(format!(
                "the atlas is {res}², its light-map layout {}²",
                layout.resolution
            )));
        }
        let missing_texels = layout
            .texels
            .iter()
            .filter(|&&t| atlas.pixels[t as usize][3] <= 0.0)
            .count();
        if missing_texels * 100 > layout.texels.len() {
            return Err(RenderError::Settings(format!(
                "the atlas does not match this scene's light-map layout ({missing_texels} of {} texels missing); bake it for the same scene and --max-edge",
                layout.texels.len()
            )));
        }
        let mut bytes = GpuBytes::default();
        let vertex_usage = wgpu::BufferUsages::VERTEX;
        let mut meshes = Vec::new();
        for m in &layout.meshes {
            let node = scene
                .instances
                .get(m.instance as usize)
                .ok_or_else(|| {
                    RenderError::Settings(format!(
                        "the atlas's light-map layout places instance {} of {}",
                        m.instance,
                        scene.instances.len()
                    ))
                })?
                .node;
            let vertices: Vec<AtlasVertex> = m
                .model_positions
                .iter()
                .zip(&m.uvs)
                .map(|(p, uv)| AtlasVertex {
                    position: p.to_array(),
                    uv: uv.to_array(),
                })
                .collect();
            meshes.push(LayerMesh {
                vertices: bytes.buffer_init(
                    device,
                    "atlas vertices",
                    bytemuck::cast_slice(&vertices),
                    vertex_usage,
                ),
                indices: bytes.buffer_init(
                    device,
                    "atlas indices",
                    bytemuck::cast_slice(&m.indices),
                    wgpu::BufferUsages::INDEX,
                ),
                index_count: m.indices.len() as u32,
                node,
                sheet_face: m.sheet_face,
            });
        }
        let transforms = bytes.buffer(
            device,
            &wgpu::BufferDescriptor {
                label: Some("atlas transforms"),
                size: (meshes.len().max(1) * 64) as u64,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            },
        );
        let texture = |bytes: &mut GpuBytes, label, w, h, format, usage| {
            bytes.texture_2d(device, label, (w, h), format, usage)
        };
        // The atlas and its contact cuts: R × R, uploaded once.
        let mut upload = |label, format, data: &[u8], bytes_per_texel| {
            let t = texture(
                &mut bytes,
                label,
                res,
                res,
                format,
                wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            );
            ctx.write_texture_2d(&t, 0, data, (res, res), bytes_per_texel);
            t.create_view(&Default::default())
        };
        let atlas_view = upload(
            "light atlas",
            wgpu::TextureFormat::Rgba32Float,
            bytemuck::cast_slice(&atlas.pixels),
            16,
        );
        let cuts_view = upload(
            "atlas contact cuts",
            wgpu::TextureFormat::Rg32Uint,
            bytemuck::cast_slice(&layout.dense_cuts()),
            8,
        );
        let render_module = ctx.shader("atlas_render.wgsl");
        let render_bgl = GroupLayout::new(
            device,
            "atlas lookup",
            wgpu::ShaderStages::VERTEX_FRAGMENT,
            LOOKUP_BINDINGS,
        );
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("atlas lookup"),
            bind_group_layouts: &[Some(&render_bgl.layout)],
            immediate_size: 0,
        });
        const ATTRIBUTES: [wgpu::VertexAttribute; 2] =
            wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x2];
        let make_render_pipeline = |cull_mode, fragment_entry| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("atlas lookup"),
                layout: Some(&pipeline_layout),
                vertex: wgpu::VertexState {
                    module: &render_module,
                    entry_point: Some("vs_main"),
                    compilation_options: Default::default(),
                    buffers: &[Some(wgpu::VertexBufferLayout {
                        array_stride: std::mem::size_of::<AtlasVertex>() as u64,
                        step_mode: wgpu::VertexStepMode::Vertex,
                        attributes: &ATTRIBUTES,
                    })],
                },
                primitive: wgpu::PrimitiveState {
                    cull_mode,
                    ..Default::default()
                },
                depth_stencil: Some(wgpu::DepthStencilState {
                    format: DEPTH_FORMAT,
                    depth_write_enabled: Some(true),
                    depth_compare: Some(wgpu::CompareFunction::Less),
                    stencil: wgpu::StencilState::default(),
                    bias: wgpu::DepthBiasState::default(),
                }),
                multisample: wgpu::MultisampleState::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &render_module,
                    entry_point: Some(fragment_entry),
                    compilation_options: Default::default(),
                    targets: &[Some(wgpu::ColorTargetState {
                        format: RADIANCE_FORMAT,
                        blend: None,
                        write_mask: wgpu::ColorWrites::ALL,
                    })],
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        let render_pipeline = make_render_pipeline(None, "fs_main");
        let sheet_pipeline = make_render_pipeline(Some(wgpu::Face::Back), "fs_main");
        let debug_pipeline = make_render_pipeline(None, "fs_debug");
        let debug_sheet_pipeline = make_render_pipeline(Some(wgpu::Face::Back), "fs_debug");

        let apply_module = ctx.shader("atlas_apply.wgsl");
        let apply_bgl = GroupLayout::new(
            device,
            "atlas apply",
            wgpu::ShaderStages::COMPUTE,
            APPLY_BINDINGS,
        );
        let apply_pipeline =
            compute_pipeline(device, "atlas apply", &apply_module, &apply_bgl.layout);
        Ok(Self {
            meshes,
            transforms,
            render_pipeline,
            sheet_pipeline,
            debug_pipeline,
            debug_sheet_pipeline,
            debug: false,
            render_bgl,
            apply_pipeline,
            apply_bgl,
            atlas_view,
            cuts_view,
            atlas_size: res,
            views: ViewCache::default(),
            last_view: None,
            bytes,
            missing_texels,
            layout_from_file,
        })
    }

    /// Uploads the instances' transforms and drops the state of views that are gone.
    pub fn update(&mut self, ctx: &GpuContext, world_from_node: &[Mat4], views: &[&View]) {
        let transforms: Vec<[[f32; 4]; 4]> = self
            .meshes
            .iter()
            .map(|m| world_from_node[m.node].to_cols_array_2d())
            .collect();
        if !transforms.is_empty() {
            ctx.queue
                .write_buffer(&self.transforms, 0, bytemuck::cast_slice(&transforms));
        }
        self.views.retain(views);
    }

    /// GPU bytes of the atlas and of every view's lookup targets.
    pub fn gpu_bytes(&self) -> u64 {
        self.bytes.0 + self.views.values().map(|v| v.bytes.0).sum::<u64>()
    }

    /// The view's lookup state (made on first use), with this frame's camera uploaded.
    pub fn view_state(&mut self, ctx: &GpuContext, view: &View) -> Result<&AtlasView, RenderError> {
        let device = &ctx.device;
        let (rw, rh) = view.render_size();
        let (render_bgl, transforms, atlas_view, cuts_view) = (
            &self.render_bgl,
            &self.transforms,
            &self.atlas_view,
            &self.cuts_view,
        );
        let state = self.views.get_or_try_insert(view, || {
            let mut bytes = GpuBytes::default();
            let frame_buffer = bytes.uniform::<AtlasFrame>(device, "atlas frame");
            let apply_buffer = bytes.uniform::<ApplyParams>(device, "atlas apply");
            let irradiance_texture = bytes.texture_2d(
                device,
                "atlas irradiance",
                (rw, rh),
                RADIANCE_FORMAT,
                wgpu::TextureUsages::RENDER_ATTACHMENT
                    | wgpu::TextureUsages::TEXTURE_BINDING
                    | wgpu::TextureUsages::COPY_SRC,
            );
            let irradiance = irradiance_texture.create_view(&Default::default());
            let depth = bytes
                .texture_2d(
                    device,
                    "atlas depth",
                    (rw, rh),
                    DEPTH_FORMAT,
                    wgpu::TextureUsages::RENDER_ATTACHMENT,
                )
                .create_view(&Default::default());
            let render_group =
                render_bgl.bind(device, &[&frame_buffer, transforms, atlas_view, cuts_view]);
            Ok(AtlasView {
                frame_buffer,
                apply_buffer,
                irradiance,
                irradiance_texture,
                depth,
                render_group,
                render_size: [rw, rh],
                bytes,
            })
        })?;
        let frame = AtlasFrame {
            clip_from_world: view.camera.clip_from_world().to_cols_array_2d(),
            atlas_size: [self.atlas_size; 2],
            pad: [0; 2],
        };
        ctx.queue
            .write_buffer(&state.frame_buffer, 0, bytemuck::bytes_of(&frame));
        let apply = ApplyParams {
            render_size: state.render_size,
            debug: self.debug as u32,
            pad: 0,
        };
        ctx.queue
            .write_buffer(&state.apply_buffer, 0, bytemuck::bytes_of(&apply));
        self.last_view = Some(view.id());
        Ok(state)
    }

    /// Reads back the last recorded view's per-pixel atlas irradiance (render resolution;
    /// alpha 1 where a light-mapped surface was drawn, 0 on background).
    pub fn read_irradiance(&self, ctx: &GpuContext) -> Result<Image, RenderError> {
        let state = self
            .last_view
            .and_then(|id| self.views.values_by_id(id))
            .ok_or_else(|| RenderError::Settings("no atlas lookup recorded yet".into()))?;
        let [w, h] = state.render_size;
        Ok(Image::from_rgba(
            w,
            h,
            crate::gpu::read_texture_rgba32f(ctx, &state.irradiance_texture)?,
        ))
    }

    /// Atlas lookup (render pass) and ρ_d/π·E into the view's `radiance_indirect` (compute
    /// pass). Needs the view's G-buffer.
    pub fn record(
        &mut self,
        ctx: &GpuContext,
        view: &View,
        passes: &mut Passes,
    ) -> Result<(), RenderError> {
        self.record_lookup(ctx, view, passes)?;
        let state = self.views.get(view).expect("made by the lookup");
        let group = self.apply_bgl.bind(
            &ctx.device,
            &[
                &state.apply_buffer,
                &state.irradiance,
                &view.targets.diffuse,
                &view.targets.radiance_indirect,
            ],
        );
        view.record_per_pixel(passes, "atlas apply", &self.apply_pipeline, &group)?;
        Ok(())
    }

    /// Only the lookup: per-pixel atlas irradiance into the view's [`AtlasView::irradiance`],
    /// for a method that applies it together with its own indirect light.
    pub fn record_lookup(
        &mut self,
        ctx: &GpuContext,
        view: &View,
        passes: &mut Passes,
    ) -> Result<&AtlasView, RenderError> {
        self.view_state(ctx, view)?;
        let state = self.views.get(view).expect("made above");
        passes.render(
            "atlas lookup",
            &[Some(wgpu::RenderPassColorAttachment {
                view: &state.irradiance,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                    store: wgpu::StoreOp::Store,
                },
            })],
            Some(wgpu::RenderPassDepthStencilAttachment {
                view: &state.depth,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            |pass| {
                pass.set_bind_group(0, &state.render_group, &[]);
                for (i, m) in self.meshes.iter().enumerate() {
                    pass.set_pipeline(match (self.debug, m.sheet_face) {
                        (false, false) => &self.render_pipeline,
                        (false, true) => &self.sheet_pipeline,
                        (true, false) => &self.debug_pipeline,
                        (true, true) => &self.debug_sheet_pipeline,
                    });
                    pass.set_vertex_buffer(0, m.vertices.slice(..));
                    pass.set_index_buffer(m.indices.slice(..), wgpu::IndexFormat::Uint32);
                    let i = i as u32;
                    pass.draw_indexed(0..m.index_count, 0, i..i + 1);
                }
            },
        )?;
        Ok(state)
    }
}

/// Direct light plus every indirect bounce stored in a baked atlas (`--atlas FILE`).
pub struct AtlasMethod {
    raster: Rasterizer,
    layer: AtlasLayer,
    /// Milliseconds of the set-up's parts (reading the atlas and its layout file, the
    /// rasterizer, the lookup with its layout), for the report.
    setup_ms: Vec<(&'static str, f64)>,
}

/// The `atlas` option every atlas method takes.
pub const ATLAS_OPTION: OptionSpec = OptionSpec {
    name: "atlas",
    kind: OptionKind::Path,
    default: "",
    help: "baked light atlas (.exr from `valgi bake`); not given: baked in memory first with \
           `valgi bake`'s defaults",
};

pub static ENTRY: Entry = Entry {
    name: "atlas",
    help: "direct light plus the indirect bounces of a baked light atlas",
    options: &[ATLAS_OPTION],
    create,
};

fn create(
    ctx: &GpuContext,
    scene: &Scene,
    settings: RenderSettings,
    options: &MethodOptions,
) -> Result<Box<dyn Method>, RenderError> {
    Ok(Box::new(AtlasMethod::new(ctx, scene, settings, options)?))
}

impl AtlasMethod {
    pub fn new(
        ctx: &GpuContext,
        scene: &Scene,
        settings: RenderSettings,
        options: &MethodOptions,
    ) -> Result<Self, RenderError> {
        let path: String = options.get("atlas", String::new())?;
        let ms = |since: std::time::Instant| since.elapsed().as_secs_f64() * 1000.0;
        let started = std::time::Instant::now();
        let atlas = if path.is_empty() {
            bake_in_memory(scene, 1)?
        } else {
            Arc::new(load_atlas(Path::new(&path))?)
        };
        let read_ms = ms(started);
        if let Some(bounces) = atlas.bounces.as_ref().filter(|b| *b.start() > 1) {
            log::warn!(
                "--atlas {path} holds bounces {}..={} only (baked with --from-bounce {}): \
                 method 'atlas' shows no bounce below {}; bake with --from-bounce 1, or use \
                 'sparse+atlas', which adds bounce 1",
                bounces.start(),
                bounces.end(),
                bounces.start(),
                bounces.start()
            );
        }
        let started = std::time::Instant::now();
        let raster = Rasterizer::new(ctx, scene, settings)?;
        let raster_ms = ms(started);
        let started = std::time::Instant::now();
        let layer = AtlasLayer::from_loaded(ctx, scene, &atlas)?;
        let setup_ms = vec![
            ("read", read_ms),
            ("rasterizer", raster_ms),
            ("lookup", ms(started)),
        ];
        Ok(Self {
            raster,
            layer,
            setup_ms,
        })
    }

    /// The atlas layer (for tests and composed methods).
    pub fn layer(&self) -> &AtlasLayer {
        &self.layer
    }
}

impl Method for AtlasMethod {
    fn name(&self) -> &'static str {
        "atlas"
    }

    fn settings(&self) -> RenderSettings {
        self.raster.settings
    }

    fn update(
        &mut self,
        ctx: &GpuContext,
        frame: &FrameInput,
        views: &[&View],
        passes: &mut Passes,
    ) -> Result<(), RenderError> {
        self.raster
            .update_and_record(ctx, frame.scene, frame.world_from_node, passes)?;
        self.layer.update(ctx, frame.world_from_node, views);
        Ok(())
    }

    fn record_view(
        &mut self,
        ctx: &GpuContext,
        _frame: &FrameInput,
        view: &View,
        passes: &mut Passes,
    ) -> Result<ViewResult, RenderError> {
        self.raster.record_view_base(ctx, view, passes)?;
        self.layer.record(ctx, view, passes)?;
        Ok(ViewResult::DirectAndIndirect)
    }

    fn gpu_bytes(&self) -> u64 {
        self.raster.gpu_bytes() + self.layer.gpu_bytes()
    }

    fn set_debug_atlas(&mut self, on: bool) -> bool {
        self.layer.debug = on;
        true
    }

    fn report(&self) -> serde_json::Map<String, serde_json::Value> {
        let mut map = serde_json::Map::new();
        map.insert(
            "atlas_missing_texels".into(),
            serde_json::json!(self.layer.missing_texels),
        );
        map.insert(
            "atlas_setup_ms".into(),
            self.setup_ms
                .iter()
                .map(|&(part, ms)| (part.to_string(), serde_json::json!(ms.round())))
                .collect::<serde_json::Map<_, _>>()
                .into(),
        );
        map.insert(
            "atlas_layout".into(),
            serde_json::json!(if self.layer.layout_from_file {
                "stored"
            } else {
                "rebuilt"
            }),
        );
        map
    }
}

#[cfg(test)]
mod kept_bake_tests {
    use super::*;
    use crate::scene::builtin::{self, BuiltinParams};

    /// A scene baked again takes the kept bake; a scene that differs in anything the bake
    /// reads is baked anew, and what it does not read (name, cameras, warnings) leaves the
    /// key as it was.
    #[test]
    fn the_same_scene_takes_the_kept_bake_and_any_change_bakes_anew() {
        let scene = builtin::load("cornell", &BuiltinParams { max_edge: 0.25 }).expect("cornell");
        let key = scene.content_key();
        let mut unread = scene.clone();
        unread.name = "another name".into();
        unread.cameras.clear();
        unread.warnings.push("a warning".into());
        assert_eq!(unread.content_key(), key);
        type Edit = (&'static str, fn(&mut Scene));
        let edits: [Edit; 5] = [
            ("a light's intensity", |s| s.lights[0].intensity *= 1.001),
            ("a material's colour", |s| {
                s.materials[0].base_color.x *= 0.5
            }),
            ("a vertex", |s| s.meshes[0].positions[0].x += 1e-4),
            ("a node's place", |s| s.nodes[0].local.translation.y += 0.01),
            ("an index", |s| s.meshes[0].indices.swap(0, 1)),
        ];
        for (what, edit) in edits {
            let mut edited = scene.clone();
            edit(&mut edited);
            assert_ne!(edited.content_key(), key, "{what}");
        }

        let first = bake_in_memory(&scene, 2).expect("bake");
        let again = bake_in_memory(&unread, 2).expect("the kept bake");
        assert!(Arc::ptr_eq(&first, &again));
        let mut brighter = scene.clone();
        brighter.lights[0].intensity *= 2.0;
        let anew = bake_in_memory(&brighter, 2).expect("a new bake");
        assert!(!Arc::ptr_eq(&first, &anew));
        // Twice the light, twice the bounces (the bake is linear in it).
        let mean = |a: &LoadedAtlas| a.image.pixels.iter().map(|p| p[0] as f64).sum::<f64>();
        let ratio = mean(&anew) / mean(&first);
        assert!((ratio - 2.0).abs() < 0.02, "{ratio}");
    }
}
