//! Showing frames in a window: the window's surface, configured for the
//! GPU, and a pass that copies the renderer's colour target onto it
//! (`shaders/present.wgsl`). The colour target holds sRGB-encoded bytes,
//! copied as they are to a plain surface format, decoded for an sRGB one.

use super::super::render::gpu::Gpu;
use super::super::render::shaders;

/// Why a frame could not be shown.
#[derive(Debug, thiserror::Error)]
pub enum PresentError {
    /// The surface has no format the GPU can render to.
    #[error("the window's surface offers no format this GPU can render to")]
    NoFormat,
    /// The surface is gone and must be made again.
    #[error("the window's surface was lost")]
    Lost,
    /// The surface refused the frame.
    #[error("the window's surface refused the frame: {0}")]
    Refused(&'static str),
}

/// A window's surface and the pass that fills it.
pub struct Presenter {
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
}

impl Presenter {
    /// Configures `surface` for `gpu` at `size` pixels.
    pub fn new(gpu: &Gpu, surface: wgpu::Surface<'static>, size: (u32, u32)) -> Result<Presenter, PresentError> {
        let caps = surface.get_capabilities(&gpu.adapter);
        let format = pick_format(&caps.formats).ok_or(PresentError::NoFormat)?;
        let config = wgpu::SurfaceConfiguration {
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            format,
            width: size.0.max(1),
            height: size.1.max(1),
            // Fifo is always there; a frame waits for the display, as an
            // interactive viewer should.
            present_mode: wgpu::PresentMode::Fifo,
            desired_maximum_frame_latency: 2,
            alpha_mode: caps.alpha_modes.first().copied().unwrap_or(wgpu::CompositeAlphaMode::Auto),
            view_formats: Vec::new(),
            color_space: wgpu::SurfaceColorSpace::Auto,
        };
        surface.configure(&gpu.device, &config);
        let (pipeline, layout) = pipeline(&gpu.device, format);
        Ok(Presenter { surface, config, pipeline, layout })
    }

    /// The surface's size, pixels.
    pub fn size(&self) -> (u32, u32) {
        (self.config.width, self.config.height)
    }

    /// Follows the window to `size` pixels.
    pub fn resize(&mut self, gpu: &Gpu, size: (u32, u32)) {
        (self.config.width, self.config.height) = (size.0.max(1), size.1.max(1));
        self.surface.configure(&gpu.device, &self.config);
    }

    /// Copies `colour` (the size of the surface) to the window.
    pub fn show(&mut self, gpu: &Gpu, colour: &wgpu::Texture) -> Result<(), PresentError> {
        let frame = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t) | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            wgpu::CurrentSurfaceTexture::Outdated => {
                // Resized under us: take the new size on the next frame.
                self.surface.configure(&gpu.device, &self.config);
                return Ok(());
            }
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => return Ok(()),
            wgpu::CurrentSurfaceTexture::Lost => return Err(PresentError::Lost),
            wgpu::CurrentSurfaceTexture::Validation => return Err(PresentError::Refused("validation error")),
        };
        let target = frame.texture.create_view(&wgpu::TextureViewDescriptor::default());
        let source = colour.create_view(&wgpu::TextureViewDescriptor::default());
        let group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("present"),
            layout: &self.layout,
            entries: &[wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::TextureView(&source) }],
        });
        let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("present") });
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("present"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &target,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                ..Default::default()
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &group, &[]);
            pass.draw(0..3, 0..1);
        }
        gpu.queue.submit([encoder.finish()]);
        gpu.queue.present(frame);
        Ok(())
    }
}

/// The surface format frames are shown in: an 8-bit one without sRGB
/// encoding if there is one (the frame's bytes go to the screen as they
/// are), else an 8-bit sRGB one (the pass decodes them, the surface encodes
/// them again), else the first.
fn pick_format(formats: &[wgpu::TextureFormat]) -> Option<wgpu::TextureFormat> {
    let eight_bit = |f: &&wgpu::TextureFormat| {
        matches!(f.remove_srgb_suffix(), wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Rgba8Unorm)
    };
    let plain = formats.iter().filter(eight_bit).find(|f| !f.is_srgb());
    plain.or(formats.iter().find(eight_bit)).or(formats.first()).copied()
}

/// The present pipeline writing `format`, and its bind group layout.
fn pipeline(device: &wgpu::Device, format: wgpu::TextureFormat) -> (wgpu::RenderPipeline, wgpu::BindGroupLayout) {
    let (name, source) = shaders::PRESENT;
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(name),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("present"),
        entries: &[wgpu::BindGroupLayoutEntry {
            binding: 0,
            visibility: wgpu::ShaderStages::FRAGMENT,
            ty: wgpu::BindingType::Texture {
                sample_type: wgpu::TextureSampleType::Float { filterable: false },
                view_dimension: wgpu::TextureViewDimension::D2,
                multisampled: false,
            },
            count: None,
        }],
    });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("present"),
        bind_group_layouts: &[Some(&layout)],
        immediate_size: 0,
    });
    let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("present"),
        layout: Some(&pipeline_layout),
        vertex: wgpu::VertexState {
            module: &module,
            entry_point: Some("vs_present"),
            compilation_options: Default::default(),
            buffers: &[],
        },
        fragment: Some(wgpu::FragmentState {
            module: &module,
            entry_point: Some("fs_present"),
            compilation_options: wgpu::PipelineCompilationOptions {
                constants: &[("SRGB_TARGET", if format.is_srgb() { 1.0 } else { 0.0 })],
                ..Default::default()
            },
            targets: &[Some(wgpu::ColorTargetState { format, blend: None, write_mask: wgpu::ColorWrites::ALL })],
        }),
        primitive: wgpu::PrimitiveState::default(),
        depth_stencil: None,
        multisample: wgpu::MultisampleState::default(),
        multiview_mask: None,
        cache: None,
    });
    (pipeline, layout)
}
