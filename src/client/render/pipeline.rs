//! The render pipelines and their bindings: hull fragments that ray cast
//! (front faces), the same from a camera inside the hull (back faces), and
//! plain texture mapping of the terrain mesh (far tiles, and crack filling
//! under ray-cast ones), and trees' splats as instanced quads, lit by a
//! compute pipeline that casts each splat's shadow ray once. All render
//! pipelines write colour, per-pixel fetch counts, the view-axis distance
//! and reversed-Z depth (greater is nearer). The ray-casting pipelines are
//! specialised per [`RayVariant`] and built when a frame first needs one
//! (`compute` builds those that cast rays in a compute pass instead).

use super::super::hull::HullVertex;
use super::super::terrain::TerrainVertex;
use super::super::trees::Splat;
use super::cache::TileCache;
use super::shaders;
use super::uniforms::{FrameUniform, TILE_STRIDE, TileUniform};
use super::work::WorkCounters;
use std::collections::HashMap;

/// Colour target format.
pub const COLOUR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
/// Per-pixel data target: view and shadow fetches, the bits of the
/// view-axis distance and the draw whose rays the pixel shows (read back instead of the depth buffer, which GL
/// cannot copy; an integer target, which GL renders to, unlike R32Float).
pub const PIXEL_DATA_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Uint;
/// Depth format.
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// Vertex attributes of the hull (sample position; ground and CEM bound).
const HULL_ATTRIBUTES: [wgpu::VertexAttribute; 2] = wgpu::vertex_attr_array![0 => Float32x2, 1 => Float32x2];

/// What a ray-casting pipeline's shaders are specialised for (WGSL
/// overrides): a tile pays only for the work it needs, which matters most
/// on software rasterisers, which run both sides of every branch under a
/// mask (lavapipe, `bench raycast --size 320x256`: behind uniform branches
/// the morph blend cost 1.26–1.39× and the canopy fade 1.52–1.90× the frame
/// time on tiles without them).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct RayVariant {
    /// The camera is inside the hull: rays start on its back faces.
    pub inside: bool,
    /// The tile morphs: its heights are blended with its morph layer's
    /// (`MORPHING`).
    pub morphing: bool,
    /// The whole canopy, unfaded, everywhere on the tile (`CANOPY_WHOLE`).
    pub whole: bool,
    /// Rays march linearly instead of traversing the maximum mipmap
    /// (`LINEAR`).
    pub linear: bool,
    /// Every ray's work is counted per draw ([`super::work`],
    /// [`super::Renderer::count_work`]; the module with
    /// `work_count.wgsl`): the counters' atomics cost lavapipe 8–35 % of a
    /// frame, so other frames go without.
    pub counted: bool,
}

impl RayVariant {
    /// The shaders' override constants of this variant.
    pub fn constants(&self) -> [(&'static str, f64); 3] {
        let flag = |on: bool| f64::from(u8::from(on));
        [("MORPHING", flag(self.morphing)), ("CANOPY_WHOLE", flag(self.whole)), ("LINEAR", flag(self.linear))]
    }
}

/// The pipelines and bind group layouts.
pub struct Pipelines {
    /// Ray casting from the hull, per variant (built when first needed).
    rays: HashMap<RayVariant, wgpu::RenderPipeline>,
    /// Texture-mapped terrain mesh.
    pub plain: wgpu::RenderPipeline,
    /// Trees' splats: a quad of four strip vertices per instance, whose
    /// light is a second instance buffer.
    pub splat: wgpu::RenderPipeline,
    /// The light of each splat (group 2: the splats, their lights).
    pub splat_light: wgpu::ComputePipeline,
    /// Group 2 of [`Self::splat_light`].
    pub splat_layout: wgpu::BindGroupLayout,
    /// Group 0: frame uniform, tile textures, sampler, morph layers, work
    /// counters.
    pub frame_layout: wgpu::BindGroupLayout,
    /// Group 1: the tile uniform at a dynamic offset.
    pub tile_layout: wgpu::BindGroupLayout,
    module: wgpu::ShaderModule,
    /// The module of ray-casting pipelines that count their rays' work.
    counting: wgpu::ShaderModule,
    layout: wgpu::PipelineLayout,
    /// Hull fragments promise their depth (`fs_ray_hull`), so hidden ones
    /// can be rejected before their rays are cast; terrain meshes' and
    /// splats' too (`fs_plain_early`, `fs_splat_early`).
    early_depth: bool,
}

impl Pipelines {
    /// Compiles the shaders and builds the pipelines; hull, terrain mesh and
    /// splat fragments promise their depth if `early_depth` (the device must have
    /// `SHADER_EARLY_DEPTH_TEST`).
    pub fn new(device: &wgpu::Device, early_depth: bool) -> Pipelines {
        let source = |counted| shaders::raycast_source(early_depth, counted);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("raycast"),
            source: wgpu::ShaderSource::Wgsl(source(false).into()),
        });
        let counting = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("raycast, counting"),
            source: wgpu::ShaderSource::Wgsl(source(true).into()),
        });
        let frame_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("frame"),
            entries: &[
                uniform_entry(0, std::mem::size_of::<FrameUniform>() as u64, false),
                texture_entry(1),
                texture_entry(2),
                texture_entry(3),
                wgpu::BindGroupLayoutEntry {
                    binding: 4,
                    visibility: STAGES,
                    ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::NonFiltering),
                    count: None,
                },
                texture_entry(5),
                wgpu::BindGroupLayoutEntry {
                    binding: 6,
                    // Written: no vertex stage may see it.
                    visibility: wgpu::ShaderStages::FRAGMENT.union(wgpu::ShaderStages::COMPUTE),
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage { read_only: false },
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
            ],
        });
        let tile_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("tile"),
            entries: &[uniform_entry(0, std::mem::size_of::<TileUniform>() as u64, true)],
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("raycast"),
            bind_group_layouts: &[Some(&frame_layout), Some(&tile_layout)],
            immediate_size: 0,
        });
        let terrain_attributes = wgpu::vertex_attr_array![0 => Float32x2, 1 => Float32, 2 => Float32x3];
        let terrain_vertex = wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<TerrainVertex>() as u64,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &terrain_attributes,
        };
        let splat_attributes = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32, 2 => Unorm8x4];
        let light_attributes = wgpu::vertex_attr_array![3 => Float32];
        let instances = |stride: usize, attributes| wgpu::VertexBufferLayout {
            array_stride: stride as u64,
            step_mode: wgpu::VertexStepMode::Instance,
            attributes,
        };
        let splat_instance = [
            instances(std::mem::size_of::<Splat>(), &splat_attributes[..]),
            instances(std::mem::size_of::<f32>(), &light_attributes[..]),
        ];
        let quads = wgpu::PrimitiveState { topology: wgpu::PrimitiveTopology::TriangleStrip, ..Default::default() };
        let plain = ("vs_plain", &[terrain_vertex][..]);
        let splat = ("vs_splat", &splat_instance[..]);
        let splat_layout = splat_layout(device);
        let (plain_fragment, splat_fragment) =
            if early_depth { ("fs_plain_early", "fs_splat_early") } else { ("fs_plain", "fs_splat") };
        Pipelines {
            plain: pipeline(device, (&layout, &module), plain, plain_fragment, (triangles(wgpu::Face::Back), &[])),
            splat: pipeline(device, (&layout, &module), splat, splat_fragment, (quads, &[])),
            splat_light: splat_light(device, &module, [&frame_layout, &tile_layout, &splat_layout]),
            splat_layout,
            rays: HashMap::new(),
            frame_layout,
            tile_layout,
            module,
            counting,
            layout,
            early_depth,
        }
    }

    /// Builds the hull fragments' ray-casting pipeline of `variant` if it is
    /// not built yet.
    pub fn prepare_ray(&mut self, device: &wgpu::Device, variant: RayVariant) {
        if self.rays.contains_key(&variant) {
            return;
        }
        let vertex = wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<HullVertex>() as u64,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &HULL_ATTRIBUTES,
        };
        // Back faces when the camera is inside the hull.
        let cull = if variant.inside { wgpu::Face::Front } else { wgpu::Face::Back };
        let constants = variant.constants();
        // From inside the hull, its back faces lie beyond the surface: no
        // depth promise there.
        let fragment = if self.early_depth && !variant.inside { "fs_ray_hull" } else { "fs_ray" };
        let built = pipeline(
            device,
            (&self.layout, if variant.counted { &self.counting } else { &self.module }),
            ("vs_hull", &[vertex][..]),
            fragment,
            (triangles(cull), &constants),
        );
        self.rays.insert(variant, built);
    }

    /// The ray-casting pipeline of `variant`, once prepared.
    pub fn ray(&self, variant: RayVariant) -> Option<&wgpu::RenderPipeline> {
        self.rays.get(&variant)
    }

    /// The frame bind group over the cache's textures and the work
    /// counters.
    pub fn frame_group(
        &self,
        device: &wgpu::Device,
        frame: &wgpu::Buffer,
        (cache, work): (&TileCache, &WorkCounters),
    ) -> wgpu::BindGroup {
        let view = |t: &wgpu::Texture| {
            t.create_view(&wgpu::TextureViewDescriptor {
                dimension: Some(wgpu::TextureViewDimension::D2Array),
                ..Default::default()
            })
        };
        let (texels, colours, mip) = (view(&cache.texels), view(&cache.colours), view(&cache.mip));
        let morph_from = view(&cache.morph_from);
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor { label: Some("gather"), ..Default::default() });
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("frame"),
            layout: &self.frame_layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: frame.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(&texels) },
                wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::TextureView(&colours) },
                wgpu::BindGroupEntry { binding: 3, resource: wgpu::BindingResource::TextureView(&mip) },
                wgpu::BindGroupEntry { binding: 4, resource: wgpu::BindingResource::Sampler(&sampler) },
                wgpu::BindGroupEntry { binding: 5, resource: wgpu::BindingResource::TextureView(&morph_from) },
                wgpu::BindGroupEntry { binding: 6, resource: work.binding() },
            ],
        })
    }

    /// The tile bind group over the per-tile uniform buffer.
    pub fn tile_group(&self, device: &wgpu::Device, tiles: &wgpu::Buffer) -> wgpu::BindGroup {
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("tile"),
            layout: &self.tile_layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                    buffer: tiles,
                    offset: 0,
                    size: wgpu::BufferSize::new(TILE_STRIDE),
                }),
            }],
        })
    }
}

/// The stages that read the frame's and the tiles' bindings.
const STAGES: wgpu::ShaderStages = wgpu::ShaderStages::VERTEX_FRAGMENT.union(wgpu::ShaderStages::COMPUTE);

/// Group 2 of the splat light pipeline: the splats (read), their lights
/// (written).
fn splat_layout(device: &wgpu::Device) -> wgpu::BindGroupLayout {
    let storage = |binding, read_only| wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    };
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("splats"),
        entries: &[storage(0, true), storage(1, false)],
    })
}

fn splat_light(
    device: &wgpu::Device,
    module: &wgpu::ShaderModule,
    groups: [&wgpu::BindGroupLayout; 3],
) -> wgpu::ComputePipeline {
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("splat light"),
        bind_group_layouts: &groups.map(Some),
        immediate_size: 0,
    });
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("splat light"),
        layout: Some(&layout),
        module,
        entry_point: Some("cs_splat_light"),
        compilation_options: Default::default(),
        cache: None,
    })
}

fn uniform_entry(binding: u32, size: u64, dynamic: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: STAGES,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: dynamic,
            min_binding_size: wgpu::BufferSize::new(size),
        },
        count: None,
    }
}

fn texture_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: STAGES,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable: false },
            view_dimension: wgpu::TextureViewDimension::D2Array,
            multisampled: false,
        },
        count: None,
    }
}

fn triangles(cull: wgpu::Face) -> wgpu::PrimitiveState {
    wgpu::PrimitiveState {
        topology: wgpu::PrimitiveTopology::TriangleList,
        front_face: wgpu::FrontFace::Ccw,
        cull_mode: Some(cull),
        ..Default::default()
    }
}

/// A pipeline of `module`'s `vs` and `fs` with the pipeline-overridable
/// `constants` set in both stages.
fn pipeline(
    device: &wgpu::Device,
    (layout, module): (&wgpu::PipelineLayout, &wgpu::ShaderModule),
    (vs, buffers): (&str, &[wgpu::VertexBufferLayout]),
    fs: &str,
    (primitive, constants): (wgpu::PrimitiveState, &[(&str, f64)]),
) -> wgpu::RenderPipeline {
    let options = || wgpu::PipelineCompilationOptions { constants, ..Default::default() };
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(fs),
        layout: Some(layout),
        vertex: wgpu::VertexState {
            module,
            entry_point: Some(vs),
            compilation_options: options(),
            buffers: &buffers.iter().cloned().map(Some).collect::<Vec<_>>(),
        },
        primitive,
        depth_stencil: Some(wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(true),
            depth_compare: Some(wgpu::CompareFunction::Greater),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module,
            entry_point: Some(fs),
            compilation_options: options(),
            targets: &[
                Some(wgpu::ColorTargetState { format: COLOUR_FORMAT, blend: None, write_mask: wgpu::ColorWrites::ALL }),
                Some(wgpu::ColorTargetState {
                    format: PIXEL_DATA_FORMAT,
                    blend: None,
                    write_mask: wgpu::ColorWrites::ALL,
                }),
            ],
        }),
        multiview_mask: None,
        cache: None,
    })
}
