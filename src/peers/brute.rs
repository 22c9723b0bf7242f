//! Brute-force VALs: every pixel sums every VAL from the same RSMs with the same disc
//! irradiance and BRDF as the sparse method, without interpolation or occlusion
//! (`shaders/brute/brute_vals.wgsl`; CPU twin [`crate::vals::math::brute_force`]). Its image is what
//! the sparse method would give with a receiver point at every pixel, so the difference between
//! the two is the sparse method's interpolation error alone.

use crate::frame::{FrameInput, Method, View, ViewResult, PIXEL_TILE};
use crate::gpu::bindings::{GroupLayout, Slot};
use crate::gpu::{FrameTimings, GpuContext, Passes};
use crate::light::rsm::Rsm;
use crate::light::val_windows::{self, ValReads, ValWindows};
use crate::light::{GlossyGather, ValParams, FLAG_GLOSSY};
use crate::method::{Entry, MethodOptions, OptionKind, OptionSpec};
use crate::raster::{Rasterizer, RenderError, RenderSettings, RADIANCE_FORMAT};
use crate::scene::Scene;

/// `brute_vals.wgsl`'s group: the view's frame uniform, the VAL parameters, the VALs and their
/// count, the G-buffer (depth, normal, diffuse, specular) and the indirect target.
const BINDINGS: &[Slot] = &[
    Slot::Uniform,
    Slot::Uniform,
    Slot::Storage,
    Slot::Storage,
    Slot::DepthTexture,
    Slot::Texture,
    Slot::Texture,
    Slot::Texture,
    Slot::StorageTexture(RADIANCE_FORMAT),
];

pub static ENTRY: Entry = Entry {
    name: "brute",
    help: "direct + every VAL summed at every pixel: the sparse method without interpolation or occlusion",
    options: &[
        OptionSpec {
            name: "rsm",
            kind: OptionKind::Int { min: 1, max: 2048 },
            default: "128",
            help: "RSM resolution per light layer: R×R texels, six layers for a point light \
                   (not given: at most 128², the lights sharing 6·128² texels by power)",
        },
        OptionSpec {
            name: "tile",
            kind: OptionKind::Int { min: 1, max: 256 },
            default: "128",
            help: "VALs per workgroup-memory tile (--vals tiles)",
        },
        OptionSpec {
            name: "vals",
            kind: OptionKind::Choice(ValReads::CHOICES),
            default: "auto",
            help: "how each pixel reads the VAL list: staged through workgroup memory in tiles, or from uniform windows of 1024 VALs, one dispatch each (a CPU device reads a VAL every invocation shares far faster from a uniform block); auto: windows on a CPU device, tiles on a GPU; both give the same bits",
        },
        OptionSpec {
            name: "glossy",
            kind: OptionKind::Choice(GlossyGather::CHOICES),
            default: "auto",
            help: "glossy indirect light (auto: where some material has a specular factor above 0; an all-Lambert scene's glossy term is zero, so only diffuse light is summed)",
        },
    ],
    create,
};

fn create(
    ctx: &GpuContext,
    scene: &Scene,
    settings: RenderSettings,
    options: &MethodOptions,
) -> Result<Box<dyn Method>, RenderError> {
    Ok(Box::new(BruteMethod::new(ctx, scene, settings, options)?))
}

pub struct BruteMethod {
    pub raster: Rasterizer,
    pub rsm: Rsm,
    /// The `glossy` option, and whether it sums glossy light in this scene.
    glossy_option: GlossyGather,
    glossy: bool,
    tile: u32,
    params_buffer: wgpu::Buffer,
    pipeline: wgpu::ComputePipeline,
    layout: GroupLayout,
    /// The window form (`cs_window`), where it runs: its pipeline, the VAL windows, the
    /// running sums' layout and the sums of the last view size.
    windows: Option<BruteWindows>,
    vals: u32,
}

/// Pixels per invocation of the window form (`COLUMN` in `brute_vals.wgsl`): a column of them,
/// so that each VAL read from the window serves that many pixels.
pub const WINDOW_COLUMN: u32 = 4;

/// What the window form of brute force needs besides the tile form's group.
struct BruteWindows {
    pipeline: wgpu::ComputePipeline,
    windows: ValWindows,
    running_layout: GroupLayout,
    /// One vec4 per pixel, made again when the view's pixel count changes.
    running: Option<(u64, wgpu::Buffer, wgpu::BindGroup)>,
}

impl BruteWindows {
    fn running_group(&mut self, ctx: &GpuContext, pixels: u64) -> wgpu::BindGroup {
        let bytes = pixels.max(1) * 16;
        if let Some((held, _, group)) = &self.running {
            if *held == bytes {
                return group.clone();
            }
        }
        let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("brute running sums"),
            size: bytes,
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        let group = self.running_layout.bind(&ctx.device, &[&buffer]);
        self.running = Some((bytes, buffer, group.clone()));
        group
    }
}

impl BruteMethod {
    pub fn new(
        ctx: &GpuContext,
        scene: &Scene,
        render: RenderSettings,
        options: &MethodOptions,
    ) -> Result<Self, RenderError> {
        let rsm_resolution: u32 = options.get("rsm", 128)?;
        let glossy_option = GlossyGather::parse(options.choice("glossy", GlossyGather::CHOICES)?);
        let glossy = glossy_option.gathers(crate::light::reflects_glossily(scene));
        let tile: u32 = options.get("tile", 128)?;
        if !(1..=256).contains(&tile) {
            return Err(RenderError::Settings(format!(
                "--tile {tile}: must be 1..=256"
            )));
        }
        let reads = ValReads::parse(options.choice("vals", ValReads::CHOICES)?);
        let raster = Rasterizer::new(ctx, scene, render)?;
        // Without --rsm the lights share one point light's texels, as in the sparse method:
        // both gather the same VALs.
        let shared_texels =
            (!options.given("rsm")).then_some(crate::light::rsm::DEFAULT_SHARED_TEXELS);
        let rsm = Rsm::with_external(ctx, scene, &raster, rsm_resolution, shared_texels, None)?;
        let device = &ctx.device;
        let params_buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("brute params"),
            size: std::mem::size_of::<ValParams>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let cs = wgpu::ShaderStages::COMPUTE;
        let layout = GroupLayout::new(device, "brute", cs, BINDINGS);
        // Without glossy light, the build without its code (see `GlossyGather`).
        let module = ctx.shader("brute_vals.wgsl");
        let constants = [("GLOSSY_GATHER", if glossy { 1.0 } else { 0.0 })];
        let pipeline = crate::gpu::compute_pipeline_groups(
            device,
            "brute",
            &module,
            &[&layout.layout],
            "cs_main",
            &constants,
        );
        let window_layout = val_windows::layout(device, cs);
        let windows = ValWindows::new(ctx, &rsm, &window_layout)
            .filter(|_| reads.windows(ctx.is_software(), true, 0))
            .map(|windows| {
                let running_layout =
                    GroupLayout::new(device, "brute running sums", cs, &[Slot::StorageRw]);
                let pipeline = crate::gpu::compute_pipeline_groups(
                    device,
                    "brute",
                    &module,
                    &[
                        &layout.layout,
                        &running_layout.layout,
                        &window_layout.layout,
                    ],
                    "cs_window",
                    &constants,
                );
                BruteWindows {
                    pipeline,
                    windows,
                    running_layout,
                    running: None,
                }
            });
        Ok(Self {
            raster,
            rsm,
            glossy_option,
            glossy,
            tile,
            params_buffer,
            pipeline,
            layout,
            windows,
            vals: 0,
        })
    }
}

impl Method for BruteMethod {
    fn name(&self) -> &'static str {
        "brute"
    }

    fn settings(&self) -> RenderSettings {
        self.raster.settings
    }

    fn update(
        &mut self,
        ctx: &GpuContext,
        frame: &FrameInput,
        _views: &[&View],
        passes: &mut Passes,
    ) -> Result<(), RenderError> {
        self.raster
            .update_and_record(ctx, frame.scene, frame.world_from_node, passes)?;
        self.rsm.prepare(ctx, frame.scene, frame.world_from_node);
        // Every pixel's glossy lobe uses its own view's eye (the shader reads the frame
        // uniform's camera), so nothing here depends on a view.
        let params = ValParams {
            eye: frame.solution_eye.extend(1.0).to_array(),
            flags: if self.glossy { FLAG_GLOSSY } else { 0 },
            tile: self.tile,
            ..Default::default()
        };
        ctx.queue
            .write_buffer(&self.params_buffer, 0, bytemuck::bytes_of(&params));
        self.rsm.record(passes, &self.raster.scene_gpu)?;
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
        let t = &view.targets;
        let group = self.layout.bind(
            &ctx.device,
            &[
                &view.frame_buffer,
                &self.params_buffer,
                &self.rsm.vals_buffer,
                &self.rsm.val_count_buffer,
                &t.depth,
                &t.normal,
                &t.diffuse,
                &t.specular,
                &t.radiance_indirect,
            ],
        );
        match &mut self.windows {
            Some(w) => {
                let (width, height) = view.render_size();
                let running = w.running_group(ctx, u64::from(width) * u64::from(height));
                passes.compute("brute", |pass| {
                    pass.set_pipeline(&w.pipeline);
                    pass.set_bind_group(0, &group, &[]);
                    pass.set_bind_group(1, &running, &[]);
                    w.windows.for_each(pass, 2, |pass| {
                        pass.dispatch_workgroups(
                            width.div_ceil(PIXEL_TILE),
                            height.div_ceil(PIXEL_TILE * WINDOW_COLUMN),
                            1,
                        );
                    });
                })?;
            }
            None => view.record_per_pixel(passes, "brute", &self.pipeline, &group)?,
        }
        Ok(ViewResult::DirectAndIndirect)
    }

    fn end_frame(&mut self, ctx: &GpuContext, _timings: &FrameTimings) -> Result<(), RenderError> {
        self.vals = self.rsm.read_count(ctx)?;
        Ok(())
    }

    fn debug_vals(&self) -> Option<crate::frame::DebugValSource<'_>> {
        Some(self.rsm.debug_vals())
    }

    fn gpu_bytes(&self) -> u64 {
        let running = self
            .windows
            .as_ref()
            .and_then(|w| w.running.as_ref())
            .map_or(0, |(bytes, _, _)| *bytes);
        self.raster.gpu_bytes() + self.rsm.bytes.0 + running
    }

    fn report(&self) -> serde_json::Map<String, serde_json::Value> {
        let mut map = serde_json::Map::new();
        map.insert("vals".into(), self.vals.into());
        map.insert("rsm".into(), self.rsm.resolution.into());
        map.insert(
            "glossy".into(),
            format!("{:?}", self.glossy_option).to_lowercase().into(),
        );
        map.insert("glossy_gathered".into(), self.glossy.into());
        map.insert(
            "vals_read".into(),
            ValReads::name(self.windows.is_some()).into(),
        );
        map
    }
}
