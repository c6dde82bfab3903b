//! GPU time of a frame's passes (from the first — the splats' light or the
//! compute rays, if any — to the end of the render pass) from timestamp queries, where the adapter has them
//! (`None` elsewhere; the caller then reports CPU-side time).

use super::targets::map_read;

/// Two timestamps around a pass.
pub struct PassTimer {
    queries: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    read: wgpu::Buffer,
    period_ns: f32,
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
            count: 2,
        });
        let buffer = |usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("timestamps"),
                size: 16,
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

    /// The first timestamp at the start of a compute pass that precedes
    /// the render pass (the splats' light, or the rays').
    pub fn compute_start(&self) -> wgpu::ComputePassTimestampWrites<'_> {
        wgpu::ComputePassTimestampWrites {
            query_set: &self.queries,
            beginning_of_pass_write_index: Some(0),
            end_of_pass_write_index: None,
        }
    }

    /// The render pass's timestamps: its end, and its start if it is
    /// `first` (no compute pass before it).
    pub fn render(&self, first: bool) -> wgpu::RenderPassTimestampWrites<'_> {
        wgpu::RenderPassTimestampWrites {
            query_set: &self.queries,
            beginning_of_pass_write_index: first.then_some(0),
            end_of_pass_write_index: Some(1),
        }
    }

    /// Resolves the queries after the pass, in the same encoder.
    pub fn resolve(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.resolve_query_set(&self.queries, 0..2, &self.resolve, 0);
        encoder.copy_buffer_to_buffer(&self.resolve, 0, &self.read, 0, 16);
    }

    /// The pass's duration in milliseconds, once submitted.
    pub fn read_ms(&self, device: &wgpu::Device) -> Option<f64> {
        let bytes = map_read(device, &self.read);
        let stamps: &[u64] = bytemuck::try_cast_slice(&bytes).ok()?;
        let [start, end] = stamps.get(..2)?.try_into().ok()?;
        (end > start).then(|| (end - start) as f64 * self.period_ns as f64 / 1e6)
    }
}
