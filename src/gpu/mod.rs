//! Headless GPU access: device creation on any adapter, per-pass timing, readback, and a count
//! of the bytes each method owns on the GPU.

pub mod bindings;
pub mod peak;
pub mod readback;
pub mod resources;
pub mod timing;

pub use readback::{read_buffer, read_texture_bytes, read_texture_rgba32f};
pub use resources::GpuBytes;
pub use timing::{FrameTimings, PassTimings, Passes, Scope};

/// Why no GPU device could be made. The message names the remedy.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error(
        "no GPU adapter found (backends tried: {backends}). Install a Vulkan driver; on a \
         machine without a GPU install Mesa's software driver: `apt-get install mesa-vulkan-drivers` \
         (README's commands do this). Set WGPU_BACKEND to try another backend."
    )]
    NoAdapter { backends: String },
    #[error(
        "WGPU_ADAPTER_NAME='{wanted}' matches no adapter; available: {available}. Unset it or \
         name one of these."
    )]
    AdapterNameNotFound { wanted: String, available: String },
    #[error("could not create a device on '{adapter}': {message}")]
    Device { adapter: String, message: String },
    /// The adapter lacks what every method needs; said at start-up, before any work.
    #[error(
        "the {backend} adapter '{adapter}' cannot run valgi: {missing}. Use a Vulkan, Metal or \
         DX12 adapter; on a machine without a GPU install Mesa's software Vulkan driver: \
         `apt-get install mesa-vulkan-drivers` (README's commands do this)"
    )]
    Unsupported {
        adapter: String,
        backend: String,
        missing: String,
    },
    #[error("GPU readback failed: {0}")]
    Readback(String),
    /// wgpu refused or could not back an allocation or a pipeline.
    #[error("could not create {what} on the GPU ({size}): {message}. {remedy}")]
    Allocation {
        what: String,
        size: String,
        message: String,
        remedy: String,
    },
    /// An error wgpu raised outside any allocation scope (while recording or submitting).
    #[error("GPU error: {0}")]
    Uncaptured(String),
}

/// `1.5 GiB`, `256 KiB`, `12 B`: sizes in error messages.
/// Workgroups `(x, y)` that cover `groups` in a row when one dimension holds at most
/// `max_per_dimension` (`max_compute_workgroups_per_dimension`): a long 1-D kernel wraps into a
/// second dimension, and its shader counts `gid.x + gid.y · x · group_size`
/// (`linear_index` in `shaders/vals/vals_common.wgsl`). The extra threads of the last row
/// fall past the end and return, as the last group's do in one dimension.
pub fn linear_groups(groups: u32, max_per_dimension: u32) -> (u32, u32) {
    let max = max_per_dimension.max(1);
    if groups <= max {
        (groups.max(1), 1)
    } else {
        (max, groups.div_ceil(max))
    }
}

/// A compute pipeline whose bind groups 0, 1, … have `layouts`, with the module's
/// pipeline-overridable constants (`override` in WGSL) set to `constants`: code behind a
/// constant-false condition is compiled out, which a uniform flag does not achieve on a CPU
/// device (llvmpipe runs both sides of every branch under a mask).
pub fn compute_pipeline_groups(
    device: &wgpu::Device,
    label: &str,
    module: &wgpu::ShaderModule,
    layouts: &[&wgpu::BindGroupLayout],
    entry: &str,
    constants: &[(&str, f64)],
) -> wgpu::ComputePipeline {
    let groups: Vec<Option<&wgpu::BindGroupLayout>> = layouts.iter().map(|l| Some(*l)).collect();
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(label),
        bind_group_layouts: &groups,
        immediate_size: 0,
    });
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: Some(&pipeline_layout),
        module,
        entry_point: Some(entry),
        compilation_options: wgpu::PipelineCompilationOptions {
            constants,
            ..Default::default()
        },
        cache: None,
    })
}

pub fn format_bytes(bytes: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut value = bytes as f64;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < UNITS.len() {
        value /= 1024.0;
        unit += 1;
    }
    if unit == 0 {
        format!("{bytes} B")
    } else {
        format!("{value:.1} {}", UNITS[unit])
    }
}

/// `1 light`, `3 lights`.
pub fn count_of(count: usize, noun: &str) -> String {
    if count == 1 {
        format!("1 {noun}")
    } else {
        format!("{count} {noun}s")
    }
}

/// The first error wgpu raised outside a scope since it was last taken. wgpu's default is to
/// panic; the device's handler stores the message here instead, and the next
/// [`GpuContext::check_uncaptured`] returns it as an error.
#[derive(Clone, Default)]
struct UncapturedErrors(std::sync::Arc<std::sync::Mutex<Option<String>>>);

impl UncapturedErrors {
    fn install(&self, device: &wgpu::Device) {
        let slot = self.0.clone();
        device.on_uncaptured_error(std::sync::Arc::new(move |error: wgpu::Error| {
            let message = describe(&error);
            log::error!("GPU error: {message}");
            let mut first = slot.lock().unwrap_or_else(|e| e.into_inner());
            first.get_or_insert(message);
        }));
    }

    fn take(&self) -> Option<String> {
        self.0.lock().unwrap_or_else(|e| e.into_inner()).take()
    }
}

/// One line for a wgpu error: its kind and description (with the validation error's source
/// chain, which names the resource and the limit).
fn describe(error: &wgpu::Error) -> String {
    match error {
        wgpu::Error::OutOfMemory { .. } => "out of GPU memory".into(),
        wgpu::Error::Validation { description, .. } | wgpu::Error::Internal { description, .. } => {
            description.split_whitespace().collect::<Vec<_>>().join(" ")
        }
    }
}

/// The device, its queue, and what the adapter can do.
pub struct GpuContext {
    pub adapter: wgpu::Adapter,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub adapter_info: wgpu::AdapterInfo,
    /// Whether pass timings come from GPU timestamp queries (else from wall-clock time around
    /// a submission per pass).
    pub timestamps: bool,
    uncaptured: UncapturedErrors,
    /// Objects made once per device and shared by everything that asks for them (the resolve
    /// pipeline every view uses), one per type.
    shared: std::sync::Mutex<
        std::collections::HashMap<
            std::any::TypeId,
            std::sync::Arc<dyn std::any::Any + Send + Sync>,
        >,
    >,
}

/// The live `T`s of [`GpuContext::live_by_key`], one list per device and type.
struct Live<T>(std::sync::Mutex<Vec<(u64, std::sync::Weak<T>)>>);

impl<T> Default for Live<T> {
    fn default() -> Self {
        Self(std::sync::Mutex::new(Vec::new()))
    }
}

impl GpuContext {
    /// The device's one `T`, made by `make` the first time it is asked for: pipelines that do
    /// not depend on their user (every view's resolve) are compiled once, not per user.
    pub fn shared<T, E>(&self, make: impl FnOnce() -> Result<T, E>) -> Result<std::sync::Arc<T>, E>
    where
        T: std::any::Any + Send + Sync,
    {
        let key = std::any::TypeId::of::<T>();
        let found = self
            .shared
            .lock()
            .ok()
            .and_then(|map| map.get(&key).cloned());
        if let Some(any) = found {
            if let Ok(value) = any.downcast::<T>() {
                return Ok(value);
            }
        }
        // Made outside the lock: `make` may itself ask for other shared objects.
        let value = std::sync::Arc::new(make()?);
        if let Ok(mut map) = self.shared.lock() {
            let stored = map
                .entry(key)
                .or_insert_with(|| value.clone() as std::sync::Arc<dyn std::any::Any + Send + Sync>)
                .clone();
            if let Ok(stored) = stored.downcast::<T>() {
                return Ok(stored);
            }
        }
        Ok(value)
    }

    /// The `T` made for `key` (a scene's [`crate::scene::Scene::content_key`]) that something
    /// still holds on this device, else a new one made by `make`. Builds over the same scene
    /// (the viewer's rebuilds, a benchmark's warm-up instance beside its timed one, budget
    /// mode's pilots) then share one upload of it. Only weak references are kept here: each
    /// object lives exactly as long as its users.
    pub fn live_by_key<T, E>(
        &self,
        key: u64,
        make: impl FnOnce() -> Result<T, E>,
    ) -> Result<std::sync::Arc<T>, E>
    where
        T: std::any::Any + Send + Sync,
    {
        let live = match self.shared(|| Ok::<_, std::convert::Infallible>(Live::<T>::default())) {
            Ok(live) => live,
            Err(never) => match never {},
        };
        if let Ok(mut entries) = live.0.lock() {
            entries.retain(|(_, weak)| weak.strong_count() > 0);
            let found = entries
                .iter()
                .find(|(k, _)| *k == key)
                .and_then(|(_, weak)| weak.upgrade());
            if let Some(found) = found {
                return Ok(found);
            }
        }
        // Made outside the lock: `make` may take long (an upload) or ask for other objects.
        let made = std::sync::Arc::new(make()?);
        if let Ok(mut entries) = live.0.lock() {
            entries.push((key, std::sync::Arc::downgrade(&made)));
        }
        Ok(made)
    }

    /// Uploads one mip level of a 2D texture: `data` is `width × height` texels of
    /// `bytes_per_texel` bytes, rows packed.
    pub fn write_texture_2d(
        &self,
        texture: &wgpu::Texture,
        mip_level: u32,
        data: &[u8],
        (width, height): (u32, u32),
        bytes_per_texel: u32,
    ) {
        self.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture,
                mip_level,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            data,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(bytes_per_texel * width),
                rows_per_image: Some(height),
            },
            wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
        );
    }

    /// Opens a headless device. Honours `WGPU_BACKEND` (e.g. `vulkan`, `gl`) and
    /// `WGPU_ADAPTER_NAME` (case-insensitive substring of the adapter's name); otherwise takes
    /// the high-performance adapter, falling back to any (software drivers included).
    pub fn new() -> Result<Self, GpuError> {
        Self::with_limits(|_| {})
    }

    /// [`GpuContext::new`] with the adapter's limits changed by `adjust` before the device is
    /// asked for them: lowering one shows how the code meets a smaller device (a binding
    /// limit, a workgroup count) on the machine at hand.
    pub fn with_limits(adjust: impl Fn(&mut wgpu::Limits)) -> Result<Self, GpuError> {
        pollster::block_on(Self::new_async(&adjust))
    }

    async fn new_async(adjust: &dyn Fn(&mut wgpu::Limits)) -> Result<Self, GpuError> {
        if std::env::var_os("WGPU_BACKEND").is_some() {
            let backends = wgpu::Backends::from_env().unwrap_or_default();
            return Self::on_backends(backends, adjust).await;
        }
        // Vulkan, Metal or DX12 first; OpenGL only when none of those has an adapter, because
        // probing EGL without a display is slow and noisy.
        match Self::on_backends(wgpu::Backends::PRIMARY, adjust).await {
            Err(GpuError::NoAdapter { .. }) => Self::on_backends(wgpu::Backends::GL, adjust)
                .await
                .map_err(|e| match e {
                    GpuError::NoAdapter { .. } => GpuError::NoAdapter {
                        backends: format!("{:?}", wgpu::Backends::PRIMARY | wgpu::Backends::GL),
                    },
                    other => other,
                }),
            other => other,
        }
    }

    async fn on_backends(
        backends: wgpu::Backends,
        adjust: &dyn Fn(&mut wgpu::Limits),
    ) -> Result<Self, GpuError> {
        let mut instance_desc = wgpu::InstanceDescriptor::new_without_display_handle();
        instance_desc.backends = backends;
        // Debug labels stay off unless WGPU_DEBUG=1: Mesa 22's lavapipe crashes in
        // vkCmdBeginDebugUtilsLabelEXT, and release builds never had them.
        instance_desc.flags = wgpu::InstanceFlags::empty().with_env();
        let instance = wgpu::Instance::new(instance_desc);
        let adapter = match std::env::var("WGPU_ADAPTER_NAME") {
            Ok(wanted) if !wanted.is_empty() => {
                let adapters = instance.enumerate_adapters(backends).await;
                let wanted_lower = wanted.to_lowercase();
                let names: Vec<String> = adapters
                    .iter()
                    .map(|a| {
                        let i = a.get_info();
                        format!("'{}' ({:?})", i.name, i.backend)
                    })
                    .collect();
                match adapters
                    .into_iter()
                    .find(|a| a.get_info().name.to_lowercase().contains(&wanted_lower))
                {
                    Some(a) => a,
                    None => {
                        return Err(GpuError::AdapterNameNotFound {
                            wanted,
                            available: if names.is_empty() {
                                "none".into()
                            } else {
                                names.join(", ")
                            },
                        })
                    }
                }
            }
            _ => {
                let preferred = instance
                    .request_adapter(&wgpu::RequestAdapterOptions {
                        power_preference: wgpu::PowerPreference::HighPerformance,
                        force_fallback_adapter: false,
                        compatible_surface: None,
                        ..Default::default()
                    })
                    .await;
                match preferred {
                    Ok(a) => a,
                    Err(_) => instance
                        .request_adapter(&wgpu::RequestAdapterOptions {
                            power_preference: wgpu::PowerPreference::None,
                            force_fallback_adapter: true,
                            compatible_surface: None,
                            ..Default::default()
                        })
                        .await
                        .map_err(|_| GpuError::NoAdapter {
                            backends: format!("{backends:?}"),
                        })?,
                }
            }
        };
        Self::from_adapter(adapter, adjust).await
    }

    /// An instance for windows on `display` (a winit event loop's display handle), with the
    /// backends and debug flags the headless path uses.
    pub fn window_instance(display: Box<dyn wgpu::wgt::WgpuHasDisplayHandle>) -> wgpu::Instance {
        let mut desc = wgpu::InstanceDescriptor::new_with_display_handle(display);
        desc.backends = wgpu::Backends::from_env().unwrap_or(wgpu::Backends::PRIMARY);
        desc.flags = wgpu::InstanceFlags::empty().with_env();
        wgpu::Instance::new(desc)
    }

    /// Opens a device on an adapter that can present to `surface` (made from `instance`),
    /// falling back to a software adapter.
    pub fn for_surface(
        instance: &wgpu::Instance,
        surface: &wgpu::Surface<'_>,
    ) -> Result<Self, GpuError> {
        pollster::block_on(async {
            let options = |fallback| wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::HighPerformance,
                force_fallback_adapter: fallback,
                compatible_surface: Some(surface),
                ..Default::default()
            };
            let adapter = match instance.request_adapter(&options(false)).await {
                Ok(a) => a,
                Err(_) => instance
                    .request_adapter(&options(true))
                    .await
                    .map_err(|_| GpuError::NoAdapter {
                        backends: "any that can present to the window".into(),
                    })?,
            };
            Self::from_adapter(adapter, &|_| {}).await
        })
    }

    /// What `adapter` lacks of the capabilities every method relies on (empty: none).
    pub fn missing_capabilities(adapter: &wgpu::Adapter) -> Vec<String> {
        let mut missing = Vec::new();
        if adapter.get_info().backend == wgpu::Backend::Gl {
            // naga's GLSL output has no textureLoad from depth textures, which the direct-light
            // and VAL kernels use to read shadow maps and the G-buffer depth.
            missing.push("its shaders cannot read depth textures with textureLoad (GLSL)".into());
        }
        let downlevel = adapter.get_downlevel_capabilities();
        if !downlevel
            .flags
            .contains(wgpu::DownlevelFlags::COMPUTE_SHADERS)
        {
            missing.push("no compute shaders".into());
        }
        let float_target = adapter.get_texture_format_features(wgpu::TextureFormat::Rgba32Float);
        let needed = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::STORAGE_BINDING;
        if !float_target.allowed_usages.contains(needed) {
            missing.push(format!(
                "Rgba32Float textures allow only {:?}, and the radiance targets need {needed:?}",
                float_target.allowed_usages
            ));
        }
        missing
    }

    async fn from_adapter(
        adapter: wgpu::Adapter,
        adjust: &dyn Fn(&mut wgpu::Limits),
    ) -> Result<Self, GpuError> {
        let adapter_info = adapter.get_info();
        let missing = Self::missing_capabilities(&adapter);
        if !missing.is_empty() {
            return Err(GpuError::Unsupported {
                adapter: adapter_info.name.clone(),
                backend: format!("{:?}", adapter_info.backend),
                missing: missing.join("; "),
            });
        }
        let available = adapter.features();
        let timestamps = available.contains(wgpu::Features::TIMESTAMP_QUERY);
        let mut required_features = wgpu::Features::empty();
        if timestamps {
            required_features |= wgpu::Features::TIMESTAMP_QUERY;
        }
        // Ask for what the adapter has: large scenes and high resolutions need more than the
        // WebGPU defaults, and software drivers report generous limits.
        let mut required_limits = adapter.limits();
        adjust(&mut required_limits);
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("valgi device"),
                required_features,
                required_limits,
                experimental_features: wgpu::ExperimentalFeatures::disabled(),
                memory_hints: wgpu::MemoryHints::Performance,
                trace: wgpu::Trace::Off,
            })
            .await
            .map_err(|e| GpuError::Device {
                adapter: adapter_info.name.clone(),
                message: e.to_string(),
            })?;
        // Mesa's CPU drivers answer timestamp queries, but long compute dispatches that use
        // workgroup barriers come back as ~0 ms (seen with lavapipe 22.3), so on a CPU
        // adapter passes are timed by the wall clock, one submission each, which there measures
        // the work itself. VALGI_TIMING=gpu|wall overrides the choice.
        let timestamps = match std::env::var("VALGI_TIMING").as_deref() {
            Ok("wall") => false,
            Ok("gpu") => timestamps,
            _ => timestamps && adapter_info.device_type != wgpu::DeviceType::Cpu,
        };
        let uncaptured = UncapturedErrors::default();
        uncaptured.install(&device);
        Ok(Self {
            adapter,
            device,
            queue,
            adapter_info,
            timestamps,
            uncaptured,
            shared: Default::default(),
        })
    }

    /// Runs `create` under out-of-memory and validation error scopes, so that an allocation
    /// or pipeline wgpu cannot make is an error naming `what` (and how big, `bytes`) with a
    /// `remedy`, not a panic. Whatever `create` made is dropped on error.
    pub fn scoped<T>(
        &self,
        what: &str,
        bytes: Option<u64>,
        remedy: &str,
        create: impl FnOnce() -> T,
    ) -> Result<T, GpuError> {
        let out_of_memory = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let made = create();
        let invalid = pollster::block_on(validation.pop());
        let exhausted = pollster::block_on(out_of_memory.pop());
        match exhausted.or(invalid) {
            None => Ok(made),
            Some(error) => Err(GpuError::Allocation {
                what: what.to_string(),
                size: bytes.map_or_else(|| "size n/a".into(), format_bytes),
                message: describe(&error),
                remedy: remedy.to_string(),
            }),
        }
    }

    /// The first GPU error raised outside [`GpuContext::scoped`] since the last call.
    pub fn check_uncaptured(&self) -> Result<(), GpuError> {
        match self.uncaptured.take() {
            None => Ok(()),
            Some(message) => Err(GpuError::Uncaptured(message)),
        }
    }

    /// An error unless a storage buffer of `bytes` can be made and bound whole.
    pub fn check_storage_buffer(
        &self,
        what: &str,
        bytes: u64,
        remedy: &str,
    ) -> Result<(), GpuError> {
        let limits = self.device.limits();
        let limit = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        if bytes > limit {
            return Err(GpuError::Allocation {
                what: what.to_string(),
                size: format_bytes(bytes),
                message: format!(
                    "the device binds storage buffers of at most {}",
                    format_bytes(limit)
                ),
                remedy: remedy.to_string(),
            });
        }
        Ok(())
    }

    /// "name (backend)" for reports.
    pub fn adapter_label(&self) -> String {
        format!(
            "{} ({:?})",
            self.adapter_info.name, self.adapter_info.backend
        )
    }

    /// True when the adapter is a CPU implementation (lavapipe, SwiftShader, WARP …).
    pub fn is_software(&self) -> bool {
        self.adapter_info.device_type == wgpu::DeviceType::Cpu
    }

    /// Blocks until all submitted work is done.
    pub fn wait_idle(&self) -> Result<(), GpuError> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| GpuError::Readback(e.to_string()))
    }

    /// Compiles a WGSL shader from `shaders/`, with its `#include` lines resolved.
    pub fn shader(&self, name: &str) -> wgpu::ShaderModule {
        let source = crate::shaders::source(name);
        self.device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(name),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            })
    }
}

#[cfg(test)]
mod tests {
    use super::linear_groups;

    #[test]
    fn long_dispatches_wrap_into_a_second_dimension_covering_every_group() {
        assert_eq!(linear_groups(0, 65535), (1, 1));
        assert_eq!(linear_groups(65535, 65535), (65535, 1));
        assert_eq!(linear_groups(65536, 65535), (65535, 2));
        for groups in [1, 7, 100, 1000] {
            let (x, y) = linear_groups(groups, 3);
            assert!(
                x <= 3 && x * y >= groups && x * (y - 1) < groups,
                "{groups}: {x}×{y}"
            );
        }
    }
}
