//! GPU resources created through these helpers are counted, so every method can report the
//! bytes of GPU memory it owns (buffers and textures, mip chains included).

use wgpu::util::DeviceExt;

/// Running total of the bytes a method has allocated on the GPU.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GpuBytes(pub u64);

impl GpuBytes {
    pub fn buffer(&mut self, device: &wgpu::Device, desc: &wgpu::BufferDescriptor) -> wgpu::Buffer {
        self.0 += desc.size;
        device.create_buffer(desc)
    }

    pub fn buffer_init(
        &mut self,
        device: &wgpu::Device,
        label: &str,
        contents: &[u8],
        usage: wgpu::BufferUsages,
    ) -> wgpu::Buffer {
        // wgpu rejects empty buffers bound as storage; keep one element's worth instead.
        let padded;
        let contents = if contents.is_empty() {
            padded = [0u8; 16];
            &padded[..]
        } else {
            contents
        };
        self.0 += contents.len() as u64;
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents,
            usage,
        })
    }

    pub fn texture(
        &mut self,
        device: &wgpu::Device,
        desc: &wgpu::TextureDescriptor,
    ) -> wgpu::Texture {
        self.0 += texture_bytes(desc);
        device.create_texture(desc)
    }

    /// A single-layer 2D texture without mips.
    pub fn texture_2d(
        &mut self,
        device: &wgpu::Device,
        label: &str,
        (width, height): (u32, u32),
        format: wgpu::TextureFormat,
        usage: wgpu::TextureUsages,
    ) -> wgpu::Texture {
        self.texture(
            device,
            &wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d {
                    width,
                    height,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            },
        )
    }

    /// A uniform buffer sized for one `T`, written each frame with `queue.write_buffer`.
    pub fn uniform<T>(&mut self, device: &wgpu::Device, label: &str) -> wgpu::Buffer {
        self.buffer(
            device,
            &wgpu::BufferDescriptor {
                label: Some(label),
                size: std::mem::size_of::<T>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            },
        )
    }

    /// A parameter block that compute kernels read as read-only storage (render passes may
    /// still bind it as a uniform). Mesa's lavapipe specialises a compute pipeline on the
    /// uniform values its branches and loops read and keeps every variant until the
    /// pipeline is destroyed: with the sparse kernels' block as a uniform the process grew
    /// ~1.8 MB a frame (tests/soak.rs); as storage it stays flat, at no cost on hardware.
    pub fn params<T>(&mut self, device: &wgpu::Device, label: &str) -> wgpu::Buffer {
        self.buffer(
            device,
            &wgpu::BufferDescriptor {
                label: Some(label),
                size: std::mem::size_of::<T>() as u64,
                usage: wgpu::BufferUsages::UNIFORM
                    | wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            },
        )
    }

    pub fn add(&mut self, other: GpuBytes) {
        self.0 += other.0;
    }
}

/// Bytes of one block (one texel for uncompressed formats) of `format`.
pub fn block_bytes(format: wgpu::TextureFormat) -> u64 {
    format
        .block_copy_size(Some(wgpu::TextureAspect::All))
        .or_else(|| format.block_copy_size(Some(wgpu::TextureAspect::DepthOnly)))
        .unwrap_or(4) as u64
}

/// Bytes a texture occupies: every mip level of every layer, at the format's block size.
pub fn texture_bytes(desc: &wgpu::TextureDescriptor) -> u64 {
    let block = block_bytes(desc.format);
    let (bw, bh) = desc.format.block_dimensions();
    let mut total = 0u64;
    for level in 0..desc.mip_level_count {
        let size = desc.size.mip_level_size(level, desc.dimension);
        let blocks_x = size.width.div_ceil(bw) as u64;
        let blocks_y = size.height.div_ceil(bh) as u64;
        total += blocks_x * blocks_y * size.depth_or_array_layers as u64 * block;
    }
    total * desc.sample_count as u64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texture_bytes_counts_mips_and_layers() {
        let desc = wgpu::TextureDescriptor {
            label: None,
            size: wgpu::Extent3d {
                width: 4,
                height: 4,
                depth_or_array_layers: 6,
            },
            mip_level_count: 3,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba16Float,
            usage: wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        };
        // (16 + 4 + 1) texels × 6 layers × 8 bytes.
        assert_eq!(texture_bytes(&desc), 21 * 6 * 8);
        let depth = wgpu::TextureDescriptor {
            format: wgpu::TextureFormat::Depth32Float,
            mip_level_count: 1,
            ..desc
        };
        assert_eq!(texture_bytes(&depth), 16 * 6 * 4);
    }
}
