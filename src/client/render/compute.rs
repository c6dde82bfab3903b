//! Ray casting in a compute pass (`shaders/compute.wgsl`), the alternative
//! to hull fragments for GPUs that shade fragments on a small part of the
//! chip: a data-centre GPU such as the H200 runs fragment shaders on a few
//! of its multiprocessors and compute shaders on all of them. One
//! invocation per pixel casts through the ray-cast tiles listed for its bin
//! of the screen and shades the nearest hit; a full-screen pass then writes
//! the hits' depth for the terrain meshes and splats drawn after, if any
//! (without them the frame is this pass alone). The traversal
//! and shading are the fragments' functions, so both agree with the CPU
//! reference alike.

use super::pipeline::{COLOUR_FORMAT, DEPTH_FORMAT, PIXEL_DATA_FORMAT, RayVariant};
use super::shaders;
use super::targets::Targets;
use super::timer::PassTimer;
use std::collections::HashMap;

/// Side of a workgroup's square of pixels (`@workgroup_size(8, 8)`).
const WORKGROUP_SIDE: u32 = 8;
/// Side of a bin of the screen, pixels (`BIN_PX`).
const BIN_PX: u32 = 32;

/// Where a frame's rays are cast.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum RayPass {
    /// From each ray-cast tile's hull fragments (dissertation 6.4).
    #[default]
    Fragment,
    /// In a compute pass, one invocation per pixel.
    Compute,
}

impl std::str::FromStr for RayPass {
    type Err = String;

    fn from_str(text: &str) -> Result<RayPass, String> {
        match text {
            "fragment" => Ok(RayPass::Fragment),
            "compute" => Ok(RayPass::Compute),
            _ => Err(format!("{text:?} is not a ray pass (fragment or compute)")),
        }
    }
}

/// The compute module, its layouts and pipelines, the tiles' buffer bound as
/// an array, and the last frame's bindings.
pub struct ComputeRays {
    /// The module without and with the counting of rays' work.
    modules: [wgpu::ShaderModule; 2],
    layout: wgpu::PipelineLayout,
    /// Group 1: the tiles' blocks as one array.
    tiles: wgpu::BindGroup,
    /// Group 2 of the rays: bins, colour, pixel data.
    rays_layout: wgpu::BindGroupLayout,
    /// Group 2 of the depth fill: the pixel data, read.
    fill_layout: wgpu::BindGroupLayout,
    fill: wgpu::RenderPipeline,
    /// The rays' pipeline per variant (built when first needed).
    variants: HashMap<RayVariant, wgpu::ComputePipeline>,
    frame: Option<ComputeFrame>,
}

/// The bindings of one frame: its bins and targets as the passes see them,
/// kept while the target size lasts and the bins fit.
pub struct ComputeFrame {
    size: (u32, u32),
    /// The pipeline variant of the frame's tiles.
    variant: RayVariant,
    bins: wgpu::Buffer,
    rays: wgpu::BindGroup,
    fill: wgpu::BindGroup,
}

impl ComputeRays {
    /// The compute module and layouts, and the depth fill's pipeline; group
    /// 0 is `frame`, group 1 the `tiles` buffer (with `STORAGE` usage) as
    /// an array.
    pub fn new(device: &wgpu::Device, frame: &wgpu::BindGroupLayout, tiles: &wgpu::Buffer) -> ComputeRays {
        let module_of = |counted| {
            device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("compute rays"),
                source: wgpu::ShaderSource::Wgsl(shaders::compute_source(counted).into()),
            })
        };
        let modules = [module_of(false), module_of(true)];
        let tiles_layout = layout(device, "tiles", &[storage_buffer(0)]);
        let rays_layout = layout(
            device,
            "compute rays",
            &[storage_buffer(0), storage_texture(1, COLOUR_FORMAT), storage_texture(2, PIXEL_DATA_FORMAT)],
        );
        let fill_layout = layout(
            device,
            "depth fill",
            &[wgpu::BindGroupLayoutEntry {
                binding: 3,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Uint,
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: false,
                },
                count: None,
            }],
        );
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("compute rays"),
            bind_group_layouts: &[Some(frame), Some(&tiles_layout), Some(&rays_layout)],
            immediate_size: 0,
        });
        let fill = fill_pipeline(device, &modules[0], &[Some(frame), None, Some(&fill_layout)]);
        let tiles = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("tiles"),
            layout: &tiles_layout,
            entries: &[wgpu::BindGroupEntry { binding: 0, resource: tiles.as_entire_binding() }],
        });
        ComputeRays { modules, layout, tiles, rays_layout, fill_layout, fill, variants: HashMap::new(), frame: None }
    }

    /// Readies a frame: the rays' pipeline of `variant` (built if it is
    /// not yet; `inside` is ignored, rays start at the camera inside a box
    /// either way), and the frame's `bins` ([`bins`]) uploaded and bound
    /// with `targets` (the last frame's bindings reused where its size and
    /// room allow).
    pub fn prepare(
        &mut self,
        (device, queue): (&wgpu::Device, &wgpu::Queue),
        targets: &Targets,
        (bins, variant): (&[u32], RayVariant),
    ) {
        let variant = RayVariant { inside: false, ..variant };
        self.build(device, variant);
        let bytes = std::mem::size_of_val(bins) as u64;
        let mut frame = match self.frame.take().filter(|o| o.size == targets.size && o.bins.size() >= bytes) {
            Some(old) => old,
            None => self.bind(device, targets, bytes.next_power_of_two(), variant),
        };
        queue.write_buffer(&frame.bins, 0, bytemuck::cast_slice(bins));
        frame.variant = variant;
        self.frame = Some(frame);
    }

    fn build(&mut self, device: &wgpu::Device, variant: RayVariant) {
        if self.variants.contains_key(&variant) {
            return;
        }
        let constants = variant.constants();
        let built = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("cs_rays"),
            layout: Some(&self.layout),
            module: &self.modules[usize::from(variant.counted)],
            entry_point: Some("cs_rays"),
            compilation_options: wgpu::PipelineCompilationOptions { constants: &constants, ..Default::default() },
            cache: None,
        });
        self.variants.insert(variant, built);
    }

    fn bind(&self, device: &wgpu::Device, targets: &Targets, bytes: u64, variant: RayVariant) -> ComputeFrame {
        let bins = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("ray bins"),
            size: bytes,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let view = |t: &wgpu::Texture| t.create_view(&Default::default());
        let (colour, data) = (view(&targets.colour), view(&targets.pixel_data));
        let entry = |binding, resource| wgpu::BindGroupEntry { binding, resource };
        let rays = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("compute rays"),
            layout: &self.rays_layout,
            entries: &[
                entry(0, bins.as_entire_binding()),
                entry(1, wgpu::BindingResource::TextureView(&colour)),
                entry(2, wgpu::BindingResource::TextureView(&data)),
            ],
        });
        let fill = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("depth fill"),
            layout: &self.fill_layout,
            entries: &[entry(3, wgpu::BindingResource::TextureView(&data))],
        });
        ComputeFrame { size: targets.size, variant, bins, rays, fill }
    }

    /// Encodes the prepared frame's rays: every pixel of the colour and
    /// data targets written.
    pub fn encode_rays(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        frame_group: &wgpu::BindGroup,
        timer: Option<&PassTimer>,
    ) {
        let Some(frame) = &self.frame else { return };
        let Some(pipeline) = self.variants.get(&frame.variant) else { return };
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("rays"),
            timestamp_writes: timer.map(PassTimer::rays),
        });
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, frame_group, &[]);
        pass.set_bind_group(1, &self.tiles, &[]);
        pass.set_bind_group(2, &frame.rays, &[]);
        let (w, h) = frame.size;
        pass.dispatch_workgroups(w.div_ceil(WORKGROUP_SIDE), h.div_ceil(WORKGROUP_SIDE), 1);
    }

    /// Encodes the depth fill: the depth target cleared, then the depth of
    /// the prepared frame's hits written.
    pub fn encode_fill(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        (targets, frame_group): (&Targets, &wgpu::BindGroup),
        timer: Option<&PassTimer>,
    ) {
        let Some(frame) = &self.frame else { return };
        let depth = targets.depth.create_view(&Default::default());
        let mut fill = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("depth fill"),
            color_attachments: &[],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &depth,
                depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(0.0), store: wgpu::StoreOp::Store }),
                stencil_ops: None,
            }),
            timestamp_writes: timer.map(PassTimer::fill),
            occlusion_query_set: None,
            multiview_mask: None,
        });
        fill.set_pipeline(&self.fill);
        fill.set_bind_group(0, frame_group, &[]);
        fill.set_bind_group(2, &frame.fill, &[]);
        fill.draw(0..3, 0..1);
    }
}

/// The bins of a `size` screen for ray-cast tiles given as `(draw index,
/// screen rectangle [x0, y0, x1, y1))`, in their order: bins per row, then
/// each bin's start and end in the array (one more than bins), then the
/// lists.
pub fn bins(size: (u32, u32), tiles: &[(u32, [u32; 4])]) -> Vec<u32> {
    let (columns, rows) = (size.0.div_ceil(BIN_PX), size.1.div_ceil(BIN_PX));
    let mut lists = vec![Vec::new(); (columns * rows) as usize];
    for &(draw, [x0, y0, x1, y1]) in tiles.iter().filter(|(_, r)| r[2] > r[0] && r[3] > r[1]) {
        for row in y0 / BIN_PX..=(y1 - 1) / BIN_PX {
            for column in x0 / BIN_PX..=(x1 - 1) / BIN_PX {
                lists[(row * columns + column) as usize].push(draw);
            }
        }
    }
    let header = 2 + lists.len();
    let mut out = Vec::with_capacity(header + lists.iter().map(Vec::len).sum::<usize>());
    out.push(columns);
    let mut at = header as u32;
    for list in &lists {
        out.push(at);
        at += list.len() as u32;
    }
    out.push(at);
    out.extend(lists.into_iter().flatten());
    out
}

fn layout(device: &wgpu::Device, label: &str, entries: &[wgpu::BindGroupLayoutEntry]) -> wgpu::BindGroupLayout {
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(label), entries })
}

fn storage_buffer(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only: true },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

fn storage_texture(binding: u32, format: wgpu::TextureFormat) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::StorageTexture {
            access: wgpu::StorageTextureAccess::WriteOnly,
            format,
            view_dimension: wgpu::TextureViewDimension::D2,
        },
        count: None,
    }
}

/// The full-screen triangle that writes the depth of the pixels whose rays
/// hit (depth only, always written).
fn fill_pipeline(
    device: &wgpu::Device,
    module: &wgpu::ShaderModule,
    groups: &[Option<&wgpu::BindGroupLayout>],
) -> wgpu::RenderPipeline {
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("depth fill"),
        bind_group_layouts: groups,
        immediate_size: 0,
    });
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("depth fill"),
        layout: Some(&layout),
        vertex: wgpu::VertexState {
            module,
            entry_point: Some("vs_fill"),
            compilation_options: Default::default(),
            buffers: &[],
        },
        primitive: wgpu::PrimitiveState::default(),
        depth_stencil: Some(wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(true),
            depth_compare: Some(wgpu::CompareFunction::Always),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module,
            entry_point: Some("fs_fill"),
            compilation_options: Default::default(),
            targets: &[],
        }),
        multiview_mask: None,
        cache: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bins_list_the_tiles_covering_them_in_order() {
        // A 70×40 screen: 3 × 2 bins. Tile 5 covers the top-left pixel, tile
        // 2 everything, tile 7 an empty rectangle, tile 1 the bottom right.
        let b = bins((70, 40), &[(5, [0, 0, 1, 1]), (2, [0, 0, 70, 40]), (7, [10, 10, 10, 20]), (1, [64, 32, 70, 40])]);
        assert_eq!(b[0], 3);
        let list = |bin: usize| b[b[1 + bin] as usize..b[2 + bin] as usize].to_vec();
        assert_eq!(list(0), vec![5, 2]);
        assert_eq!((1..5).map(list).collect::<Vec<_>>(), vec![vec![2]; 4]);
        assert_eq!(list(5), vec![2, 1]);
        assert_eq!(b.len(), 2 + 6 + 8);
    }
}
