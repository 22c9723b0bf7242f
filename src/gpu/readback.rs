//! Copies GPU results back to the CPU, handling wgpu's 256-byte row alignment.

use super::{GpuContext, GpuError};

/// Reads a whole buffer (it must have `COPY_SRC`) as a vector of `T`.
pub fn read_buffer<T: bytemuck::Pod>(
    ctx: &GpuContext,
    buffer: &wgpu::Buffer,
) -> Result<Vec<T>, GpuError> {
    let size = buffer.size();
    let staging = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback staging"),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = ctx
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("readback"),
        });
    encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, size);
    ctx.queue.submit([encoder.finish()]);
    let bytes = map_and_copy(ctx, &staging)?;
    Ok(bytemuck::pod_collect_to_vec(&bytes))
}

/// Reads mip 0, layer 0 of an `Rgba32Float` texture (it must have `COPY_SRC`), row-major from
/// the top-left texel.
pub fn read_texture_rgba32f(
    ctx: &GpuContext,
    texture: &wgpu::Texture,
) -> Result<Vec<[f32; 4]>, GpuError> {
    let bytes = read_texture_bytes(ctx, texture, 16)?;
    Ok(bytemuck::pod_collect_to_vec(&bytes))
}

/// Reads mip 0, layer 0 of a texture of `texel_bytes` bytes per texel (it must have
/// `COPY_SRC`): packed rows from the top-left texel; of a 3D texture, every slice in turn.
pub fn read_texture_bytes(
    ctx: &GpuContext,
    texture: &wgpu::Texture,
    texel_bytes: u32,
) -> Result<Vec<u8>, GpuError> {
    let width = texture.width();
    let height = texture.height();
    let depth = match texture.dimension() {
        wgpu::TextureDimension::D3 => texture.depth_or_array_layers(),
        _ => 1,
    };
    let unpadded = width * texel_bytes;
    let padded =
        unpadded.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    let staging = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("texture readback staging"),
        size: padded as u64 * height as u64 * depth as u64,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = ctx
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("texture readback"),
        });
    encoder.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        wgpu::TexelCopyBufferInfo {
            buffer: &staging,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(padded),
                rows_per_image: Some(height),
            },
        },
        wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: depth,
        },
    );
    ctx.queue.submit([encoder.finish()]);
    let bytes = map_and_copy(ctx, &staging)?;
    let mut texels = Vec::with_capacity(unpadded as usize * height as usize * depth as usize);
    for row in bytes.chunks_exact(padded as usize) {
        texels.extend_from_slice(&row[..unpadded as usize]);
    }
    Ok(texels)
}

fn map_and_copy(ctx: &GpuContext, staging: &wgpu::Buffer) -> Result<Vec<u8>, GpuError> {
    let (sender, receiver) = std::sync::mpsc::channel();
    staging.map_async(wgpu::MapMode::Read, .., move |result| {
        let _ = sender.send(result);
    });
    ctx.wait_idle()?;
    receiver
        .recv()
        .map_err(|e| GpuError::Readback(e.to_string()))?
        .map_err(|e| GpuError::Readback(e.to_string()))?;
    let bytes = staging
        .get_mapped_range(..)
        .map_err(|e| GpuError::Readback(e.to_string()))?
        .to_vec();
    staging.unmap();
    Ok(bytes)
}
