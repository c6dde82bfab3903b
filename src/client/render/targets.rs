//! Off-screen render targets (colour, per-pixel data, depth) and reading
//! the colour ones back: rows are copied with wgpu's 256-byte
//! row alignment and unpadded here. Depth is never copied (GL cannot).
//! Targets beyond the GPU's limits, or more than its memory holds, are an
//! error naming their size.

use super::gpu::{AllocError, allocate};
use super::pipeline::{COLOUR_FORMAT, DEPTH_FORMAT, PIXEL_DATA_FORMAT};

/// The three targets of one image size.
pub struct Targets {
    /// Width and height, pixels.
    pub size: (u32, u32),
    /// Colour.
    pub colour: wgpu::Texture,
    /// Per pixel: view-ray and shadow-ray fetches, the bits of the distance
    /// along the view axis (metres; 0: nothing), the draw whose rays it
    /// shows + 1 (0: none).
    pub pixel_data: wgpu::Texture,
    /// Reversed-Z depth.
    pub depth: wgpu::Texture,
}

impl Targets {
    /// Targets of `size`, if the GPU can hold them and read them back.
    pub fn new(device: &wgpu::Device, size: (u32, u32)) -> Result<Targets, AllocError> {
        let what = format!("render targets of {}×{}", size.0, size.1);
        if let Some(why) = beyond_limits(&device.limits(), size) {
            return Err(AllocError { what, why });
        }
        allocate(device, what, || Targets::make(device, size))
    }

    /// The textures of `size`, unchecked.
    fn make(device: &wgpu::Device, size: (u32, u32)) -> Targets {
        // Colour and data are also written by the compute ray passes, and
        // the data read by their depth fill.
        let written = wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::TEXTURE_BINDING;
        let make = |label, format, extra| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d { width: size.0, height: size.1, depth_or_array_layers: 1 },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC | extra,
                view_formats: &[],
            })
        };
        Targets {
            size,
            colour: make("colour", COLOUR_FORMAT, written),
            pixel_data: make("pixel data", PIXEL_DATA_FORMAT, written),
            depth: make("depth", DEPTH_FORMAT, wgpu::TextureUsages::empty()),
        }
    }
}

/// Why targets of `size` are beyond the GPU's `limits`, if they are: a
/// side longer than its textures', or a readback buffer (of the widest
/// texels, the pixel data) larger than its buffers.
fn beyond_limits(limits: &wgpu::Limits, (w, h): (u32, u32)) -> Option<String> {
    let side = limits.max_texture_dimension_2d;
    if w > side || h > side {
        return Some(format!("the GPU's textures are at most {side}×{side}"));
    }
    let texel_bytes = PIXEL_DATA_FORMAT.block_copy_size(None).unwrap_or(16);
    let readback = u64::from(padded_row(w, texel_bytes)) * u64::from(h);
    let mib = |bytes: u64| bytes as f64 / f64::from(1 << 20);
    (readback > limits.max_buffer_size).then(|| {
        format!(
            "reading them back takes a buffer of {:.0} MiB, and the GPU's buffers are at most {:.0} MiB",
            mib(readback),
            mib(limits.max_buffer_size)
        )
    })
}

/// Bytes of one row of `w` texels of `texel_bytes` in a readback buffer.
fn padded_row(w: u32, texel_bytes: u32) -> u32 {
    (w * texel_bytes).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT
}

/// Reads one 2-D texture back, `texel_bytes` per texel, rows unpadded; an
/// error if the GPU has not the memory for the readback buffer.
pub fn read_texture(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    texture: &wgpu::Texture,
    texel_bytes: u32,
) -> Result<Vec<u8>, AllocError> {
    let (w, h) = (texture.width(), texture.height());
    let row = w * texel_bytes;
    let padded = padded_row(w, texel_bytes);
    let buffer = allocate(device, format!("a readback buffer for {w}×{h} pixels"), || {
        device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: u64::from(padded) * u64::from(h),
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        })
    })?;
    let mut encoder = device.create_command_encoder(&Default::default());
    encoder.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        wgpu::TexelCopyBufferInfo {
            buffer: &buffer,
            layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(padded), rows_per_image: Some(h) },
        },
        wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
    );
    queue.submit([encoder.finish()]);
    let bytes = map_read(device, &buffer);
    Ok(bytes.chunks(padded as usize).flat_map(|r| r[..row as usize].to_vec()).collect())
}

/// Maps a buffer and copies its bytes out, waiting for the GPU.
pub fn map_read(device: &wgpu::Device, buffer: &wgpu::Buffer) -> Vec<u8> {
    let slice = buffer.slice(..);
    slice.map_async(wgpu::MapMode::Read, |_| {});
    // A lost device leaves the buffer unmapped; an empty read says so.
    if device.poll(wgpu::PollType::wait_indefinitely()).is_err() {
        return Vec::new();
    }
    let bytes = slice.get_mapped_range().map(|view| view.to_vec()).unwrap_or_default();
    buffer.unmap();
    bytes
}
