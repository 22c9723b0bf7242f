//! The device's arithmetic peak, measured: a trivial kernel of dependent fused multiply-adds
//! (`shaders/bench/bench_fma.wgsl`). `valgi bench` states the gather's pair rate as a share of
//! it, and budget mode scales its fitted frame-time model by it to the device at hand.

use bytemuck::{Pod, Zeroable};

use super::{GpuContext, GpuError, Passes};

/// `FmaParams` in `shaders/bench/bench_fma.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct FmaParams {
    pub iterations: u32,
    pub pad0: u32,
    pub pad1: u32,
    pub pad2: u32,
}

/// Threads per workgroup of the FMA-peak kernel (`bench_fma.wgsl`).
pub const FMA_GROUP: u32 = 256;

/// Scalar fused multiply-adds per loop iteration of `bench_fma.wgsl`: four vec4 chains,
/// written out eight times.
pub const FMAS_PER_ITERATION: u32 = 4 * 4 * 8;

/// [`fma_peak`] measured once per device (budget mode asks for it at every method build: a
/// viewer's rebuild or a sweep's settings would measure it again, ~0.3 s on lavapipe).
pub fn device_fma_peak(ctx: &GpuContext) -> Result<f64, GpuError> {
    struct Peak(f64);
    ctx.shared(|| fma_peak(ctx).map(Peak)).map(|peak| peak.0)
}

/// Fused multiply-adds per second of the trivial kernel (best of three runs).
pub fn fma_peak(ctx: &GpuContext) -> Result<f64, GpuError> {
    let device = &ctx.device;
    let threads: u32 = FMA_GROUP * 256;
    let sink = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("fma sink"),
        size: threads as u64 * 16,
        usage: wgpu::BufferUsages::STORAGE,
        mapped_at_creation: false,
    });
    let params = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("fma params"),
        size: 16,
        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let cs = wgpu::ShaderStages::COMPUTE;
    let layout = crate::gpu::bindings::GroupLayout::new(
        device,
        "fma",
        cs,
        &[
            crate::gpu::bindings::Slot::Uniform,
            crate::gpu::bindings::Slot::StorageRw,
        ],
    );
    let group = layout.bind(device, &[&params, &sink]);
    let pipeline = super::compute_pipeline_groups(
        device,
        "fma peak",
        &ctx.shader("bench_fma.wgsl"),
        &[&layout.layout],
        "cs_main",
        &[],
    );
    let run = |iterations: u32| -> Result<f64, GpuError> {
        ctx.queue.write_buffer(
            &params,
            0,
            bytemuck::bytes_of(&FmaParams {
                iterations,
                pad0: 0,
                pad1: 0,
                pad2: 0,
            }),
        );
        let mut passes = Passes::new(ctx);
        passes.compute("fma", |pass| {
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &group, &[]);
            pass.dispatch_workgroups(threads / FMA_GROUP, 1, 1);
        })?;
        let ms = passes.finish()?.get("fma").unwrap_or(0.0).max(1e-6);
        Ok(threads as f64 * iterations as f64 * FMAS_PER_ITERATION as f64 / (ms * 1e-3))
    };
    // Grow the work until one run takes long enough to time well.
    let mut iterations = 64u32;
    let mut rate = run(iterations)?;
    while threads as f64 * iterations as f64 * FMAS_PER_ITERATION as f64 / rate < 0.2
        && iterations < 1 << 20
    {
        iterations *= 4;
        rate = run(iterations)?;
    }
    let best = (0..3)
        .map(|_| run(iterations))
        .collect::<Result<Vec<f64>, _>>()?;
    Ok(best.into_iter().fold(rate, f64::max))
}

#[cfg(test)]
mod tests {
    use super::FMAS_PER_ITERATION;

    #[test]
    fn the_peak_counts_the_fmas_its_kernel_runs() {
        let source = crate::shaders::source("bench_fma.wgsl");
        // Each `fma` statement of the loop is on vec4 chains: four scalar FMAs.
        let statements = source.matches("= fma(").count() as u32;
        assert!(statements >= 4, "{statements} fma statements");
        assert_eq!(4 * statements, FMAS_PER_ITERATION);
    }
}
