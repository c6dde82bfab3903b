//! GPU time of a frame's passes from timestamp queries, where the adapter
//! has them (`None` elsewhere; the caller then reports CPU-side time): the
//! whole frame, from the start of its first pass to the end of its render
//! pass (or of its rays where nothing is rasterised), and with rays in a
//! compute pass (which then comes first) the rays' pass and the depth fill
//! after it.

use super::targets::map_read;

/// Query indices: the first pass's start, the render pass's end, the rays'
/// end, the depth fill's end.
const FRAME_START: u32 = 0;
const FRAME_END: u32 = 1;
const RAYS_END: u32 = 2;
const FILL_END: u32 = 3;
const QUERIES: u32 = 4;

/// The timestamps of a frame's passes.
pub struct PassTimer {
    queries: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    read: wgpu::Buffer,
    period_ns: f32,
}

/// GPU milliseconds of one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GpuTimes {
    /// The whole frame.
    pub total_ms: f64,
    /// The compute rays' pass, and the depth fill after it (with rays in
    /// a compute pass).
    pub rays_ms: Option<(f64, f64)>,
}

impl PassTimer {
    /// A timer, if `enabled` (the device has `TIMESTAMP_QUERY`).
    pub fn new(device: &wgpu::Device, queue: &wgpu::Queue, enabled: bool) -> Option<PassTimer> {
        if !enabled {
            return None;
        }
        let queries = device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("pass time"),
            ty: wgpu::QueryType::Timestamp,
            count: QUERIES,
        });
        let buffer = |usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("timestamps"),
                size: 8 * QUERIES as u64,
                usage,
                mapped_at_creation: false,
            })
        };
        Some(PassTimer {
            queries,
            resolve: buffer(wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC),
            read: buffer(wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ),
            period_ns: queue.get_timestamp_period(),
        })
    }

    /// The splats' light pass: the frame's start if it is `first`.
    pub fn light(&self, first: bool) -> Option<wgpu::ComputePassTimestampWrites<'_>> {
        first.then_some(wgpu::ComputePassTimestampWrites {
            query_set: &self.queries,
            beginning_of_pass_write_index: Some(FRAME_START),
            end_of_pass_write_index: None,
        })
    }

    /// The compute rays' pass, the frame's first.
    pub fn rays(&self) -> wgpu::ComputePassTimestampWrites<'_> {
        wgpu::ComputePassTimestampWrites {
            query_set: &self.queries,
            beginning_of_pass_write_index: Some(FRAME_START),
            end_of_pass_write_index: Some(RAYS_END),
        }
    }

    /// The depth fill after the compute rays.
    pub fn fill(&self) -> wgpu::RenderPassTimestampWrites<'_> {
        wgpu::RenderPassTimestampWrites {
            query_set: &self.queries,
            beginning_of_pass_write_index: None,
            end_of_pass_write_index: Some(FILL_END),
        }
    }

    /// The render pass: the frame's end, and its start if it is `first`.
    pub fn render(&self, first: bool) -> wgpu::RenderPassTimestampWrites<'_> {
        wgpu::RenderPassTimestampWrites {
            query_set: &self.queries,
            beginning_of_pass_write_index: first.then_some(FRAME_START),
            end_of_pass_write_index: Some(FRAME_END),
        }
    }

    /// Resolves the queries after the passes, in the same encoder.
    pub fn resolve(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.resolve_query_set(&self.queries, 0..QUERIES, &self.resolve, 0);
        encoder.copy_buffer_to_buffer(&self.resolve, 0, &self.read, 0, 8 * QUERIES as u64);
    }

    /// The frame's times once submitted: with a compute rays' pass (`rays`)
    /// its time, and the depth fill's if there was a render pass after it
    /// (`raster`; without one the frame ends with the rays).
    pub fn read(&self, device: &wgpu::Device, rays: bool, raster: bool) -> Option<GpuTimes> {
        let bytes = map_read(device, &self.read);
        let stamps: &[u64] = bytemuck::try_cast_slice(&bytes).ok()?;
        let stamp = |k: u32| stamps.get(k as usize).copied();
        let ms = |from: u32, to: u32| {
            let (a, b) = (stamp(from)?, stamp(to)?);
            (b >= a).then(|| (b - a) as f64 * self.period_ns as f64 / 1e6)
        };
        let end = if raster { FRAME_END } else { RAYS_END };
        let total_ms = ms(FRAME_START, end).filter(|&t| t > 0.0)?;
        let fill_ms = if raster { ms(RAYS_END, FILL_END) } else { Some(0.0) };
        let rays_ms = if rays { ms(FRAME_START, RAYS_END).zip(fill_ms) } else { None };
        Some(GpuTimes { total_ms, rays_ms })
    }
}
