//! The device's stage clock: timestamps written inside the substeps' compute pass, at the
//! boundaries of the stages, where the adapter supports them (`TIMESTAMP_QUERY` and
//! `TIMESTAMP_QUERY_INSIDE_PASSES`). Read back with the state, they give each stage's kernel
//! time; without them the device's work is one share, the host's wait.

use super::*;
use crate::schedule::{StageKind, StageTimes};

/// The features the clock needs.
pub const FEATURES: wgpu::Features =
    wgpu::Features::TIMESTAMP_QUERY.union(wgpu::Features::TIMESTAMP_QUERY_INSIDE_PASSES);

/// Timestamps a frame may hold: a frame needing more (one per substep and stage on the device,
/// one per submit) is not timed by stage.
pub const CAPACITY: u32 = 4096;

/// The query set, its resolve and read buffers, and what each timestamp closes.
pub(super) struct Clock {
    set: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    read: wgpu::Buffer,
    /// The stage whose kernels end at each written timestamp (`None`: a submit's start).
    marks: Vec<Option<StageKind>>,
    /// Nanoseconds per tick.
    period: f64,
    /// Kernel time per stage since [`Self::take`].
    times: StageTimes,
    /// A submit of this frame went untimed (no room): the times are partial.
    overflowed: bool,
    /// Whether to write timestamps ([`GpuSolver::set_clock`]).
    pub(super) on: bool,
}

impl Clock {
    /// A clock on `ctx`'s device, if it has the features.
    pub(super) fn new(ctx: &GpuContext) -> Option<Self> {
        if !ctx.device.features().contains(FEATURES) {
            return None;
        }
        let bytes = u64::from(CAPACITY) * u64::from(wgpu::QUERY_SIZE);
        let buffer = |label, usage| {
            ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: bytes,
                usage,
                mapped_at_creation: false,
            })
        };
        Some(Self {
            set: ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("stage clock"),
                ty: wgpu::QueryType::Timestamp,
                count: CAPACITY,
            }),
            resolve: buffer(
                "stage clock resolve",
                wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            ),
            read: buffer(
                "stage clock read",
                wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            ),
            marks: Vec::with_capacity(CAPACITY as usize),
            period: f64::from(ctx.queue.get_timestamp_period()),
            times: StageTimes::default(),
            overflowed: false,
            on: false,
        })
    }

    /// Whether a submit writing `count` timestamps is timed: on, and room for all of them.
    /// A submit that does not fit marks the frame's times partial.
    pub(super) fn admits(&mut self, count: u32) -> bool {
        if !self.on {
            return false;
        }
        let fits = self.marks.len() + count as usize <= CAPACITY as usize;
        self.overflowed |= !fits;
        fits
    }

    /// Writes a timestamp closing `stage`'s kernels (`None`: a submit's start).
    pub(super) fn mark(&mut self, pass: &mut wgpu::ComputePass<'_>, stage: Option<StageKind>) {
        pass.write_timestamp(&self.set, self.marks.len() as u32);
        self.marks.push(stage);
    }

    /// Resolves the written timestamps into the read buffer (recorded before the state's
    /// read-back copy, so one wait covers both).
    pub(super) fn resolve(&self, encoder: &mut wgpu::CommandEncoder) {
        let n = self.marks.len() as u32;
        if n == 0 {
            return;
        }
        encoder.resolve_query_set(&self.set, 0..n, &self.resolve, 0);
        let bytes = u64::from(n) * u64::from(wgpu::QUERY_SIZE);
        encoder.copy_buffer_to_buffer(&self.resolve, 0, &self.read, 0, bytes);
    }

    /// After the read-back's wait: adds the resolved intervals to each stage's time and
    /// starts over.
    pub(super) fn collect(&mut self, ctx: &GpuContext) -> Result<(), GpuError> {
        let n = self.marks.len();
        if n == 0 {
            return Ok(());
        }
        let bytes = (n * wgpu::QUERY_SIZE as usize) as u64;
        let (marks, times, period) = (&self.marks, &mut self.times, self.period);
        super::map_read(ctx, &self.read, bytes, |view| {
            let ticks: &[u64] = bytemuck::cast_slice(view);
            for (i, stage) in marks.iter().enumerate().skip(1) {
                if let Some(kind) = stage {
                    // A device may reorder or reset its counter: a negative span is dropped.
                    let span = ticks[i].saturating_sub(ticks[i - 1]) as f64 * period;
                    times[*kind] += std::time::Duration::from_nanos(span as u64);
                }
            }
        })?;
        self.marks.clear();
        Ok(())
    }

    /// The frame's kernel time per stage, if the clock is on and every submit of the frame
    /// was timed; starts over.
    pub(super) fn take(&mut self) -> Option<StageTimes> {
        let times = std::mem::take(&mut self.times);
        let whole = !std::mem::take(&mut self.overflowed);
        (self.on && whole).then_some(times)
    }
}
