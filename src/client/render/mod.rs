//! The wgpu renderer (feature `client`): each visible tile's hull is
//! rasterised and its fragments ray cast into the tile's textures
//! (dissertation 6.4); tiles too far for their canopy and relief to show are
//! texture-mapped terrain meshes instead; trees near the camera are drawn
//! as splats in their tiles' frames. Headless: frames are rendered to
//! textures and read back.
//!
//! - `gpu`: the adapter and device; `cache`: tile texture slots within a
//!   memory budget; `pipeline`: the pipelines; `compute`: ray casting in
//!   a compute pass instead of hull fragments ([`RayPass`]); `splats`: the splat
//!   instances and their lights; `uniforms`: the uniform blocks; `targets`:
//!   render targets and readback; `timer`: GPU pass time; `shaders`: the
//!   WGSL table.

pub mod cache;
pub mod compute;
pub mod gpu;
pub mod pipeline;
pub mod shaders;
pub mod splats;
pub mod targets;
pub mod timer;
pub mod uniforms;
pub mod work;

use super::camera::Camera;
use super::raycast::{self, SKY, Traversal};
use super::tile::TileData;
use super::trees::Splat;
use cache::{CacheFull, TileCache};
use compute::ComputeRays;
pub use compute::RayPass;
use gpu::{AllocError, Gpu};
use pipeline::{Pipelines, RayVariant};
use splats::SplatBuffers;
use std::time::Instant;
use targets::Targets;
use timer::PassTimer;
use uniforms::{DrawMode, FrameSettings, FrameUniform, Placement, TILE_STRIDE, TileUniform};
pub use work::DrawWork;
use work::WorkCounters;

/// Frames submitted and not yet done, at most, when they are pipelined
/// ([`Renderer::pipelined`]): what a swapchain holds an interactive loop to.
pub const FRAMES_IN_FLIGHT: usize = 3;

/// What to read back after a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Readback {
    /// Nothing (timing runs).
    None,
    /// Colour only.
    Colour,
    /// Colour, depth and fetch counts.
    All,
}

/// Why a frame could not be rendered.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// The frame has more tiles than the GPU cache holds.
    #[error(transparent)]
    Cache(#[from] CacheFull),
    /// The render targets of the frame's size could not be allocated.
    #[error(transparent)]
    Targets(#[from] AllocError),
}

/// Counts and times of one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameStats {
    /// GPU time of the frame's passes, if the adapter has timestamps.
    pub gpu_ms: Option<f64>,
    /// Of that, with rays in a compute pass: the rays' pass, and the depth
    /// fill after it.
    pub gpu_rays_ms: Option<(f64, f64)>,
    /// CPU time from encoding to the GPU being done, ms.
    pub wall_ms: f64,
    /// Tiles ray cast from their hull.
    pub tiles_hull: u32,
    /// Tiles ray cast from the camera inside them.
    pub tiles_inside: u32,
    /// Tiles drawn without ray casting.
    pub tiles_plain: u32,
    /// Tile bytes resident on the GPU.
    pub resident_bytes: usize,
    /// Tree splats drawn.
    pub splats: u32,
}

/// A rendered frame, row 0 at the top; empty buffers where not read back.
#[derive(Clone, Debug, Default)]
pub struct Rendered {
    /// Colour.
    pub colour: Vec<[u8; 4]>,
    /// Distance along the view axis, metres; 0 where nothing was hit.
    pub view_z_m: Vec<f32>,
    /// Texture fetches per pixel: the view ray with the read of its hit
    /// cell for shading (with rays in a compute pass, the view rays of every
    /// tile the pixel's ray was cast through), and the shadow rays.
    pub fetches: Vec<[u32; 2]>,
    /// The draw whose rays a pixel shows: `k + 1` for the `k`-th of the
    /// frame's draws, 0 where no ray was cast.
    pub draws: Vec<u32>,
    /// The work of every ray each draw cast, shown or not, by draw (where
    /// counted: [`Renderer::count_work`]).
    pub work: Vec<DrawWork>,
    /// Counts and times.
    pub stats: FrameStats,
}

/// A tile to draw and its ray-casting quality.
#[derive(Clone, Copy, Debug)]
pub struct Draw<'a> {
    /// The tile.
    pub tile: &'a TileData,
    /// Shadow samples per hit on this tile (0: none).
    pub shadow_steps: u32,
    /// Trees' splats in this tile's frame.
    pub splats: &'a [Splat],
    /// Weight of the tile's own heights against the coarser surface it
    /// morphs from or to (1 for a tile that does not morph).
    pub morph_weight: f32,
}

/// How one tile of a frame is drawn: its texture slot, its mode and the
/// range of its splats in the frame's instance buffer.
#[derive(Clone, Debug)]
struct Prepared {
    slot: u32,
    mode: DrawMode,
    variant: RayVariant,
    splats: std::ops::Range<u32>,
    /// Pixels its box covers (the compute ray passes' invocations).
    screen: [u32; 4],
    /// Its terrain mesh is drawn: the tile is drawn plain, or ray cast
    /// over a crack filler ([`uniforms::needs_filler`]).
    mesh: bool,
}

/// The renderer and its GPU resources.
pub struct Renderer {
    gpu: Gpu,
    pipelines: Pipelines,
    cache: TileCache,
    frame_buffer: wgpu::Buffer,
    frame_group: wgpu::BindGroup,
    work: WorkCounters,
    tile_buffer: wgpu::Buffer,
    tile_group: wgpu::BindGroup,
    splats: Option<SplatBuffers>,
    /// The last frame's splat ranges in the instance buffer, by draw.
    splat_ranges: Vec<std::ops::Range<u32>>,
    targets: Option<Targets>,
    /// Rays cast in a compute pass (none: from the hulls' fragments).
    compute: Option<ComputeRays>,
    timer: Option<PassTimer>,
    /// Frames are submitted without waiting for the GPU ([`Self::pipelined`]).
    pipelined: bool,
    /// Their submissions not yet waited for, oldest first.
    in_flight: std::collections::VecDeque<wgpu::SubmissionIndex>,
    frame_no: u64,
    /// Frames read back in full count their rays' work ([`Self::count_work`]).
    count_work: bool,
    /// The frame being drawn counts its rays' work.
    counting: bool,
}

impl Renderer {
    /// Hulls uploaded with quads `factor` times as large as the tiles' 16
    /// samples (set before the first frame). A software rasteriser shades
    /// whole pixel blocks along every triangle's edge, so there fewer,
    /// larger triangles win although rays start farther from the surface:
    /// the same 27-tile frames on lavapipe took 257 ms with 16-sample quads,
    /// 187–192 ms with 64 (and 15.1 against 19.6 fetches per pixel; the
    /// linear march, starting farther away, misses more).
    pub fn with_hull_factor(mut self, factor: usize) -> Renderer {
        self.cache.set_hull_factor(factor);
        self
    }

    /// Rays cast in `pass` (set before the first frame).
    pub fn with_ray_pass(mut self, pass: RayPass) -> Renderer {
        self.compute = (pass == RayPass::Compute)
            .then(|| ComputeRays::new(&self.gpu.device, &self.pipelines.frame_layout, &self.tile_buffer));
        self
    }

    /// A renderer for tiles of `samples` per side with `halo`, keeping at
    /// most `budget_bytes` of tiles on the GPU, and, if `geomorph`, room for
    /// morphing tiles' coarser surfaces within that budget; an error if the
    /// GPU has not the memory for that cache.
    pub fn new(gpu: Gpu, samples: u32, halo: u32, budget_bytes: usize, geomorph: bool) -> Result<Renderer, AllocError> {
        let device = &gpu.device;
        let cache = TileCache::new(device, samples, halo, budget_bytes, geomorph)?;
        let pipelines = Pipelines::new(device, gpu.early_depth);
        let frame_buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("frame"),
            size: std::mem::size_of::<FrameUniform>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let work = WorkCounters::new(device, cache.capacity());
        let frame_group = pipelines.frame_group(device, &frame_buffer, (&cache, &work));
        let tile_buffer = tile_buffer(device, cache.capacity());
        let tile_group = pipelines.tile_group(device, &tile_buffer);
        let timer = PassTimer::new(device, &gpu.queue, gpu.timestamps);
        Ok(Renderer {
            gpu,
            pipelines,
            cache,
            frame_buffer,
            frame_group,
            work,
            tile_buffer,
            tile_group,
            splats: None,
            splat_ranges: Vec::new(),
            targets: None,
            compute: None,
            timer,
            pipelined: false,
            in_flight: Default::default(),
            frame_no: 0,
            count_work: false,
            counting: false,
        })
    }

    /// Whether frames are submitted without waiting for the GPU, up to
    /// [`FRAMES_IN_FLIGHT`] at once as in an interactive loop: their wall
    /// time then measures throughput, and they have no GPU times (no
    /// timestamps are written) and nothing to read back. [`Self::wait`]
    /// waits for them.
    pub fn pipelined(&mut self, on: bool) {
        self.pipelined = on;
    }

    /// Whether frames read back in full ([`Readback::All`]) count the work
    /// of every ray they cast, per draw ([`Rendered::work`]): off by
    /// default, for the counters cost lavapipe 8–35 % of a frame.
    pub fn count_work(&mut self, on: bool) {
        self.count_work = on;
    }

    /// Waits until the GPU has done every frame submitted.
    pub fn wait(&mut self) {
        let _ = self.gpu.device.poll(wgpu::PollType::wait_indefinitely());
        self.in_flight.clear();
    }

    /// The GPU.
    pub fn gpu(&self) -> &Gpu {
        &self.gpu
    }

    /// The colour target of the last frame rendered, if any.
    pub fn colour(&self) -> Option<&wgpu::Texture> {
        self.targets.as_ref().map(|t| &t.colour)
    }

    /// Tiles the GPU cache holds at most.
    pub fn cache_slots(&self) -> u32 {
        self.cache.capacity()
    }

    /// Renders `tiles` (all the frame's tiles, at most [`Self::cache_slots`])
    /// with the settings' shadow steps on every tile, without trees.
    pub fn render(
        &mut self,
        camera: &Camera,
        tiles: &[&TileData],
        settings: &FrameSettings,
        readback: Readback,
    ) -> Result<Rendered, RenderError> {
        let draws: Vec<Draw> = tiles
            .iter()
            .map(|&tile| Draw { tile, shadow_steps: settings.shadow_steps, splats: &[], morph_weight: 1.0 })
            .collect();
        self.render_draws(camera, &draws, settings, readback)
    }

    /// Renders `draws`, each tile with its own quality.
    pub fn render_draws(
        &mut self,
        camera: &Camera,
        draws: &[Draw],
        settings: &FrameSettings,
        readback: Readback,
    ) -> Result<Rendered, RenderError> {
        self.frame_no += 1;
        let size = (camera.width_px, camera.height_px);
        if self.targets.as_ref().map(|t| t.size) != Some(size) {
            // The old targets go first: their memory may be what the new
            // ones need.
            self.targets = None;
            self.targets = Some(Targets::new(&self.gpu.device, size)?);
        }
        let start = Instant::now();
        self.counting = self.count_work && readback == Readback::All && !self.pipelined;
        let camera = &depth_camera(camera, draws);
        let mut stats = FrameStats::default();
        let draws = self.prepare(camera, draws, settings, &mut stats)?;
        self.prepare_compute(camera, &draws);
        let raster = self.compute.is_none() || draws.iter().any(|d| d.mesh || !d.splats.is_empty());
        let submitted = self.encode_and_submit(&draws, raster);
        self.throttle(submitted);
        let timer = self.timer.as_ref().filter(|_| !self.pipelined);
        let times = timer.and_then(|t| t.read(&self.gpu.device, self.compute.is_some(), raster));
        stats.gpu_ms = times.map(|t| t.total_ms);
        stats.gpu_rays_ms = times.and_then(|t| t.rays_ms);
        stats.wall_ms = start.elapsed().as_secs_f64() * 1e3;
        stats.resident_bytes = self.cache.resident_bytes();
        Ok(self.read(readback, stats, draws.len())?)
    }

    /// Uploads tiles and splats, decides how each tile is drawn and writes
    /// the uniforms.
    fn prepare(
        &mut self,
        camera: &Camera,
        tiles: &[Draw],
        settings: &FrameSettings,
        stats: &mut FrameStats,
    ) -> Result<Vec<Prepared>, CacheFull> {
        let mut order: Vec<(f64, usize, &Draw)> =
            tiles.iter().enumerate().map(|(k, d)| (uniforms::tile_near_m(camera, d.tile), k, d)).collect();
        order.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut blocks = Vec::with_capacity(order.len());
        let mut draws = Vec::with_capacity(order.len());
        let mut splats: Vec<Splat> = Vec::new();
        self.splat_ranges = vec![0..0; tiles.len()];
        for (near_m, k, draw) in order {
            let (prepared, block) = self.prepare_tile(camera, settings, (k, draw, near_m), stats, &mut splats)?;
            let mut bytes = bytemuck::bytes_of(&block).to_vec();
            bytes.resize(TILE_STRIDE as usize, 0);
            blocks.extend(bytes);
            draws.push(prepared);
        }
        let (device, queue) = (&self.gpu.device, &self.gpu.queue);
        let frame = FrameUniform::new(camera, settings, &self.cache.mip_rects);
        queue.write_buffer(&self.frame_buffer, 0, bytemuck::bytes_of(&frame));
        queue.write_buffer(&self.tile_buffer, 0, &blocks);
        stats.splats = splats.len() as u32;
        SplatBuffers::upload(&mut self.splats, (device, queue), &self.pipelines, &splats);
        Ok(draws)
    }

    /// Uploads the `k`-th draw, `near_m` from the camera, and appends its
    /// splats to `splats`: how the tile is drawn, and its uniform block.
    fn prepare_tile(
        &mut self,
        camera: &Camera,
        settings: &FrameSettings,
        (k, draw, near_m): (usize, &Draw, f64),
        stats: &mut FrameStats,
        splats: &mut Vec<Splat>,
    ) -> Result<(Prepared, TileUniform), CacheFull> {
        let (device, queue) = (&self.gpu.device, &self.gpu.queue);
        let tile = draw.tile;
        let slot = self.cache.insert(device, queue, tile, self.frame_no)?;
        let mode = draw_mode(camera, tile, settings, near_m);
        // A tile drawn plain shows its own ground: no morph layer.
        let morph = match mode {
            DrawMode::Plain => None,
            _ => self.cache.morph_layer(queue, tile, self.frame_no).map(|layer| (layer, draw.morph_weight)),
        };
        match mode {
            DrawMode::Hull => stats.tiles_hull += 1,
            DrawMode::Inside => stats.tiles_inside += 1,
            DrawMode::Plain => stats.tiles_plain += 1,
        }
        let hull_quad_samples = self.cache.hull_quad_samples(slot).unwrap_or_else(|| tile.hull.quad_samples());
        let start = splats.len() as u32;
        splats.extend_from_slice(draw.splats);
        let tile_splats = start..splats.len() as u32;
        self.splat_ranges[k] = tile_splats.clone();
        let at =
            Placement { draw: k as u32, slot, mode, hull_quad_samples, morph, splats: tile_splats.clone(), near_m };
        let block = TileUniform::new(camera, settings, tile, at, draw.shadow_steps);
        let variant = RayVariant {
            inside: mode == DrawMode::Inside,
            morphing: morph.is_some(),
            whole: uniforms::canopy_whole(camera, tile, &settings.fade),
            linear: matches!(settings.traversal, Traversal::Linear(_)),
            counted: self.counting,
        };
        if mode != DrawMode::Plain && self.compute.is_none() {
            self.pipelines.prepare_ray(device, variant);
        }
        let mesh = mode == DrawMode::Plain || uniforms::needs_filler(tile);
        Ok((Prepared { slot, mode, variant, splats: tile_splats, screen: block.screen, mesh }, block))
    }

    /// With rays in a compute pass, its pipeline for the frame's tiles (one
    /// for all: morphing if any tile morphs, the whole canopy if every tile
    /// has it) and the bins of its ray-cast tiles, nearest first.
    fn prepare_compute(&mut self, camera: &Camera, draws: &[Prepared]) {
        let (Some(compute), Some(targets)) = (&mut self.compute, &self.targets) else { return };
        let rays: Vec<(usize, &Prepared)> =
            draws.iter().enumerate().filter(|(_, d)| d.mode != DrawMode::Plain).collect();
        let variant = RayVariant {
            inside: false,
            morphing: rays.iter().any(|(_, d)| d.variant.morphing),
            whole: rays.iter().all(|(_, d)| d.variant.whole),
            linear: rays.first().is_some_and(|(_, d)| d.variant.linear),
            counted: self.counting,
        };
        let order: Vec<(u32, [u32; 4])> = rays.iter().map(|(k, d)| (*k as u32, d.screen)).collect();
        let bins = compute::bins((camera.width_px, camera.height_px), &order);
        compute.prepare((&self.gpu.device, &self.gpu.queue), targets, (&bins, variant));
    }

    /// Waits for the frame just `submitted`, or, with frames pipelined, for
    /// the oldest one once more than [`FRAMES_IN_FLIGHT`] are.
    fn throttle(&mut self, submitted: Option<wgpu::SubmissionIndex>) {
        // Waiting here makes the frame time the GPU's, not the queue's.
        if !self.pipelined {
            self.wait();
            return;
        }
        self.in_flight.extend(submitted);
        if self.in_flight.len() > FRAMES_IN_FLIGHT {
            let oldest = self.in_flight.pop_front();
            let _ = self.gpu.device.poll(wgpu::PollType::Wait { submission_index: oldest, timeout: None });
        }
    }

    /// Encodes and submits the frame: the compute rays if any, then, if
    /// `raster` (anything is rasterised: rays from hulls, terrain meshes or
    /// splats), the compute rays' depth fill, the splats' light and the
    /// render pass.
    fn encode_and_submit(&self, draws: &[Prepared], raster: bool) -> Option<wgpu::SubmissionIndex> {
        let targets = self.targets.as_ref()?;
        let mut encoder = self.gpu.device.create_command_encoder(&Default::default());
        if self.counting {
            self.work.clear(&mut encoder);
        }
        let computed = self.compute.as_ref();
        let timer = self.timer.as_ref().filter(|_| !self.pipelined);
        if let Some(compute) = computed {
            compute.encode_rays(&mut encoder, &self.frame_group, timer);
            if raster {
                compute.encode_fill(&mut encoder, (targets, &self.frame_group), timer);
            }
        }
        let splats = self.splats.as_ref().filter(|_| draws.iter().any(|d| !d.splats.is_empty()));
        if let Some(splats) = splats {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("splat light"),
                timestamp_writes: timer.and_then(|t| t.light(computed.is_none())),
            });
            let groups = (&self.pipelines, &self.frame_group, &self.tile_group);
            splats.light(&mut pass, groups, draws.iter().map(|d| &d.splats).enumerate());
        }
        if raster {
            self.encode_render_pass(&mut encoder, draws, (targets, splats, timer));
        }
        if let Some(t) = timer {
            t.resolve(&mut encoder);
        }
        Some(self.gpu.queue.submit([encoder.finish()]))
    }

    /// The render pass: hulls casting rays (without a compute rays pass),
    /// terrain meshes, splats.
    fn encode_render_pass(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        draws: &[Prepared],
        (targets, splats, timer): (&Targets, Option<&SplatBuffers>, Option<&PassTimer>),
    ) {
        let computed = self.compute.as_ref();
        let view = |t: &wgpu::Texture| t.create_view(&Default::default());
        let (colour, pixel_data, depth) = (view(&targets.colour), view(&targets.pixel_data), view(&targets.depth));
        let sky = wgpu::Color { r: SKY[0], g: SKY[1], b: SKY[2], a: 1.0 };
        // After the compute ray pass the targets hold its rays.
        let load = |clear| if computed.is_some() { wgpu::LoadOp::Load } else { wgpu::LoadOp::Clear(clear) };
        let attach = |v, clear| {
            Some(wgpu::RenderPassColorAttachment {
                view: v,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations { load: load(clear), store: wgpu::StoreOp::Store },
            })
        };
        let depth_load = if computed.is_some() { wgpu::LoadOp::Load } else { wgpu::LoadOp::Clear(0.0) };
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("tiles"),
            color_attachments: &[attach(&colour, sky), attach(&pixel_data, wgpu::Color::TRANSPARENT)],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &depth,
                depth_ops: Some(wgpu::Operations { load: depth_load, store: wgpu::StoreOp::Store }),
                stencil_ops: None,
            }),
            timestamp_writes: timer.map(|t| t.render(splats.is_none() && computed.is_none())),
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_bind_group(0, &self.frame_group, &[]);
        // Ray-cast tiles first, then the terrain meshes: far tiles, and
        // under ray-cast tiles the lowered crack fillers.
        let hulls = draws.iter().enumerate().filter(|(_, d)| d.mode != DrawMode::Plain && computed.is_none());
        for (k, d) in hulls {
            let (Some((hull, _)), Some(rays)) = (self.cache.meshes(d.slot), self.pipelines.ray(d.variant)) else {
                continue;
            };
            pass.set_pipeline(rays);
            pass.set_bind_group(1, &self.tile_group, &[(k as u64 * TILE_STRIDE) as u32]);
            draw(&mut pass, hull, hull.index_count);
        }
        pass.set_pipeline(&self.pipelines.plain);
        for (k, d) in draws.iter().enumerate().filter(|(_, d)| d.mesh) {
            let Some((_, terrain)) = self.cache.meshes(d.slot) else { continue };
            pass.set_bind_group(1, &self.tile_group, &[(k as u64 * TILE_STRIDE) as u32]);
            let count = if d.mode == DrawMode::Plain { terrain.index_count } else { terrain.grid_count };
            draw(&mut pass, terrain, count);
        }
        if let Some(splats) = splats {
            pass.set_pipeline(&self.pipelines.splat);
            splats.bind(&mut pass);
            for (k, d) in draws.iter().enumerate().filter(|(_, d)| !d.splats.is_empty()) {
                pass.set_bind_group(1, &self.tile_group, &[(k as u64 * TILE_STRIDE) as u32]);
                pass.draw(0..4, d.splats.clone());
            }
        }
    }

    /// The frame's images, as `readback` asks, and the work of its `draws`
    /// draws with its pixel data.
    fn read(&self, readback: Readback, stats: FrameStats, draws: usize) -> Result<Rendered, AllocError> {
        let mut out = Rendered { stats, ..Default::default() };
        let (Some(targets), true) = (&self.targets, readback != Readback::None && !self.pipelined) else {
            return Ok(out);
        };
        let (device, queue) = (&self.gpu.device, &self.gpu.queue);
        out.colour = bytemuck::cast_slice(&targets::read_texture(device, queue, &targets.colour, 4)?).to_vec();
        if readback == Readback::All {
            let data: Vec<[u32; 4]> =
                bytemuck::cast_slice(&targets::read_texture(device, queue, &targets.pixel_data, 16)?).to_vec();
            out.view_z_m = data.iter().map(|d| f32::from_bits(d[2])).collect();
            out.fetches = data.iter().map(|d| [d[0], d[1]]).collect();
            out.draws = data.iter().map(|d| d[3]).collect();
            if self.counting {
                out.work = self.work.read(device, queue, draws);
            }
        }
        Ok(out)
    }

    /// The light the last frame's splats received through the terrain,
    /// its draws' splats in their order (read back on demand, for checks
    /// against the CPU's shadow rule).
    pub fn splat_lights(&self) -> Vec<f32> {
        let Some(splats) = &self.splats else { return Vec::new() };
        let lights = splats.read_lights(&self.gpu.device, &self.gpu.queue);
        let range = |r: &std::ops::Range<u32>| lights.get(r.start as usize..r.end as usize).unwrap_or_default();
        self.splat_ranges.iter().flat_map(range).copied().collect()
    }
}

/// The camera with its near plane pushed out to half the distance of the
/// nearest tile: nothing is clipped that could be seen, and depth values
/// (`near / z`) stay far from zero, where software rasterisers lose
/// absolute precision (lavapipe: ~3·10⁻¹³, i.e. 10⁻⁴ relative at 300 km
/// with a 1 mm near plane).
fn depth_camera(camera: &Camera, draws: &[Draw]) -> Camera {
    let nearest = draws.iter().map(|d| uniforms::tile_near_m(camera, d.tile)).fold(f64::INFINITY, f64::min);
    let near_m = if nearest.is_finite() { (0.5 * nearest).max(camera.near_m) } else { camera.near_m };
    Camera { near_m, ..*camera }
}

fn draw(pass: &mut wgpu::RenderPass<'_>, mesh: &cache::Mesh, indices: u32) {
    pass.set_vertex_buffer(0, mesh.vertices.slice(..));
    pass.set_index_buffer(mesh.indices.slice(..), wgpu::IndexFormat::Uint32);
    pass.draw_indexed(0..indices, 0, 0..1);
}

/// How a tile is drawn from `camera`.
fn draw_mode(camera: &Camera, tile: &TileData, settings: &FrameSettings, near_m: f64) -> DrawMode {
    if uniforms::camera_inside(camera, tile) {
        return DrawMode::Inside;
    }
    if raycast::plain(&settings.fade, near_m, (tile.range.mesh_error_m as f64, tile.flat_error_m())) {
        DrawMode::Plain
    } else {
        DrawMode::Hull
    }
}

fn tile_buffer(device: &wgpu::Device, slots: u32) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("tiles"),
        size: TILE_STRIDE * slots.max(1) as u64,
        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}
