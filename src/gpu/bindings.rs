//! Bind-group layouts and bind groups from one list.
//!
//! A technique declares the bindings of a shader's group once, as a `&'static [Slot]` in the
//! order of the WGSL `@binding(i)` indices; [`GroupLayout::new`] makes the layout from it and
//! [`GroupLayout::bind`] the groups, taking the resources in the same order. No binding index
//! is written twice, so the layout and the groups cannot drift apart, and a group given the
//! wrong number or kind of resources is refused where it is made, naming the slot.

/// What a shader declares at one binding.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Slot {
    /// `var<uniform>`.
    Uniform,
    /// `var<uniform>` at an offset given when the group is set (`set_bind_group`'s dynamic
    /// offsets, in slot order), bound to a [`BufferWindow`]: one group serves every window
    /// of a buffer larger than a uniform binding may be.
    DynamicUniform,
    /// `var<storage, read>`.
    Storage,
    /// `var<storage, read_write>`.
    StorageRw,
    /// `texture_2d<f32>` read with `textureLoad` (no filtering).
    Texture,
    /// `texture_2d_array<f32>` read with `textureLoad`.
    TextureArray,
    /// `texture_2d<u32>`.
    UintTexture,
    /// `texture_2d<f32>` sampled with filtering (material textures).
    FilterableTexture,
    /// `sampler` with filtering.
    FilteringSampler,
    /// `texture_depth_2d` read with `textureLoad`.
    DepthTexture,
    /// `texture_depth_2d_array` (shadow-map layers).
    DepthTextureArray,
    /// `sampler_comparison`.
    ComparisonSampler,
    /// `texture_storage_2d<FORMAT, write>`.
    StorageTexture(wgpu::TextureFormat),
    /// `texture_3d<f32>` read with `textureLoad`.
    Texture3d,
    /// `texture_storage_3d<FORMAT, write>`.
    StorageTexture3d(wgpu::TextureFormat),
}

impl Slot {
    /// The layout entry of this slot at `binding`.
    pub fn entry(self, binding: u32, visibility: wgpu::ShaderStages) -> wgpu::BindGroupLayoutEntry {
        let buffer = |ty| wgpu::BindingType::Buffer {
            ty,
            has_dynamic_offset: self == Slot::DynamicUniform,
            min_binding_size: None,
        };
        let texture = |sample_type, view_dimension| wgpu::BindingType::Texture {
            sample_type,
            view_dimension,
            multisampled: false,
        };
        let float = wgpu::TextureSampleType::Float { filterable: false };
        let d2 = wgpu::TextureViewDimension::D2;
        let ty = match self {
            Slot::Uniform | Slot::DynamicUniform => buffer(wgpu::BufferBindingType::Uniform),
            Slot::Storage => buffer(wgpu::BufferBindingType::Storage { read_only: true }),
            Slot::StorageRw => buffer(wgpu::BufferBindingType::Storage { read_only: false }),
            Slot::Texture => texture(float, d2),
            Slot::TextureArray => texture(float, wgpu::TextureViewDimension::D2Array),
            Slot::UintTexture => texture(wgpu::TextureSampleType::Uint, d2),
            Slot::FilterableTexture => {
                texture(wgpu::TextureSampleType::Float { filterable: true }, d2)
            }
            Slot::FilteringSampler => {
                wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering)
            }
            Slot::DepthTexture => texture(wgpu::TextureSampleType::Depth, d2),
            Slot::DepthTextureArray => texture(
                wgpu::TextureSampleType::Depth,
                wgpu::TextureViewDimension::D2Array,
            ),
            Slot::ComparisonSampler => {
                wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Comparison)
            }
            Slot::StorageTexture(format) => wgpu::BindingType::StorageTexture {
                access: wgpu::StorageTextureAccess::WriteOnly,
                format,
                view_dimension: wgpu::TextureViewDimension::D2,
            },
            Slot::Texture3d => texture(float, wgpu::TextureViewDimension::D3),
            Slot::StorageTexture3d(format) => wgpu::BindingType::StorageTexture {
                access: wgpu::StorageTextureAccess::WriteOnly,
                format,
                view_dimension: wgpu::TextureViewDimension::D3,
            },
        };
        wgpu::BindGroupLayoutEntry {
            binding,
            visibility,
            ty,
            count: None,
        }
    }

    fn takes(self) -> ResourceKind {
        match self {
            Slot::Uniform | Slot::Storage | Slot::StorageRw => ResourceKind::Buffer,
            Slot::DynamicUniform => ResourceKind::BufferWindow,
            Slot::ComparisonSampler | Slot::FilteringSampler => ResourceKind::Sampler,
            _ => ResourceKind::TextureView,
        }
    }
}

/// What kind of resource a [`Slot`] takes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ResourceKind {
    Buffer,
    BufferWindow,
    TextureView,
    Sampler,
}

/// A resource that can fill a [`Slot`]: a whole buffer, a texture view or a sampler.
pub trait Bindable {
    fn resource(&self) -> wgpu::BindingResource<'_>;
    fn kind(&self) -> ResourceKind;
}

impl Bindable for wgpu::Buffer {
    fn resource(&self) -> wgpu::BindingResource<'_> {
        self.as_entire_binding()
    }

    fn kind(&self) -> ResourceKind {
        ResourceKind::Buffer
    }
}

/// The first `size` bytes of a buffer, for a [`Slot::DynamicUniform`], which moves them along
/// the buffer by its dynamic offset.
pub struct BufferWindow<'a> {
    pub buffer: &'a wgpu::Buffer,
    pub size: u64,
}

impl Bindable for BufferWindow<'_> {
    fn resource(&self) -> wgpu::BindingResource<'_> {
        wgpu::BindingResource::Buffer(wgpu::BufferBinding {
            buffer: self.buffer,
            offset: 0,
            size: std::num::NonZeroU64::new(self.size),
        })
    }

    fn kind(&self) -> ResourceKind {
        ResourceKind::BufferWindow
    }
}

impl Bindable for wgpu::TextureView {
    fn resource(&self) -> wgpu::BindingResource<'_> {
        wgpu::BindingResource::TextureView(self)
    }

    fn kind(&self) -> ResourceKind {
        ResourceKind::TextureView
    }
}

impl Bindable for wgpu::Sampler {
    fn resource(&self) -> wgpu::BindingResource<'_> {
        wgpu::BindingResource::Sampler(self)
    }

    fn kind(&self) -> ResourceKind {
        ResourceKind::Sampler
    }
}

/// A bind-group layout with the slot list it was made from.
#[derive(Clone)]
pub struct GroupLayout {
    pub layout: wgpu::BindGroupLayout,
    label: &'static str,
    slots: &'static [Slot],
}

impl GroupLayout {
    pub fn new(
        device: &wgpu::Device,
        label: &'static str,
        visibility: wgpu::ShaderStages,
        slots: &'static [Slot],
    ) -> Self {
        let entries: Vec<wgpu::BindGroupLayoutEntry> = slots
            .iter()
            .enumerate()
            .map(|(i, slot)| slot.entry(i as u32, visibility))
            .collect();
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some(label),
            entries: &entries,
        });
        Self {
            layout,
            label,
            slots,
        }
    }

    /// How many bindings the layout has.
    pub fn slot_count(&self) -> usize {
        self.slots.len()
    }

    /// A group binding `resources[i]` at binding i.
    ///
    /// # Panics
    /// When the resources do not match the slots in number or kind: a programming error in
    /// the technique, caught by its first test run.
    pub fn bind(&self, device: &wgpu::Device, resources: &[&dyn Bindable]) -> wgpu::BindGroup {
        assert_eq!(
            resources.len(),
            self.slots.len(),
            "bind group '{}': {} resources for {} slots",
            self.label,
            resources.len(),
            self.slots.len()
        );
        let entries: Vec<wgpu::BindGroupEntry> = resources
            .iter()
            .zip(self.slots)
            .enumerate()
            .map(|(i, (resource, slot))| {
                assert_eq!(
                    resource.kind(),
                    slot.takes(),
                    "bind group '{}': binding {i} is a {slot:?} slot",
                    self.label
                );
                wgpu::BindGroupEntry {
                    binding: i as u32,
                    resource: resource.resource(),
                }
            })
            .collect();
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(self.label),
            layout: &self.layout,
            entries: &entries,
        })
    }
}
