//! A frame is a list of labelled passes recorded through [`Passes`]. Each pass is wrapped in a
//! debug group and timed with GPU timestamp queries; on adapters without them every pass is
//! submitted on its own and timed by the wall clock instead.

use std::time::Instant;

use super::{GpuContext, GpuError};

/// Milliseconds per pass label, in first-recorded order. Passes that share a label (one
/// shadow map per light, say) are summed.
#[derive(Clone, Debug, Default)]
pub struct PassTimings {
    pub passes: Vec<(String, f64)>,
    /// True when the numbers are GPU timestamps, false for the wall-clock fallback.
    pub gpu_timestamps: bool,
}

impl PassTimings {
    pub fn add(&mut self, label: &str, ms: f64) {
        match self.passes.iter_mut().find(|(l, _)| l == label) {
            Some((_, total)) => *total += ms,
            None => self.passes.push((label.to_string(), ms)),
        }
    }

    pub fn get(&self, label: &str) -> Option<f64> {
        self.passes
            .iter()
            .find(|(l, _)| l == label)
            .map(|(_, ms)| *ms)
    }

    pub fn total_ms(&self) -> f64 {
        self.passes.iter().map(|(_, ms)| ms).sum()
    }

    pub fn merge(&mut self, other: &PassTimings) {
        for (label, ms) in &other.passes {
            self.add(label, *ms);
        }
        self.gpu_timestamps &= other.gpu_timestamps;
    }

    pub fn to_json(&self) -> serde_json::Value {
        let map: serde_json::Map<String, serde_json::Value> = self
            .passes
            .iter()
            .map(|(l, ms)| (l.clone(), serde_json::json!(round3(*ms))))
            .collect();
        serde_json::Value::Object(map)
    }
}

pub fn round3(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}

/// Records labelled passes into one command encoder and times them.
pub struct Passes<'a> {
    ctx: &'a GpuContext,
    encoder: wgpu::CommandEncoder,
    query_set: Option<wgpu::QuerySet>,
    labels: Vec<String>,
    capacity: u32,
    wall: PassTimings,
}

impl<'a> Passes<'a> {
    /// `max_passes` bounds how many passes this frame may time with queries.
    pub fn new(ctx: &'a GpuContext, max_passes: u32) -> Self {
        let query_set = ctx.timestamps.then(|| {
            ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("pass timestamps"),
                ty: wgpu::QueryType::Timestamp,
                count: max_passes * 2,
            })
        });
        Self {
            ctx,
            encoder: Self::new_encoder(ctx),
            query_set,
            labels: Vec::new(),
            capacity: max_passes,
            wall: PassTimings::default(),
        }
    }

    fn new_encoder(ctx: &GpuContext) -> wgpu::CommandEncoder {
        ctx.device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("frame"),
            })
    }

    /// The encoder, for copies and clears between passes.
    pub fn encoder(&mut self) -> &mut wgpu::CommandEncoder {
        &mut self.encoder
    }

    /// Index of the next timestamp pair, or `None` when not timing with queries.
    fn next_query(&mut self, label: &str) -> Option<u32> {
        if self.query_set.is_none() || self.labels.len() as u32 >= self.capacity {
            if self.query_set.is_some() {
                log::warn!(
                    "pass '{label}' not timed: more than {} passes",
                    self.capacity
                );
            }
            return None;
        }
        self.labels.push(label.to_string());
        Some(self.labels.len() as u32 - 1)
    }

    /// Wall-clock fallback: finish what was recorded before this pass so it is not charged
    /// to the pass.
    fn flush_for_wall_clock(&mut self) -> Result<(), GpuError> {
        if self.query_set.is_none() {
            let encoder = std::mem::replace(&mut self.encoder, Self::new_encoder(self.ctx));
            self.ctx.queue.submit([encoder.finish()]);
            self.ctx.wait_idle()?;
        }
        Ok(())
    }

    fn time_wall_clock(&mut self, label: &str, started: Instant) -> Result<(), GpuError> {
        if self.query_set.is_none() {
            let encoder = std::mem::replace(&mut self.encoder, Self::new_encoder(self.ctx));
            self.ctx.queue.submit([encoder.finish()]);
            self.ctx.wait_idle()?;
            self.wall
                .add(label, started.elapsed().as_secs_f64() * 1000.0);
        }
        Ok(())
    }

    /// Opens a pass: finishes earlier work in wall-clock mode, takes a timestamp slot, pushes
    /// the debug group. Returns the start time and the (begin, end) query indices.
    fn begin_pass(&mut self, label: &str) -> Result<(Instant, Option<(u32, u32)>), GpuError> {
        self.flush_for_wall_clock()?;
        let started = Instant::now();
        let query = self.next_query(label).map(|q| (2 * q, 2 * q + 1));
        self.encoder.push_debug_group(label);
        Ok((started, query))
    }

    fn end_pass(&mut self, label: &str, started: Instant) -> Result<(), GpuError> {
        self.encoder.pop_debug_group();
        self.time_wall_clock(label, started)
    }

    /// Records one compute pass named `label`.
    pub fn compute(
        &mut self,
        label: &str,
        record: impl FnOnce(&mut wgpu::ComputePass<'_>),
    ) -> Result<(), GpuError> {
        let (started, query) = self.begin_pass(label)?;
        {
            let timestamp_writes = self.query_set.as_ref().zip(query).map(|(set, (b, e))| {
                wgpu::ComputePassTimestampWrites {
                    query_set: set,
                    beginning_of_pass_write_index: Some(b),
                    end_of_pass_write_index: Some(e),
                }
            });
            let mut pass = self
                .encoder
                .begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some(label),
                    timestamp_writes,
                });
            record(&mut pass);
        }
        self.end_pass(label, started)
    }

    /// Records one render pass named `label` into the given attachments.
    pub fn render(
        &mut self,
        label: &str,
        color_attachments: &[Option<wgpu::RenderPassColorAttachment<'_>>],
        depth_stencil_attachment: Option<wgpu::RenderPassDepthStencilAttachment<'_>>,
        record: impl FnOnce(&mut wgpu::RenderPass<'_>),
    ) -> Result<(), GpuError> {
        let (started, query) = self.begin_pass(label)?;
        {
            let timestamp_writes = self.query_set.as_ref().zip(query).map(|(set, (b, e))| {
                wgpu::RenderPassTimestampWrites {
                    query_set: set,
                    beginning_of_pass_write_index: Some(b),
                    end_of_pass_write_index: Some(e),
                }
            });
            let mut pass = self.encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some(label),
                color_attachments,
                depth_stencil_attachment,
                timestamp_writes,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            record(&mut pass);
        }
        self.end_pass(label, started)
    }

    /// Submits the frame, waits for it, and returns the per-pass times.
    pub fn finish(mut self) -> Result<PassTimings, GpuError> {
        let Some(query_set) = self.query_set.take() else {
            self.ctx.queue.submit([self.encoder.finish()]);
            self.ctx.wait_idle()?;
            return Ok(self.wall);
        };
        let count = self.labels.len() as u32 * 2;
        if count == 0 {
            self.ctx.queue.submit([self.encoder.finish()]);
            self.ctx.wait_idle()?;
            return Ok(PassTimings {
                passes: Vec::new(),
                gpu_timestamps: true,
            });
        }
        let resolve = self.ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("timestamp resolve"),
            size: count as u64 * 8,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        self.encoder
            .resolve_query_set(&query_set, 0..count, &resolve, 0);
        self.ctx.queue.submit([self.encoder.finish()]);
        let ticks: Vec<u64> = super::read_buffer(self.ctx, &resolve)?;
        let period_ns = self.ctx.queue.get_timestamp_period() as f64;
        let mut timings = PassTimings {
            passes: Vec::new(),
            gpu_timestamps: true,
        };
        for (i, label) in self.labels.iter().enumerate() {
            let (begin, end) = (ticks[2 * i], ticks[2 * i + 1]);
            let ms = end.saturating_sub(begin) as f64 * period_ns / 1.0e6;
            timings.add(label, ms);
        }
        Ok(timings)
    }
}
