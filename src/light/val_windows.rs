//! The VAL buffer bound as uniform windows of [`VAL_WINDOW`] VALs
//! (`shaders/light/val_windows.wgsl`), for kernels that read the VAL list in order with every
//! invocation on the same VAL: the sparse gather's window form and brute force. One bind group
//! serves every window through two dynamic offsets (the window's VALs and its record), and the
//! kernel runs one dispatch per window, carrying whatever it sums from one to the next in a
//! buffer of its own.
//!
//! Why: Mesa 22.3's llvmpipe loads from a storage buffer or workgroup memory lane by lane even
//! where every lane reads the same address, and from a uniform buffer at such an address once
//! (`src/vals/README.md`, "How lavapipe loads memory"). A uniform binding holds 64 KiB at most,
//! hence the windows. On a GPU one small dispatch per window would leave most of it idle, so
//! techniques take the windows on a CPU device only, by default.

use bytemuck::{Pod, Zeroable};

use super::rsm::{GpuVal, Rsm, VAL_WINDOW};
use crate::gpu::bindings::{BufferWindow, GroupLayout, Slot};
use crate::gpu::GpuContext;

/// How a kernel that can read either way reads the VAL list: staged through workgroup memory
/// in tiles, or from uniform windows. Both add the VALs in the same order and write the same
/// bits.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ValReads {
    /// Windows on a CPU device (unless the kernel is split over VAL slices), tiles on a GPU.
    #[default]
    Auto,
    /// Staged through workgroup memory a tile at a time; a kernel may split them over VAL
    /// slices to fill a GPU.
    Tiles,
    /// Uniform windows of [`VAL_WINDOW`] VALs, one dispatch per window, whatever the kernel
    /// sums carried in a buffer between them; never split.
    Windows,
}

impl ValReads {
    /// The option's values, as `MethodOptions::choice` takes them.
    pub const CHOICES: &'static [&'static str] = &["auto", "tiles", "windows"];

    /// One of [`Self::CHOICES`] (anything else is `auto`; `choice` has checked it).
    pub fn parse(choice: &str) -> Self {
        match choice {
            "tiles" => Self::Tiles,
            "windows" => Self::Windows,
            _ => Self::Auto,
        }
    }

    /// Whether the kernel reads windows: on a CPU device or when asked, where the VAL buffer
    /// holds whole windows (`available`) and the kernel is not split (`slices` requested, 0
    /// automatic).
    pub fn windows(self, cpu_device: bool, available: bool, slices: u32) -> bool {
        available
            && match self {
                Self::Auto => cpu_device && slices <= 1,
                Self::Tiles => false,
                Self::Windows => true,
            }
    }

    /// The name of what runs: `windows` or `tiles`.
    pub fn name(windows: bool) -> &'static str {
        if windows {
            "windows"
        } else {
            "tiles"
        }
    }
}

/// `ValWindow` in `val_windows.wgsl`: which window one dispatch reads, one record per window
/// at the device's uniform offset alignment.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct ValWindow {
    /// Index of the window's first VAL.
    pub first: u32,
    pub pad0: u32,
    pub pad1: u32,
    pub pad2: u32,
}

/// The group (`@group(2)` of a kernel that includes `val_windows.wgsl`): the VAL window and
/// its record, both at dynamic offsets.
pub const WINDOW_BINDINGS: &[Slot] = &[Slot::DynamicUniform, Slot::DynamicUniform];

/// Bytes of one window of VALs.
pub const WINDOW_BYTES: u64 = VAL_WINDOW * std::mem::size_of::<GpuVal>() as u64;

/// A layout for [`WINDOW_BINDINGS`], visible to the shader stages `visibility`.
pub fn layout(device: &wgpu::Device, visibility: wgpu::ShaderStages) -> GroupLayout {
    GroupLayout::new(device, "val windows", visibility, WINDOW_BINDINGS)
}

/// An RSM's VAL buffer as windows, bound through `layout` (made by [`layout`]).
pub struct ValWindows {
    group: wgpu::BindGroup,
    /// Windows in the VAL buffer (one dispatch each).
    pub count: u32,
    /// Bytes between two records: the device's uniform offset alignment.
    record_stride: u32,
    /// Keeps the records alive beside the group.
    _records: wgpu::Buffer,
}

impl ValWindows {
    /// `None` where the VAL buffer is not whole windows ([`Rsm::val_windows`]: the device's
    /// binding limits left no room for the padding).
    pub fn new(ctx: &GpuContext, rsm: &Rsm, layout: &GroupLayout) -> Option<Self> {
        use wgpu::util::DeviceExt;
        if !rsm.val_windows {
            return None;
        }
        let count = u32::try_from(rsm.vals_buffer.size() / WINDOW_BYTES).ok()?;
        let record_stride = ctx.device.limits().min_uniform_buffer_offset_alignment;
        let mut records = vec![0u8; count as usize * record_stride as usize];
        for (w, record) in records.chunks_exact_mut(record_stride as usize).enumerate() {
            let window = ValWindow {
                first: (w as u64 * VAL_WINDOW) as u32,
                ..Default::default()
            };
            record[..std::mem::size_of::<ValWindow>()].copy_from_slice(bytemuck::bytes_of(&window));
        }
        let records = ctx
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("val windows"),
                contents: &records,
                usage: wgpu::BufferUsages::UNIFORM,
            });
        let group = layout.bind(
            &ctx.device,
            &[
                &BufferWindow {
                    buffer: &rsm.vals_buffer,
                    size: WINDOW_BYTES,
                },
                &BufferWindow {
                    buffer: &records,
                    size: std::mem::size_of::<ValWindow>() as u64,
                },
            ],
        );
        Some(Self {
            group,
            count,
            record_stride,
            _records: records,
        })
    }

    /// Sets group `index` to each window in turn and runs `dispatch` after each: one
    /// dispatch per window of the buffer, in list order. Windows past the frame's VAL count
    /// return at once in the kernel (`window_past_count`).
    pub fn for_each(
        &self,
        pass: &mut wgpu::ComputePass<'_>,
        index: u32,
        mut dispatch: impl FnMut(&mut wgpu::ComputePass<'_>),
    ) {
        for w in 0..self.count {
            let offsets = [w * WINDOW_BYTES as u32, w * self.record_stride];
            pass.set_bind_group(index, &self.group, &offsets);
            dispatch(pass);
        }
    }
}
