//! The frame's tree splats on the GPU: the instance buffer the splat
//! pipeline draws, and the light of each splat, which a compute pass writes
//! before the frame's render pass (one shadow ray per splat, read by the
//! quad's four vertices, which each cast it before).

use super::super::trees::Splat;
use super::pipeline::Pipelines;
use super::targets::map_read;
use super::uniforms::TILE_STRIDE;
use std::ops::Range;

/// 32-bit words per splat as `splat.wgsl` reads them (its `SPLAT_WORDS`).
const SPLAT_WORDS: usize = 5;
const _: () = assert!(std::mem::size_of::<Splat>() == 4 * SPLAT_WORDS);

/// Splats per workgroup of the light pass (its `@workgroup_size`).
const WORKGROUP: u32 = 64;

/// The splat instances and their lights, room for `capacity` splats, `len`
/// written.
pub struct SplatBuffers {
    capacity: usize,
    len: usize,
    splats: wgpu::Buffer,
    lights: wgpu::Buffer,
    group: wgpu::BindGroup,
}

impl SplatBuffers {
    /// Writes `splats` to `buffers`, replacing them with buffers of the
    /// next power of two when they do not fit.
    pub fn upload(
        buffers: &mut Option<SplatBuffers>,
        (device, queue): (&wgpu::Device, &wgpu::Queue),
        pipelines: &Pipelines,
        splats: &[Splat],
    ) {
        if splats.is_empty() {
            return;
        }
        if buffers.as_ref().is_none_or(|b| b.capacity < splats.len()) {
            *buffers = Some(SplatBuffers::new(device, pipelines, splats.len().next_power_of_two()));
        }
        if let Some(b) = buffers {
            queue.write_buffer(&b.splats, 0, bytemuck::cast_slice(splats));
            b.len = splats.len();
        }
    }

    fn new(device: &wgpu::Device, pipelines: &Pipelines, capacity: usize) -> SplatBuffers {
        let buffer = |label, size: usize, usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: size as u64,
                usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::STORAGE | usage,
                mapped_at_creation: false,
            })
        };
        let splats = buffer("splats", capacity * std::mem::size_of::<Splat>(), wgpu::BufferUsages::COPY_DST);
        let lights = buffer("splat lights", capacity * std::mem::size_of::<f32>(), wgpu::BufferUsages::COPY_SRC);
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("splats"),
            layout: &pipelines.splat_layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: splats.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: lights.as_entire_binding() },
            ],
        });
        SplatBuffers { capacity, len: 0, splats, lights, group }
    }

    /// Encodes the light of each tile's splats: `tiles` gives a tile's
    /// index in the tile uniform buffer and its splats' range.
    pub fn light<'a>(
        &self,
        pass: &mut wgpu::ComputePass<'_>,
        (pipelines, frame_group, tile_group): (&Pipelines, &wgpu::BindGroup, &wgpu::BindGroup),
        tiles: impl Iterator<Item = (usize, &'a Range<u32>)>,
    ) {
        pass.set_pipeline(&pipelines.splat_light);
        pass.set_bind_group(0, frame_group, &[]);
        pass.set_bind_group(2, &self.group, &[]);
        for (k, range) in tiles.filter(|(_, r)| !r.is_empty()) {
            pass.set_bind_group(1, tile_group, &[(k as u64 * TILE_STRIDE) as u32]);
            pass.dispatch_workgroups(range.len().div_ceil(WORKGROUP as usize) as u32, 1, 1);
        }
    }

    /// The lights of the splats last written, as the last frame's light
    /// pass left them.
    pub fn read_lights(&self, device: &wgpu::Device, queue: &wgpu::Queue) -> Vec<f32> {
        let size = (self.len * std::mem::size_of::<f32>()) as u64;
        let staging = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("splat lights readback"),
            size,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let mut encoder = device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(&self.lights, 0, &staging, 0, size);
        queue.submit([encoder.finish()]);
        bytemuck::pod_collect_to_vec(&map_read(device, &staging))
    }

    /// Binds the splats and their lights as the splat pipeline's instance
    /// buffers.
    pub fn bind(&self, pass: &mut wgpu::RenderPass<'_>) {
        pass.set_vertex_buffer(0, self.splats.slice(..));
        pass.set_vertex_buffer(1, self.lights.slice(..));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shader reads as many words per splat as a [`Splat`] holds.
    #[test]
    fn the_shader_reads_a_splat_whole() {
        let module =
            naga::front::wgsl::parse_str(&super::super::shaders::raycast_source(false, false)).expect("WGSL parses");
        let (_, words) =
            module.constants.iter().find(|(_, c)| c.name.as_deref() == Some("SPLAT_WORDS")).expect("const");
        let literal = &module.global_expressions[words.init];
        assert_eq!(*literal, naga::Expression::Literal(naga::Literal::U32(SPLAT_WORDS as u32)));
    }
}
