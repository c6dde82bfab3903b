//! Showing frames in a window: the window's surface, configured for the
//! GPU, and a pass that copies the renderer's colour target onto it
//! (`shaders/present.wgsl`). The colour target holds sRGB-encoded bytes,
//! copied as they are to a plain surface format, decoded for an sRGB one.
//! A surface the window system takes away (`Lost`: a display mode change,
//! a compositor restart) is made again from the window, and the view goes
//! on.

use super::super::render::gpu::Gpu;
use super::super::render::shaders;
use std::sync::Arc;
use winit::window::Window;

/// Why a frame could not be shown.
#[derive(Debug, thiserror::Error)]
pub enum PresentError {
    /// The surface has no format the GPU can render to.
    #[error("the window's surface offers no format this GPU can render to")]
    NoFormat,
    /// The surface was lost and could not be made again.
    #[error("the window's surface was lost and could not be made again: {0}")]
    Lost(String),
    /// The surface refused the frame.
    #[error("the window's surface refused the frame: {0}")]
    Refused(&'static str),
}

/// A window's surface and the pass that fills it.
pub struct Presenter {
    /// Makes the surface again when it is lost.
    instance: wgpu::Instance,
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
}

impl Presenter {
    /// Configures `window`'s `surface` (made by `instance`, as `gpu`) for
    /// `gpu` at the window's size.
    pub fn new(
        gpu: &Gpu,
        instance: wgpu::Instance,
        window: Arc<Window>,
        surface: wgpu::Surface<'static>,
    ) -> Result<Presenter, PresentError> {
        let size = fitted(gpu, &window);
        let caps = surface.get_capabilities(&gpu.adapter);
        let format = pick_format(&caps.formats).ok_or(PresentError::NoFormat)?;
        let config = wgpu::SurfaceConfiguration {
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            format,
            width: size.0,
            height: size.1,
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
        Ok(Presenter { instance, window, surface, config, pipeline, layout })
    }

    /// The surface's size, pixels: the frames' size.
    pub fn size(&self) -> (u32, u32) {
        (self.config.width, self.config.height)
    }

    /// Follows the window's size (within what the GPU can render).
    pub fn fit(&mut self, gpu: &Gpu) {
        (self.config.width, self.config.height) = fitted(gpu, &self.window);
        self.surface.configure(&gpu.device, &self.config);
    }

    /// A new surface for the window, configured as the lost one was (its
    /// format, if the new one still offers it).
    fn remake(&mut self, gpu: &Gpu) -> Result<(), PresentError> {
        let lost = |e: &dyn std::fmt::Display| PresentError::Lost(e.to_string());
        let surface = self.instance.create_surface(self.window.clone()).map_err(|e| lost(&e))?;
        let formats = surface.get_capabilities(&gpu.adapter).formats;
        if !formats.contains(&self.config.format) {
            return Err(lost(&"the new surface does not offer the old one's format"));
        }
        self.surface = surface;
        self.fit(gpu);
        Ok(())
    }

    /// Copies `colour` (the size of the surface) to the window.
    pub fn show(&mut self, gpu: &Gpu, colour: &wgpu::Texture) -> Result<(), PresentError> {
        let (frame, suboptimal) = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t) => (t, false),
            // Shown, then fitted to the window for the next frame.
            wgpu::CurrentSurfaceTexture::Suboptimal(t) => (t, true),
            wgpu::CurrentSurfaceTexture::Outdated => {
                // Resized under us: the next frame has the window's size.
                self.fit(gpu);
                return Ok(());
            }
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => return Ok(()),
            wgpu::CurrentSurfaceTexture::Lost => {
                // Made again now; this frame is not shown.
                self.remake(gpu)?;
                return Ok(());
            }
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
        if suboptimal {
            self.fit(gpu);
        }
        Ok(())
    }
}

/// The window's size, at least a pixel and at most what the GPU renders.
fn fitted(gpu: &Gpu, window: &Window) -> (u32, u32) {
    let (size, most) = (window.inner_size(), gpu.device.limits().max_texture_dimension_2d);
    (size.width.clamp(1, most), size.height.clamp(1, most))
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

#[cfg(test)]
mod tests {
    use super::*;
    use wgpu::TextureFormat as F;

    #[test]
    fn frames_go_to_a_plain_8_bit_format_first() {
        assert_eq!(pick_format(&[F::Bgra8UnormSrgb, F::Rgba16Float, F::Bgra8Unorm]), Some(F::Bgra8Unorm));
        assert_eq!(pick_format(&[F::Rgba16Float, F::Rgba8UnormSrgb]), Some(F::Rgba8UnormSrgb));
        assert_eq!(pick_format(&[F::Rgb10a2Unorm]), Some(F::Rgb10a2Unorm));
        assert_eq!(pick_format(&[]), None);
    }
}
