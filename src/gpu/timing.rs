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

/// Which part of a frame a pass belongs to: the view-free update (the lighting solution) or
/// the record of one view.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scope {
    Solution,
    View(usize),
}

/// Timestamp queries per query set; the pass list opens another set when one is full, so it
/// never needs to be told how many passes a frame will record.
const QUERIES_PER_SET: u32 = 128;

/// One frame's pass times split by [`Scope`].
#[derive(Clone, Debug, Default)]
pub struct FrameTimings {
    pub solution: PassTimings,
    pub views: Vec<PassTimings>,
}

impl FrameTimings {
    /// Every pass of the frame, summed by label (the mono JSON line's `passes`).
    pub fn merged(&self) -> PassTimings {
        let mut all = self.solution.clone();
        for view in &self.views {
            all.merge(view);
        }
        all
    }

    fn scope_mut(&mut self, scope: Scope) -> &mut PassTimings {
        match scope {
            Scope::Solution => &mut self.solution,
            Scope::View(i) => {
                if self.views.len() <= i {
                    let gpu = self.solution.gpu_timestamps;
                    self.views.resize(
                        i + 1,
                        PassTimings {
                            passes: vec![],
                            gpu_timestamps: gpu,
                        },
                    );
                }
                &mut self.views[i]
            }
        }
    }

    /// How many passes the solution recorded under `label` (a test that the lighting is
    /// updated once per frame, not once per view, counts these).
    pub fn solution_has(&self, label: &str) -> bool {
        self.solution.get(label).is_some()
    }
}

/// Records labelled passes into one command encoder and times them.
pub struct Passes<'a> {
    ctx: &'a GpuContext,
    encoder: wgpu::CommandEncoder,
    /// `None` on adapters timed by the wall clock.
    query_sets: Option<Vec<wgpu::QuerySet>>,
    /// (scope, label) of every pass timed with queries, in recording order.
    labels: Vec<(Scope, String)>,
    scope: Scope,
    /// Passes recorded per scope and label, timed or not.
    counts: Vec<(Scope, String, u32)>,
    /// CPU work charged to a scope ([`Passes::add_cpu`]).
    cpu: Vec<(Scope, String, f64)>,
    wall: FrameTimings,
}

impl<'a> Passes<'a> {
    pub fn new(ctx: &'a GpuContext) -> Self {
        Self {
            ctx,
            encoder: Self::new_encoder(ctx),
            query_sets: ctx.timestamps.then(Vec::new),
            labels: Vec::new(),
            scope: Scope::Solution,
            counts: Vec::new(),
            cpu: Vec::new(),
            wall: FrameTimings {
                solution: PassTimings::default(),
                views: vec![],
            },
        }
    }

    fn new_encoder(ctx: &GpuContext) -> wgpu::CommandEncoder {
        ctx.device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("frame"),
            })
    }

    /// Passes recorded from now on belong to `scope`.
    pub fn set_scope(&mut self, scope: Scope) {
        self.scope = scope;
    }

    pub fn scope(&self) -> Scope {
        self.scope
    }

    /// How many passes labelled `label` were recorded in `scope` so far.
    pub fn count(&self, scope: Scope, label: &str) -> u32 {
        self.counts
            .iter()
            .find(|(s, l, _)| *s == scope && l == label)
            .map_or(0, |(_, _, n)| *n)
    }

    /// The encoder, for copies and clears between passes.
    pub fn encoder(&mut self) -> &mut wgpu::CommandEncoder {
        &mut self.encoder
    }

    /// The query set and index of the next timestamp pair, or `None` when not timing with
    /// queries.
    fn next_query(&mut self, label: &str) -> Option<(usize, u32)> {
        let scope = self.scope;
        match self
            .counts
            .iter_mut()
            .find(|(s, l, _)| *s == scope && l == label)
        {
            Some((_, _, n)) => *n += 1,
            None => self.counts.push((scope, label.to_string(), 1)),
        }
        let sets = self.query_sets.as_mut()?;
        let index = self.labels.len() as u32;
        let set = (index / (QUERIES_PER_SET / 2)) as usize;
        if set == sets.len() {
            sets.push(self.ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("pass timestamps"),
                ty: wgpu::QueryType::Timestamp,
                count: QUERIES_PER_SET,
            }));
        }
        self.labels.push((scope, label.to_string()));
        Some((set, 2 * (index % (QUERIES_PER_SET / 2))))
    }

    /// Wall-clock fallback: finish what was recorded before this pass so it is not charged
    /// to the pass.
    fn flush_for_wall_clock(&mut self) -> Result<(), GpuError> {
        if self.query_sets.is_none() {
            let encoder = std::mem::replace(&mut self.encoder, Self::new_encoder(self.ctx));
            self.ctx.queue.submit([encoder.finish()]);
            self.ctx.wait_idle()?;
        }
        Ok(())
    }

    fn time_wall_clock(&mut self, label: &str, started: Instant) -> Result<(), GpuError> {
        if self.query_sets.is_none() {
            let encoder = std::mem::replace(&mut self.encoder, Self::new_encoder(self.ctx));
            self.ctx.queue.submit([encoder.finish()]);
            self.ctx.wait_idle()?;
            let scope = self.scope;
            self.wall
                .scope_mut(scope)
                .add(label, started.elapsed().as_secs_f64() * 1000.0);
        }
        Ok(())
    }

    /// Opens a pass: finishes earlier work in wall-clock mode, takes a timestamp slot, pushes
    /// the debug group. Returns the start time and the query slot.
    fn begin_pass(&mut self, label: &str) -> Result<(Instant, Option<(usize, u32)>), GpuError> {
        self.flush_for_wall_clock()?;
        let started = Instant::now();
        let query = self.next_query(label);
        self.encoder.push_debug_group(label);
        Ok((started, query))
    }

    fn end_pass(&mut self, label: &str, started: Instant) -> Result<(), GpuError> {
        self.encoder.pop_debug_group();
        self.time_wall_clock(label, started)
    }

    /// The device the passes are recorded for (kernels built on first use need it).
    pub fn ctx(&self) -> &'a GpuContext {
        self.ctx
    }

    /// Records one compute pass named `label`.
    pub fn compute(
        &mut self,
        label: &str,
        record: impl FnOnce(&mut wgpu::ComputePass<'_>),
    ) -> Result<(), GpuError> {
        let (started, query) = self.begin_pass(label)?;
        {
            let timestamp_writes = query.and_then(|(set, q)| {
                let set = &self.query_sets.as_ref()?[set];
                Some(wgpu::ComputePassTimestampWrites {
                    query_set: set,
                    beginning_of_pass_write_index: Some(q),
                    end_of_pass_write_index: Some(q + 1),
                })
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
            let timestamp_writes = query.and_then(|(set, q)| {
                let set = &self.query_sets.as_ref()?[set];
                Some(wgpu::RenderPassTimestampWrites {
                    query_set: set,
                    beginning_of_pass_write_index: Some(q),
                    end_of_pass_write_index: Some(q + 1),
                })
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

    /// Submits the frame, waits for it, and returns the per-pass times of every scope.
    pub fn finish_scoped(mut self) -> Result<FrameTimings, GpuError> {
        let cpu = std::mem::take(&mut self.cpu);
        let add_cpu = |mut timings: FrameTimings| {
            for (scope, label, ms) in &cpu {
                timings.scope_mut(*scope).add(label, *ms);
            }
            timings
        };
        let Some(query_sets) = self.query_sets.take() else {
            self.ctx.queue.submit([self.encoder.finish()]);
            self.ctx.wait_idle()?;
            let wall = std::mem::take(&mut self.wall);
            return Ok(add_cpu(wall));
        };
        let mut timings = FrameTimings {
            solution: PassTimings {
                passes: Vec::new(),
                gpu_timestamps: true,
            },
            views: vec![],
        };
        let count = self.labels.len() as u32 * 2;
        if count == 0 {
            self.ctx.queue.submit([self.encoder.finish()]);
            self.ctx.wait_idle()?;
            return Ok(add_cpu(timings));
        }
        let resolve = self.ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("timestamp resolve"),
            size: query_sets.len() as u64 * QUERIES_PER_SET as u64 * 8,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        for (i, set) in query_sets.iter().enumerate() {
            let used = (count - i as u32 * QUERIES_PER_SET).min(QUERIES_PER_SET);
            let offset = i as u64 * QUERIES_PER_SET as u64 * 8;
            self.encoder
                .resolve_query_set(set, 0..used, &resolve, offset);
        }
        self.ctx.queue.submit([self.encoder.finish()]);
        let ticks: Vec<u64> = super::read_buffer(self.ctx, &resolve)?;
        let period_ns = self.ctx.queue.get_timestamp_period() as f64;
        for (i, (scope, label)) in self.labels.iter().enumerate() {
            let (begin, end) = (ticks[2 * i], ticks[2 * i + 1]);
            let ms = end.saturating_sub(begin) as f64 * period_ns / 1.0e6;
            timings.scope_mut(*scope).add(label, ms);
        }
        Ok(add_cpu(timings))
    }

    /// Submits the frame, waits for it, and returns the per-pass times of all scopes summed.
    pub fn finish(self) -> Result<PassTimings, GpuError> {
        Ok(self.finish_scoped()?.merged())
    }
}

impl Passes<'_> {
    /// Passes recorded in `scope` so far, per label.
    pub fn counts(&self, scope: Scope) -> Vec<(String, u32)> {
        self.counts
            .iter()
            .filter(|(s, _, _)| *s == scope)
            .map(|(_, l, n)| (l.clone(), *n))
            .collect()
    }

    /// Adds CPU work (a path tracer's render) to the current scope's times.
    pub fn add_cpu(&mut self, label: &str, ms: f64) {
        let scope = self.scope;
        self.cpu.push((scope, label.to_string(), ms));
    }
}
