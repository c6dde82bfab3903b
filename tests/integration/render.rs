//! The GPU ray caster against the exact CPU reference (lavapipe in CI,
//! small images): real tiles of the demo and rmnp (also with a shadow
//! quality per tile), stiff synthetic scenes,
//! deep zoom, poles and the antimeridian, tile seams and shadows across
//! them, and work left out; rays cast from hull fragments and in compute
//! passes alike.
//!
//! Stated tolerances (measured values are printed with `--nocapture`):
//! hit masks differ on at most 0.1 % of pixels; over pixels both hit, the
//! relative depth error is at most 1e-5 RMS and 1e-4 at worst (measured:
//! ~1e-7 and ~2e-5, the worst where a ray skims a crown), and colour PSNR
//! is at least 40 dB (measured: 84 dB to identical).

use crate::common;
use glam::{DVec2, DVec3};
use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};
use sylva::cem::surface::SurfaceType;
use sylva::client::camera::Camera;
use sylva::client::globe::{self, Geodetic};
use sylva::client::lod::morphs;
use sylva::client::raycast::{self, Fade, Traversal, TreeBlend};
use sylva::client::reference::{self, Departure, Image, Lighting};
use sylva::client::render::gpu::Gpu;
use sylva::client::render::uniforms::{FrameSettings, needs_filler};
use sylva::client::render::{Draw, DrawWork, RayPass, Readback, Rendered, Renderer};
use sylva::client::source::{RegionSource, TileSource};
use sylva::client::tile::{TileData, TilePayload};
use sylva::client::trees::{self, Splat, TreeSettings};
use sylva::grid::{TileGrid, TileId};

/// Largest share of pixels whose hit may differ (silhouette edges).
const MAX_MISMATCH: f64 = 0.001;
/// Largest RMS and single relative depth error over pixels both hit.
const MAX_DEPTH_RMS_REL: f64 = 1e-5;
const MAX_DEPTH_REL: f64 = 1e-4;
/// Smallest colour PSNR over pixels both hit, dB.
const MIN_PSNR_DB: f64 = 40.0;

/// Where rays are cast: the tests that compare with the reference run both.
const PASSES: [RayPass; 2] = [RayPass::Fragment, RayPass::Compute];

/// One renderer per tile shape and ray pass, shared by the tests (lavapipe
/// compiles the pipelines once; frames render one at a time).
fn with_renderer_in<R>(pass: RayPass, samples: u32, halo: u32, f: impl FnOnce(&mut Renderer) -> R) -> R {
    type Shared = Mutex<HashMap<(u32, u32, RayPass), Renderer>>;
    static RENDERERS: OnceLock<Shared> = OnceLock::new();
    let mut map = RENDERERS.get_or_init(|| Mutex::new(HashMap::new())).lock().unwrap_or_else(|e| e.into_inner());
    let renderer = map.entry((samples, halo, pass)).or_insert_with(|| {
        let gpu = Gpu::open().expect("a GPU adapter (lavapipe: apt-get install mesa-vulkan-drivers)");
        Renderer::new(gpu, samples, halo, 256 << 20, true).expect("room for the tile cache").with_ray_pass(pass)
    });
    f(renderer)
}

fn with_renderer<R>(samples: u32, halo: u32, f: impl FnOnce(&mut Renderer) -> R) -> R {
    with_renderer_in(RayPass::Fragment, samples, halo, f)
}

struct Both {
    gpu: Rendered,
    cpu: Image,
    departure: Departure,
}

fn render_both(tiles: &[TileData], camera: &Camera, settings: &FrameSettings) -> Both {
    render_both_in(RayPass::Fragment, tiles, camera, settings)
}

fn render_both_in(pass: RayPass, tiles: &[TileData], camera: &Camera, settings: &FrameSettings) -> Both {
    let (samples, halo) = (tiles[0].frame.samples, tiles[0].halo as u32);
    let refs: Vec<&TileData> = tiles.iter().collect();
    let gpu = with_renderer_in(pass, samples, halo, |r| {
        r.render(camera, &refs, settings, Readback::All).expect("fits the cache")
    });
    let lighting = lighting_of(settings);
    let cpu = reference::render(camera, tiles, &lighting);
    let departure = reference::compare(&gpu.colour, &gpu.view_z_m, &cpu);
    Both { gpu, cpu, departure }
}

fn settings(traversal: Traversal, sun: Option<DVec3>) -> FrameSettings {
    FrameSettings { traversal, shadow_steps: 10, sun_ecef: sun, fade: Fade::NONE }
}

/// The reference's lighting for a GPU frame's settings.
fn lighting_of(settings: &FrameSettings) -> Lighting {
    Lighting { sun_ecef: settings.sun_ecef, shadow_steps: settings.shadow_steps, fade: settings.fade }
}

fn sun_at(lon: f64, lat: f64, azimuth_deg: f64, elevation_deg: f64) -> DVec3 {
    let (sa, ca) = azimuth_deg.to_radians().sin_cos();
    let (se, ce) = elevation_deg.to_radians().sin_cos();
    globe::enu_basis(lon, lat) * DVec3::new(sa * ce, ca * ce, se)
}

fn assert_close(name: &str, d: &Departure) {
    eprintln!("{name}: {d:?}");
    assert!(
        d.mismatch_share() <= MAX_MISMATCH,
        "{name}: hit masks differ on {:.3} % of pixels",
        100.0 * d.mismatch_share()
    );
    assert!(d.depth_rms_rel <= MAX_DEPTH_RMS_REL && d.depth_max_rel <= MAX_DEPTH_REL, "{name}: depth error {d:?}");
    assert!(d.psnr_db >= MIN_PSNR_DB, "{name}: PSNR {} dB", d.psnr_db);
}

/// As [`assert_close`], but up to [`MAX_MISMATCH`] of the pixels may hit
/// at another depth: rays that skim a crest, where the reference's surface
/// (rounded to `f32` above the ellipsoid, ~1e-4 m) decides the hit (in the
/// morph test, a weight 1e-4 away moves such a pixel's hit as far).
fn assert_close_but_skims(name: &str, gpu: &Rendered, mut cpu: Image) {
    let mut view_z_m = gpu.view_z_m.clone();
    let mut skims = 0;
    for (z, z_ref) in view_z_m.iter_mut().zip(cpu.view_z_m.iter_mut()) {
        if *z > 0.0 && *z_ref > 0.0 && f64::from(((*z - *z_ref) / *z_ref).abs()) > MAX_DEPTH_REL {
            (*z, *z_ref, skims) = (0.0, 0.0, skims + 1);
        }
    }
    let share = skims as f64 / view_z_m.len().max(1) as f64;
    assert!(share <= MAX_MISMATCH, "{name}: {skims} pixels hit at another depth");
    assert_close(name, &reference::compare(&gpu.colour, &view_z_m, &cpu));
}

/// The `n × n` tiles from `first` (south-west) of a source.
fn block(source: &dyn TileSource, first: TileId, n: u64, halo: usize) -> Vec<TileData> {
    let grid = source.grid();
    let mut out = Vec::new();
    for dr in 0..n {
        for dc in 0..n {
            let id = TileId::new(first.level, first.row + dr, first.col + dc);
            if let Some(p) = source.fetch(id, halo).expect("fetch") {
                out.push(TileData::prepare(&grid, p).expect("prepare"));
            }
        }
    }
    out
}

/// A tile of a world-anchored synthetic terrain `f(lon, lat) → (ground,
/// canopy, class)`.
fn synthetic(grid: &TileGrid, id: TileId, halo: usize, f: &dyn Fn(f64, f64) -> (f64, f64, u8)) -> TileData {
    let samples = grid.tile_samples(id, halo);
    let (w, h) = (samples.width(), samples.height());
    let mut p = TilePayload { id, halo, cem: vec![], dem: vec![], surface: vec![], colour: vec![] };
    for y in 0..h {
        for x in 0..w {
            let (lon, lat) = samples.lon_lat(x, y);
            let (ground, canopy, class) = f(lon, lat);
            p.dem.push(ground as f32);
            p.cem.push((ground + canopy) as f32);
            p.surface.push(class);
            let c = sylva::encode::relief::base_colour(class, None).map(|v| v as u8);
            p.colour.push([c[0], c[1], c[2], 255]);
        }
    }
    TileData::prepare(grid, p).expect("synthetic tile")
}

/// A 2×2 block of synthetic tiles with its south-west corner at the tile
/// containing `(lon, lat)`.
fn synthetic_block(
    grid: &TileGrid,
    lon: f64,
    lat: f64,
    level: u32,
    halo: usize,
    f: &dyn Fn(f64, f64) -> (f64, f64, u8),
) -> Vec<TileData> {
    let first = grid.tile_containing(lon, lat, level);
    let ids = [(0, 0), (0, 1), (1, 0), (1, 1)].map(|(r, c)| TileId::new(level, first.row + r, first.col + c));
    ids.iter().map(|&id| synthetic(grid, id, halo, f)).collect()
}

/// Metres east and north of `(lon0, lat0)` (a local tangent plane, enough
/// for shaping synthetic terrain).
fn metres(lon: f64, lat: f64, lon0: f64, lat0: f64) -> (f64, f64) {
    let m = sylva::geo::METRES_PER_DEGREE;
    ((lon - lon0) * m * lat0.to_radians().cos(), (lat - lat0) * m)
}

fn small_grid() -> TileGrid {
    TileGrid::new(36.0, 65).unwrap()
}

/// Four level-11 tiles of the demo, a camera looking over them from their
/// south-east corner, and the afternoon sun there.
fn demo_scene() -> (TileGrid, Vec<TileData>, Camera, Option<DVec3>) {
    let demo = RegionSource::new(Arc::new(common::demo()));
    let grid = demo.grid();
    let first = grid.tile_containing(10.12, 46.36, 11);
    let tiles = block(&demo, first, 2, 32);
    let s = grid.sector(first);
    let eye = Geodetic::new(s.max_lon, s.min_lat - 0.002, 1500.0);
    let camera = Camera::looking(eye, 10.0, -20.0, 60.0, (160, 120));
    (grid, tiles, camera, Some(sun_at(eye.lon_deg, eye.lat_deg, 150.0, 35.0)))
}

#[test]
fn gpu_matches_the_reference_on_real_tiles() {
    let (grid, demo_tiles, demo_camera, sun) = demo_scene();
    let rmnp = RegionSource::new(Arc::new(common::region("examples/rmnp.toml")));
    let first = grid.tile_containing(-105.62, 40.36, 10);
    let rmnp_tiles = block(&rmnp, first, 2, 32);
    let s = grid.sector(first);
    let eye = Geodetic::new(s.min_lon + 0.01, s.min_lat - 0.01, 3600.0);
    let rmnp_camera = Camera::looking(eye, 40.0, -15.0, 60.0, (160, 120));
    for pass in PASSES {
        let both = render_both_in(pass, &demo_tiles, &demo_camera, &settings(Traversal::Exact, sun));
        assert!(both.cpu.view_z_m.iter().filter(|&&z| z > 0.0).count() > 5000, "the view shows the tiles");
        assert_close(&format!("demo, {pass:?}"), &both.departure);
        let both = render_both_in(pass, &rmnp_tiles, &rmnp_camera, &settings(Traversal::Exact, sun));
        assert_close(&format!("rmnp, {pass:?}"), &both.departure);
    }
}

#[test]
fn render_targets_the_gpu_cannot_hold_are_an_error_naming_their_size() {
    // Regression: a 16384×16384 flight on lavapipe panicked in wgpu's
    // handler for uncaptured errors ("Out of Memory").
    let (_, tiles, camera, sun) = demo_scene();
    let (samples, halo) = (tiles[0].frame.samples, tiles[0].halo as u32);
    let settings = settings(Traversal::Exact, sun);
    let refs: Vec<&TileData> = tiles.iter().collect();
    with_renderer(samples, halo, |r| {
        let side = r.gpu().device.limits().max_texture_dimension_2d;
        let wide = Camera { width_px: side + 1, height_px: 1, ..camera };
        let err = r.render(&wide, &refs, &settings, Readback::None).err().map(|e| e.to_string());
        let wanted =
            format!("cannot allocate render targets of {}×1: the GPU's textures are at most {side}×{side}", side + 1);
        assert_eq!(err.as_deref(), Some(wanted.as_str()));
        // Beyond the GPU's memory (lavapipe's) or not, never a panic.
        let huge = Camera { width_px: 16384, height_px: 16384, ..camera };
        if let Err(e) = r.render(&huge, &[], &settings, Readback::None) {
            let said = e.to_string();
            assert!(said.starts_with("cannot allocate render targets of 16384×16384: "), "{said}");
        }
        // The renderer goes on at a size it can hold.
        let rendered = r.render(&camera, &refs, &settings, Readback::All).expect("fits");
        assert!(rendered.view_z_m.iter().any(|&z| z > 0.0), "the frame shows the tiles");
    });
}

#[test]
fn a_coarser_hull_keeps_the_exact_traversal_on_the_reference() {
    // Hull quads of 64 samples (for software rasterisers): rays start
    // farther from the surface, so they fetch more, and still hit the same.
    let (_, tiles, camera, sun) = demo_scene();
    let settings = settings(Traversal::Exact, sun);
    let fine = render_both(&tiles, &camera, &settings);
    let gpu = Gpu::open().expect("a GPU adapter");
    let mut coarse = Renderer::new(gpu, tiles[0].frame.samples, tiles[0].halo as u32, 256 << 20, false)
        .expect("room for the tile cache")
        .with_hull_factor(4);
    let refs: Vec<&TileData> = tiles.iter().collect();
    let rendered = coarse.render(&camera, &refs, &settings, Readback::All).expect("fits the cache");
    let departure = reference::compare(&rendered.colour, &rendered.view_z_m, &fine.cpu);
    assert_close("demo, 64-sample hull quads", &departure);
    let fetches = |r: &Rendered| r.fetches.iter().map(|f| u64::from(f[0])).sum::<u64>();
    assert!(fetches(&rendered) > fetches(&fine.gpu), "{} vs {}", fetches(&rendered), fetches(&fine.gpu));
}

#[test]
fn per_tile_shadow_quality_matches_the_reference() {
    // The LOD selection gives each tile its own shadow samples per hit.
    let (_, tiles, camera, sun) = demo_scene();
    let settings = settings(Traversal::Exact, sun);
    let steps: Vec<u32> = [0, 3, 10, 30].into_iter().cycle().take(tiles.len()).collect();
    let draws: Vec<Draw> = tiles
        .iter()
        .zip(&steps)
        .map(|(tile, &shadow_steps)| Draw { tile, shadow_steps, splats: &[], morph_weight: 1.0 })
        .collect();
    let (samples, halo) = (tiles[0].frame.samples, tiles[0].halo as u32);
    let gpu =
        with_renderer(samples, halo, |r| r.render_draws(&camera, &draws, &settings, Readback::All).expect("fits"));
    let lighting = lighting_of(&settings);
    let per_tile = reference::compare(
        &gpu.colour,
        &gpu.view_z_m,
        &reference::render_with_steps(&camera, &tiles, &lighting, &steps),
    );
    assert_close("per-tile shadow steps", &per_tile);
    // Against one quality for all the tiles, the shading differs.
    let uniform = reference::compare(&gpu.colour, &gpu.view_z_m, &reference::render(&camera, &tiles, &lighting));
    assert!(uniform.psnr_db + 3.0 < per_tile.psnr_db, "{uniform:?} vs {per_tile:?}");
}

#[test]
fn a_morphing_tile_draws_the_blended_surface_at_every_weight() {
    // The demo's four tiles morphing from their parent's surface: drawn
    // from one upload per morph with the weight in a uniform, they show
    // what the CPU reference shows for the surface blended at that weight.
    let (grid, tiles, camera, sun) = demo_scene();
    let demo = RegionSource::new(Arc::new(common::demo()));
    let parent_of = |t: &TileData| {
        let payload = demo.fetch(t.id().parent().expect("a parent"), t.halo).expect("fetch").expect("data");
        TileData::prepare(&grid, payload).expect("prepare")
    };
    let parents: Vec<TileData> = tiles.iter().map(parent_of).collect();
    let pairs: Vec<TileData> = tiles.iter().zip(&parents).map(|(t, p)| morphs::pair(&grid, t, p)).collect();
    let settings = settings(Traversal::Exact, sun);
    let lighting = lighting_of(&settings);
    let (samples, halo) = (tiles[0].frame.samples, tiles[0].halo as u32);
    let own = reference::render(&camera, &tiles, &lighting);
    for (weight, pass) in [0.0, 0.2, 0.4, 0.6, 0.8, 1.0].into_iter().flat_map(|w| PASSES.map(|p| (w, p))) {
        let draws: Vec<Draw> = pairs
            .iter()
            .map(|tile| Draw { tile, shadow_steps: 10, splats: &[], morph_weight: weight as f32 })
            .collect();
        let gpu = with_renderer_in(pass, samples, halo, |r| r.render_draws(&camera, &draws, &settings, Readback::All))
            .expect("fits the cache");
        let blended: Vec<TileData> =
            tiles.iter().zip(&parents).map(|(t, p)| morphs::blend(&grid, t, p, weight).expect("blend")).collect();
        let cpu = reference::render(&camera, &blended, &lighting);
        assert_close_but_skims(&format!("morph weight {weight}, {pass:?}"), &gpu, cpu);
        let from_own = reference::compare(&gpu.colour, &gpu.view_z_m, &own);
        if weight < 1.0 {
            assert!(from_own.depth_rms_rel > 10.0 * MAX_DEPTH_RMS_REL, "the parent's surface shows: {from_own:?}");
        } else {
            assert_close("morph done", &from_own);
        }
    }
}

/// Rolling ground with forest patches around `(lon0, lat0)`.
fn hills(lon0: f64, lat0: f64) -> impl Fn(f64, f64) -> (f64, f64, u8) {
    move |lon, lat| {
        let (x, y) = metres(lon, lat, lon0, lat0);
        let ground = 1000.0 + 8.0 * (x / 90.0).sin() * (y / 70.0).cos();
        let forest = ((x / 130.0).sin() + (y / 110.0).cos()) > 0.6;
        (ground, if forest { 18.0 + 4.0 * (x / 9.0).sin() * (y / 11.0).cos() } else { 0.0 }, forest as u8)
    }
}

#[test]
fn the_exact_traversal_never_misses_in_stiff_cases() {
    let grid = small_grid();
    let (lon0, lat0) = (7.3, 45.1);
    let first = grid.tile_containing(lon0, lat0, 13);
    let s = grid.sector(first);
    let (west, south) = (s.min_lon, s.min_lat);
    let tile_deg = s.max_lat - s.min_lat;
    let sun = Some(sun_at(lon0, lat0, 120.0, 30.0));
    let exact = settings(Traversal::Exact, sun);

    let rolling = synthetic_block(&grid, lon0, lat0, 13, 8, &hills(lon0, lat0));
    let cliff_at = west + tile_deg * 0.75;
    let cliff =
        synthetic_block(&grid, lon0, lat0, 13, 8, &|lon, _| (if lon < cliff_at { 1000.0 } else { 2000.0 }, 0.0, 3));
    let valley_lon = west + tile_deg;
    let valley = synthetic_block(&grid, lon0, lat0, 13, 8, &move |lon, lat| {
        let (x, _) = metres(lon, lat, valley_lon, lat0);
        (1000.0 + 0.8 * x.abs(), 0.0, 0)
    });
    let canopy_top = rolling.iter().map(|t| t.base_m + t.range.max_m as f64).fold(f64::MIN, f64::max);
    let cases: Vec<(&str, &[TileData], Camera)> = vec![
        (
            "grazing 0.01°",
            &rolling,
            Camera::looking(
                Geodetic::new(west + tile_deg * 0.1, south + tile_deg * 0.1, 1009.0),
                45.0,
                -0.01,
                10.0,
                (160, 100),
            ),
        ),
        (
            "vertical",
            &rolling,
            Camera::looking(Geodetic::new(west + tile_deg, south + tile_deg, 1400.0), 0.0, -90.0, 40.0, (120, 120)),
        ),
        (
            "1000 m cliff",
            &cliff,
            Camera::looking(
                Geodetic::new(west + tile_deg * 0.3, south + tile_deg, 1500.0),
                90.0,
                0.0,
                60.0,
                (160, 120),
            ),
        ),
        (
            "just above the canopy",
            &rolling,
            Camera::looking(
                Geodetic::new(west + tile_deg * 0.9, south + tile_deg * 0.6, canopy_top + 0.5),
                60.0,
                -3.0,
                60.0,
                (160, 100),
            ),
        ),
        (
            "inside a valley",
            &valley,
            Camera::looking(Geodetic::new(valley_lon, south + tile_deg * 0.2, 1060.0), 0.0, 2.0, 60.0, (160, 100)),
        ),
    ];
    for ((name, tiles, camera), pass) in cases.iter().flat_map(|case| PASSES.map(|pass| (case, pass))) {
        let both = render_both_in(pass, tiles, camera, &exact);
        let hits = both.cpu.view_z_m.iter().filter(|&&z| z > 0.0).count();
        assert!(hits > 1000, "{name}: the view shows the scene ({hits} pixels)");
        assert_eq!(both.departure.misses, 0, "{name}, {pass:?}: exact traversal missed: {:?}", both.departure);
        assert_close(&format!("{name}, {pass:?}"), &both.departure);
    }
}

#[test]
fn the_linear_march_misses_are_measured() {
    let grid = small_grid();
    let (lon0, lat0) = (7.3, 45.1);
    let s = grid.sector(grid.tile_containing(lon0, lat0, 13));
    let tile_deg = s.max_lat - s.min_lat;
    let tiles = synthetic_block(&grid, lon0, lat0, 13, 8, &hills(lon0, lat0));
    let camera = Camera::looking(
        Geodetic::new(s.min_lon + tile_deg * 0.1, s.min_lat + tile_deg * 0.1, 1009.0),
        45.0,
        -0.01,
        10.0,
        (160, 100),
    );
    let misses = |t: Traversal| render_both(&tiles, &camera, &settings(t, None)).departure.misses;
    let (exact, m30, m90) = (misses(Traversal::Exact), misses(Traversal::Linear(30)), misses(Traversal::Linear(90)));
    eprintln!("grazing view, pixels missed: exact {exact}, linear 30 steps {m30}, linear 90 steps {m90}");
    assert_eq!(exact, 0);
    assert!(m30 > 0, "30 steps cannot cross a grazing view (Figure 6.16)");
    assert!(m90 < m30, "more steps, fewer misses");
}

/// Builds the same scene (heights and camera in units of the tile's width)
/// on tile `id`: payload heights have the ellipsoid's drop taken out, so
/// every level sees one flat-frame scene, scaled. Heights more than
/// `nodata_beyond` tile widths from the ellipsoid are nodata (in the heights
/// alone, as a source that flags nothing else would send them).
fn scaled_scene(grid: &TileGrid, id: TileId, nodata_beyond: f64) -> (TileData, Camera) {
    let halo = 4;
    let frame = sylva::client::frame::TileFrame::new(grid, id);
    let width = frame.spacing_m.x * (grid.samples() - 1) as f64;
    let drops = frame.drops_m(halo);
    let size = grid.samples() as usize + 2 * halo;
    let mut p = TilePayload { id, halo, cem: vec![], dem: vec![], surface: vec![], colour: vec![] };
    for y in 0..size {
        for x in 0..size {
            let (u, v) = (x as f64 / (size - 1) as f64, 1.0 - y as f64 / (size - 1) as f64);
            let ground = width * 0.03 * ((u * 9.0).sin() * (v * 7.0).cos() + 0.3 * (u * 31.0).sin());
            let forest = (u * 13.0).sin() * (v * 11.0).cos() > 0.2;
            let canopy = if forest { width * 0.012 } else { 0.0 };
            let drop = drops[(size - 1 - y) * size + x];
            let none = (ground + canopy - drop).abs() > nodata_beyond * width;
            p.dem.push(if none { f32::NAN } else { (ground - drop) as f32 });
            p.cem.push(if none { f32::NAN } else { (ground + canopy - drop) as f32 });
            p.surface.push(forest as u8);
            let c = sylva::encode::relief::base_colour(forest as u8, None).map(|v| v as u8);
            p.colour.push([c[0], c[1], c[2], 255]);
        }
    }
    let tile = TileData::prepare(grid, p).expect("scene tile");
    let eye_local = DVec3::new(-0.1 * width, -0.45 * width, 0.2 * width - tile.base_m);
    let look = DVec3::new(0.35, 0.9, -0.3).normalize();
    let right = look.cross(DVec3::Z).normalize();
    let up = right.cross(look);
    let camera = Camera {
        position_ecef: tile.frame.to_ecef(eye_local),
        rotation: tile.frame.basis * glam::DMat3::from_cols(right, up, -look),
        fov_y_rad: 50f64.to_radians(),
        width_px: 128,
        height_px: 96,
        near_m: sylva::client::camera::NEAR_M,
    };
    (tile, camera)
}

#[test]
fn deep_zoom_renders_the_scene_of_a_coarse_tile() {
    // A level-2 tile (1,000 km) at 4.5° N, 4.5° E and a level-22 tile
    // (1 m) 6,000 km east of it: the same scene in tile units.
    let grid = small_grid();
    let coarse = TileId::new(2, 10, 20);
    let deep = TileId::new(22, (10 * 2 + 1) << 19, 27_787_264);
    let (tile_a, cam_a) = scaled_scene(&grid, coarse, f64::INFINITY);
    let (tile_b, cam_b) = scaled_scene(&grid, deep, f64::INFINITY);
    let apart = (tile_a.frame.origin_ecef - tile_b.frame.origin_ecef).length();
    assert!((5.7e6..6.1e6).contains(&apart), "{apart} m apart (6,000 km along the parallel)");
    let flat = settings(Traversal::Exact, None);
    let a = render_both(std::slice::from_ref(&tile_a), &cam_a, &flat);
    let b = render_both(std::slice::from_ref(&tile_b), &cam_b, &flat);
    assert_close("level 2", &a.departure);
    assert_close("level 22", &b.departure);
    // The deep view against the coarse one, depth in tile units.
    let scale = tile_a.frame.spacing_m.x / tile_b.frame.spacing_m.x;
    let coarse_as_image = Image {
        width: 128,
        height: 96,
        colour: a.gpu.colour.clone(),
        view_z_m: a.gpu.view_z_m.iter().map(|z| (*z as f64 / scale) as f32).collect(),
    };
    let d = reference::compare(&b.gpu.colour, &b.gpu.view_z_m, &coarse_as_image);
    assert!(coarse_as_image.view_z_m.iter().filter(|&&z| z > 0.0).count() > 5000);
    assert_close("level 22 against level 2", &d);
}

#[test]
fn nodata_shows_the_sky_at_every_level() {
    // Regression: where a coarse tile's flat frame needs the crack filler
    // under it (a level-2 tile, 1,000 km), the filler drew ground at the
    // tile's lowest height over samples whose heights were nodata but whose
    // class was not: 3,599 pixels the reference leaves to the sky. Then
    // the filler, lowered under the ground, still showed through holes
    // within its band beside the tile's edge, which this slanting view of a
    // tile with 9 km of flat-frame error makes the whole tile: 866 pixels,
    // until rays that come down through the tile's box were kept from it.
    let grid = small_grid();
    let ids = [TileId::new(2, 10, 20), TileId::new(12, 10 << 10, 20 << 10), TileId::new(22, 21 << 19, 27_787_264)];
    for (id, pass) in ids.into_iter().flat_map(|id| PASSES.map(|pass| (id, pass))) {
        let (tile, camera) = scaled_scene(&grid, id, 0.012);
        let both = render_both_in(pass, std::slice::from_ref(&tile), &camera, &settings(Traversal::Exact, None));
        let (hits, sky) = (both.cpu.view_z_m.iter().filter(|&&z| z > 0.0).count(), both.cpu.view_z_m.len());
        assert!((2000..sky - 4000).contains(&hits), "level {}: holes and ground in view ({hits} hits)", id.level);
        let (name, d) = (format!("level {} with holes, {pass:?}", id.level), &both.departure);
        assert_eq!(needs_filler(&tile), id.level == 2, "{name}: the coarse tile alone needs the filler");
        assert_close(&name, d);
    }
}

/// Terrain defined on the sphere (from the ECEF direction), continuous
/// across the antimeridian and over the poles.
fn globe_terrain(lon: f64, lat: f64) -> (f64, f64, u8) {
    let p = Geodetic::new(lon, lat, 0.0).to_ecef().normalize();
    let ground = 900.0
        + 700.0 * (40.0 * p.x + 3.0).sin() * (35.0 * p.y).cos() * (30.0 * p.z).sin()
        + 120.0 * (400.0 * p.x).sin() * (380.0 * p.y + 300.0 * p.z).cos();
    let forest = (900.0 * p.x).sin() * (850.0 * p.y).cos() + (700.0 * p.z).sin() > 0.4;
    (ground, if forest { 25.0 } else { 0.0 }, if forest { 1 } else { 3 })
}

/// Flat ground: forest where the longitude is 0…90° or −180…−90°, water
/// elsewhere (quadrants meeting at the poles).
fn polar_quadrants(lon: f64, _lat: f64) -> (f64, f64, u8) {
    (0.0, 0.0, if lon.rem_euclid(180.0) < 90.0 { 1 } else { 3 })
}

/// The longitude where the ray through pixel `(x, y)` of `camera` meets
/// the ellipsoid (bisection on the height along the ray).
fn ground_lon(camera: &Camera, x: u32, y: u32) -> f64 {
    let dir = camera.ray_dir(x, y);
    let at = |t: f64| Geodetic::from_ecef(camera.position_ecef + dir * t);
    let (mut lo, mut hi) = (0.0, 1e7);
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if at(mid).height_m > 0.0 { lo = mid } else { hi = mid }
    }
    at(lo).lon_deg
}

#[test]
fn coarse_tiles_at_a_pole_are_drawn_plain_in_their_true_place() {
    // Regression: a small GPU cache holds a view of a pole only in coarse
    // tiles, whose flat frames (rectangles for wedges) put the ground tens
    // of kilometres from its place; their terrain meshes are on the
    // ellipsoid, and they are drawn so.
    let grid = small_grid();
    let camera = Camera::looking(Geodetic::new(0.0, -90.0, 80_000.0), 0.0, -90.0, 40.0, (96, 96));
    let cap = sylva::grid::BBox { west: -180.0, south: -90.0, east: 180.0, north: -85.0 };
    let tiles: Vec<TileData> =
        grid.tiles_over(&cap, 2).into_iter().map(|id| synthetic(&grid, id, 8, &polar_quadrants)).collect();
    let fade = Fade { focal_px: camera.focal_px(), canopy_ref_m: 30.0, lo_px: 0.5, hi_px: 2.0, trees: TreeBlend::NONE };
    let frame = FrameSettings { fade, ..settings(Traversal::Exact, None) };
    let refs: Vec<&TileData> = tiles.iter().collect();
    let out = with_renderer(65, 8, |r| r.render(&camera, &refs, &frame, Readback::All).expect("fits the cache"));
    assert_eq!(out.stats.tiles_plain as usize, tiles.len(), "{:?}", out.stats);
    let (w, h) = (camera.width_px, camera.height_px);
    let wrong = (0..w * h)
        .filter(|&k| {
            let [r, g, b, _] = out.colour[k as usize];
            let forest = g > b && g > r;
            forest != (ground_lon(&camera, k % w, k / w).rem_euclid(180.0) < 90.0)
        })
        .count();
    // On the quadrants' edges a pixel may go either way.
    assert!(wrong <= 2 * (w + h) as usize, "{wrong} pixels of the wrong quadrant");
    // Under a fade that keeps every canopy, the same tiles are ray cast.
    let whole = FrameSettings { fade: Fade::NONE, ..frame };
    let out = with_renderer(65, 8, |r| r.render(&camera, &refs, &whole, Readback::All).expect("fits the cache"));
    assert_eq!(out.stats.tiles_plain, 0);
}

/// The tiles the quadtree selects for `camera` over `bounds`, built from
/// the globe terrain.
fn selected(grid: &TileGrid, bounds: sylva::grid::BBox, camera: &Camera) -> Vec<TileData> {
    selected_at_most(grid, bounds, camera, usize::MAX)
}

/// As [`selected`], coarser until at most `max_tiles` tiles.
fn selected_at_most(grid: &TileGrid, bounds: sylva::grid::BBox, camera: &Camera, max_tiles: usize) -> Vec<TileData> {
    selected_of(grid, bounds, camera, max_tiles, 8, &globe_terrain)
}

/// The tiles (with `halo`) of terrain `f` the quadtree selects for
/// `camera` over `bounds`, coarser until at most `max_tiles` tiles.
fn selected_of(
    grid: &TileGrid,
    bounds: sylva::grid::BBox,
    camera: &Camera,
    max_tiles: usize,
    halo: usize,
    f: &dyn Fn(f64, f64) -> (f64, f64, u8),
) -> Vec<TileData> {
    let mut max_error_px = 2.0;
    loop {
        let rule = sylva::client::quadtree::LodRule { max_error_px, max_level: 16 };
        let selection = sylva::client::quadtree::select(grid, &bounds, camera, &|_| Some((-500.0, 2500.0)), &rule);
        if selection.tiles.len() <= max_tiles {
            return selection.tiles.iter().map(|s| synthetic(grid, s.id, halo, f)).collect();
        }
        max_error_px *= 1.5;
    }
}

/// Where the ray through pixel `(x, y)` of `camera` first meets the
/// ellipsoid, if it does (the ellipsoid scaled to a sphere along its axis).
fn ellipsoid_hit(camera: &Camera, x: u32, y: u32) -> Option<Geodetic> {
    let squash = DVec3::new(1.0, 1.0, 1.0 / (1.0 - globe::E2).sqrt());
    let (o, d) = (camera.position_ecef * squash, camera.ray_dir(x, y) * squash);
    let (a, b, c) = (d.dot(d), o.dot(d), o.dot(o) - globe::A_M * globe::A_M);
    let disc = b * b - a * c;
    let t = (-b - disc.max(0.0).sqrt()) / a;
    (disc >= 0.0 && t > 0.0).then(|| Geodetic::from_ecef(camera.position_ecef + camera.ray_dir(x, y) * t))
}

/// The ground fills a view looking down: no crack on the GPU, nothing the
/// reference hits missed. Where flat frames leave cracks (the reference
/// shows them: it ray casts the same frames, and sees the sky or another
/// tile's overlap through them), the GPU shows the terrain mesh; those
/// pixels are counted, not compared, and beside them depths may differ by
/// up to 1 % (RMS 1e-3).
fn assert_whole_view(name: &str, tiles: &[TileData], camera: &Camera) -> usize {
    let cracks = PASSES.map(|pass| assert_whole_view_in(pass, &format!("{name}, {pass:?}"), tiles, camera));
    assert_eq!(cracks[0], cracks[1], "{name}: the same cracks filled in both passes");
    cracks[0]
}

fn assert_whole_view_in(pass: RayPass, name: &str, tiles: &[TileData], camera: &Camera) -> usize {
    let levels: std::collections::BTreeSet<u32> = tiles.iter().map(|t| t.id().level).collect();
    let sun = Some(sun_at(0.0, 60.0, 200.0, 30.0));
    let both = render_both_in(pass, tiles, camera, &settings(Traversal::Exact, sun));
    let holes = both.gpu.view_z_m.iter().filter(|&&z| z <= 0.0).count();
    let d = both.departure;
    eprintln!(
        "{name}: {} tiles on levels {levels:?}, {holes} pixels without ground, {} cracks filled; {d:?}",
        tiles.len(),
        d.extras
    );
    assert_eq!(holes, 0, "{name}: the ground fills the view, no crack");
    assert_eq!(d.misses, 0, "{name}: {d:?}");
    assert!(d.depth_rms_rel <= 1e-3 && d.depth_max_rel <= 0.02 && d.psnr_db >= MIN_PSNR_DB, "{name}: {d:?}");
    d.extras
}

#[test]
fn the_antimeridian_and_the_poles_have_no_seams() {
    let grid = small_grid();
    let down = |lon, lat, height| Camera::looking(Geodetic::new(lon, lat, height), 0.0, -90.0, 40.0, (128, 128));
    let antimeridian = down(180.0, 10.0, 60_000.0);
    // A region over every longitude, and one across 180° whose east is past
    // it (as a DEM of 179.5…180.5° E has): the tiles west of 180° hold it.
    let world = sylva::grid::BBox { west: -180.0, south: 0.0, east: 180.0, north: 20.0 };
    let across = sylva::grid::BBox { west: 179.5, south: 9.5, east: 180.5, north: 10.5 };
    for box_ in [world, across] {
        let tiles = selected(&grid, box_, &antimeridian);
        let west = tiles.iter().filter(|t| t.frame.sector.max_lon > 179.0).count();
        let east = tiles.iter().filter(|t| t.frame.sector.min_lon < -179.0).count();
        assert!(west > 0 && east > 0, "{box_:?}: tiles on both sides: {west} west, {east} east");
        assert_eq!(assert_whole_view("antimeridian", &tiles, &antimeridian), 0, "no crack to fill off the poles");
    }

    for (name, lat) in [("north pole", 90.0), ("south pole", -90.0)] {
        let camera = down(0.0, lat, 3_000_000.0);
        let (south, north) = if lat > 0.0 { (70.0, 90.0) } else { (-90.0, -70.0) };
        let cap = sylva::grid::BBox { west: -180.0, south, east: 180.0, north };
        let tiles = selected(&grid, cap, &camera);
        assert!(
            tiles.iter().any(|t| t.frame.sector.max_lat == 90.0 || t.frame.sector.min_lat == -90.0),
            "{name}: tiles meet at the pole"
        );
        // Without them this view shows the sky through cracks (the test fails).
        assert!(tiles.iter().any(needs_filler), "{name}: crack fillers under the tiles at the pole");
        assert_whole_view(name, &tiles, &camera);
    }
}

#[test]
fn oblique_views_near_a_pole_show_no_crack() {
    // Regression (review): the crack filler, drawn only within the flat
    // frame's error of its tile's edge, let rays that crossed a crack at a
    // slant meet nothing beyond: 58, 12 and 4 pixels of sky where these
    // views show ground.
    let grid = small_grid();
    let cap = sylva::grid::BBox { west: -180.0, south: 60.0, east: 180.0, north: 90.0 };
    for (lat, height_m, pitch) in [(80.0, 3_000_000.0, -60.0), (84.0, 1_000_000.0, -50.0), (87.0, 200_000.0, -30.0)] {
        let camera = Camera::looking(Geodetic::new(0.0, lat, height_m), 0.0, pitch, 40.0, (128, 128));
        let tiles = selected_at_most(&grid, cap, &camera, 250);
        assert!(tiles.iter().any(needs_filler), "{lat}°: crack fillers under the tiles");
        let refs: Vec<&TileData> = tiles.iter().collect();
        let settings = settings(Traversal::Exact, None);
        for pass in PASSES {
            let out =
                with_renderer_in(pass, 65, 8, |r| r.render(&camera, &refs, &settings, Readback::All).expect("fits"));
            let (w, h) = (camera.width_px, camera.height_px);
            let ground = |x, y| ellipsoid_hit(&camera, x, y).is_some_and(|g| g.lat_deg > cap.south + 1.0);
            let sky = (0..w * h).filter(|k| out.view_z_m[*k as usize] <= 0.0 && ground(k % w, k / w)).count();
            let shown = out.view_z_m.iter().filter(|&&z| z > 0.0).count();
            assert!(shown > 4000, "{lat}°, {pass:?}: the view shows ground ({shown} pixels)");
            assert_eq!(sky, 0, "{lat}°, {pass:?}: sky through cracks");
        }
    }
}

#[test]
fn lit_ground_near_a_pole_has_no_speckled_shadows() {
    // Regression (a user's trial): near a pole, where flat frames are
    // rectangles for wedges, a ray through the crack between two tiles'
    // frames enters a box through its side below the surface there (metres
    // below, 89.5° N). That hit is shaded as the surface above it, but its
    // shadow ray started at the hit, under the ground: isolated pixels of
    // full shadow in arcs along the tiles' edges, in the reference too.
    // Slopes here are under a tenth and the sun is 35° high: nothing casts
    // a shadow, so every pixel is as bright as without shadow rays.
    let grid = small_grid();
    let waves = |lon: f64, _lat: f64| (400.0 + 300.0 * (19.0 * lon.to_radians()).sin(), 0.0, 3);
    let camera = Camera::looking(Geodetic::new(120.0, 89.5, 5000.0), 200.0, -30.0, 40.0, (128, 96));
    let cap = sylva::grid::BBox { west: -180.0, south: 87.0, east: 180.0, north: 90.0 };
    let tiles = selected_of(&grid, cap, &camera, 120, 32, &waves);
    assert!(tiles.iter().any(needs_filler), "crack fillers under the tiles");
    let sun = Some(sun_at(120.0, 89.5, 150.0, 35.0));
    let lit = settings(Traversal::Exact, sun);
    let unshadowed = FrameSettings { shadow_steps: 0, ..lit };
    // Pixels both images show darker with shadow rays than without.
    let shadowed = |with: &[[u8; 4]], without: &[[u8; 4]], with_z: &[f32], without_z: &[f32]| {
        (0..with.len())
            .filter(|&k| with_z[k] > 0.0 && without_z[k] > 0.0 && luminance(without[k]) - luminance(with[k]) > 4.0)
            .count()
    };
    let cpu = reference::render(&camera, &tiles, &lighting_of(&lit));
    let cpu_plain = reference::render(&camera, &tiles, &lighting_of(&unshadowed));
    let shown = cpu.view_z_m.iter().filter(|&&z| z > 0.0).count();
    let dark = shadowed(&cpu.colour, &cpu_plain.colour, &cpu.view_z_m, &cpu_plain.view_z_m);
    eprintln!("reference: {} tiles, {shown} pixels of ground, {dark} shadowed", tiles.len());
    assert!(shown > 8000, "the view shows ground");
    let refs: Vec<&TileData> = tiles.iter().collect();
    let gpu = PASSES.map(|pass| {
        let render = |frame: &FrameSettings| {
            with_renderer_in(pass, 65, 32, |r| r.render(&camera, &refs, frame, Readback::All).expect("fits"))
        };
        let (gpu, gpu_plain) = (render(&lit), render(&unshadowed));
        let dark = shadowed(&gpu.colour, &gpu_plain.colour, &gpu.view_z_m, &gpu_plain.view_z_m);
        eprintln!("{pass:?}: {dark} pixels shadowed");
        dark
    });
    assert_eq!((dark, gpu), (0, [0, 0]), "pixels of shadow on lit ground: reference, then {PASSES:?}");
}

/// Luminance of a pixel, 0–255.
fn luminance(c: [u8; 4]) -> f64 {
    0.2126 * c[0] as f64 + 0.7152 * c[1] as f64 + 0.0722 * c[2] as f64
}

/// Image column and row of a world point seen by a camera looking down.
fn pixel_of(camera: &Camera, p: Geodetic) -> DVec2 {
    let v = camera.rotation.transpose() * (p.to_ecef() - camera.position_ecef);
    let half = DVec2::new(camera.width_px as f64, camera.height_px as f64) / 2.0;
    half + camera.focal_px() * DVec2::new(v.x, -v.y) / -v.z
}

#[test]
fn four_tiles_show_no_crack_and_shadows_cross_their_borders() {
    let grid = small_grid();
    let (lon0, lat0) = (7.3, 45.1);
    let first = grid.tile_containing(lon0, lat0, 13);
    let s = grid.sector(first);
    let border = s.max_lon;
    // A north–south ridge 100 m high, 30 m west of the border; the sun low
    // in the west casts its shadow east, over the border.
    let ridge = move |lon: f64, lat: f64| {
        let (x, _) = metres(lon, lat, border, lat0);
        (1000.0 + 100.0 * (-((x + 30.0) / 10.0).powi(2)).exp(), 0.0, 0)
    };
    let tiles = synthetic_block(&grid, lon0, lat0, 13, 32, &ridge);
    assert!(!tiles.iter().any(needs_filler), "fine tiles hold their footprint: no crack fillers");
    let eye = Geodetic::new(border, s.max_lat, 1700.0);
    let camera = Camera::looking(eye, 0.0, -90.0, 45.0, (160, 160));
    let sun = Some(sun_at(border, s.max_lat, 270.0, 15.0));
    for pass in PASSES {
        let both = render_both_in(pass, &tiles, &camera, &settings(Traversal::Exact, sun));
        assert_close(&format!("four tiles, {pass:?}"), &both.departure);
        assert!(both.gpu.view_z_m.iter().all(|&z| z > 0.0), "{pass:?}: no crack between the four tiles");
        assert_tiles_around(&grid, &tiles, &camera, &both.gpu.draws);
        assert_no_step_at(&camera, &both.gpu.colour, Geodetic::new(border, s.max_lat, 1000.0));
    }

    // Where the tiles meet, each computes the same light from its own texels
    // (the west tile's ridge is in the east tile's halo).
    let lighting = Lighting { sun_ecef: sun, shadow_steps: 10, fade: Fade::NONE };
    let (west, east) = (&tiles[0], &tiles[1]);
    let n1 = grid.samples() as i64 - 1;
    for j in [5, 30, 60] {
        let light = |t: &TileData, i: i64| {
            let view = reference::view_of(&camera, t, &lighting);
            let z = view.corner(i, j).expect("data");
            sylva::client::raycast::shadow(&view, glam::DVec2::new(i as f64, j as f64), z, view.sun.expect("sun"))
        };
        let (a, b) = (light(west, n1), light(east, 0));
        eprintln!("shared sample j = {j}: light {a:.4} in the west tile, {b:.4} in the east tile");
        assert!(a < 0.95, "the ridge shadows the border");
        assert!((a - b).abs() < 0.01, "both tiles light the shared sample alike");
    }
}

/// Each pixel names the tile whose rays it shows (by its place among the
/// draws): in each quadrant around the corner of the four tiles seen from
/// above it, the tile there.
fn assert_tiles_around(grid: &TileGrid, tiles: &[TileData], camera: &Camera, draws: &[u32]) {
    let s = grid.sector(tiles[0].id());
    let (border, d) = (s.max_lon, 0.2 * (s.max_lon - s.min_lon));
    for (dlon, dlat) in [(-d, -d), (d, -d), (-d, d), (d, d)] {
        let p = pixel_of(camera, Geodetic::new(border + dlon, s.max_lat + dlat, 1000.0)).floor();
        let k = draws[p.y as usize * camera.width_px as usize + p.x as usize] as usize;
        let shown = grid.sector(tiles[k.checked_sub(1).expect("a ray-cast pixel")].id());
        assert!(shown.min_lon < border + dlon && border + dlon < shown.max_lon, "{dlon}: {shown:?}");
        assert!(shown.min_lat < s.max_lat + dlat && s.max_lat + dlat < shown.max_lat, "{dlat}: {shown:?}");
    }
}

/// The image has no step in luminance at the column of `border` beyond
/// its neighbours' (rows 20, 80, 140 of a 160-pixel-wide image).
fn assert_no_step_at(camera: &Camera, colour: &[[u8; 4]], border: Geodetic) {
    let xb = pixel_of(camera, border).x.floor() as usize;
    for y in [20, 80, 140] {
        let l: Vec<f64> = (0..160).map(|x| luminance(colour[y * 160 + x])).collect();
        let step = |x: usize| (l[x + 1] - l[x]).abs();
        let at = step(xb - 1).max(step(xb));
        let around = [xb - 4, xb - 3, xb - 2, xb + 1, xb + 2, xb + 3].map(step).into_iter().fold(0.0, f64::max);
        eprintln!("row {y}: step {at:.1} at the border (column {xb}), up to {around:.1} beside it");
        assert!(at <= around + 2.0, "row {y}: the shadow steps at the border");
    }
}

/// `tiles` rendered in `pass` with every ray's work counted.
fn counted(pass: RayPass, tiles: &[TileData], camera: &Camera, settings: &FrameSettings) -> Rendered {
    let (samples, halo) = (tiles[0].frame.samples, tiles[0].halo as u32);
    let refs: Vec<&TileData> = tiles.iter().collect();
    with_renderer_in(pass, samples, halo, |r| {
        r.count_work(true);
        let out = r.render(camera, &refs, settings, Readback::All).expect("fits the cache");
        r.count_work(false);
        out
    })
}

#[test]
fn every_ray_cast_is_counted_by_its_draw_shown_or_not() {
    let (_, tiles, camera, sun) = demo_scene();
    let uncounted = render_both(&tiles, &camera, &settings(Traversal::Exact, sun)).gpu;
    assert!(uncounted.work.is_empty(), "counted only when asked");
    for pass in PASSES {
        let out = counted(pass, &tiles, &camera, &settings(Traversal::Exact, sun));
        assert_eq!(out.work.len(), tiles.len());
        let shown = |k: usize| out.draws.iter().filter(|&&d| d as usize == k + 1).count() as u64;
        for (k, w) in out.work.iter().enumerate() {
            assert!(w.rays >= shown(k) && w.leaf_cells <= w.view_fetches, "{pass:?}, draw {k}: {w:?}");
            assert!(shown(k) == 0 || w.view_fetches > 0 && w.leaf_cells > 0, "{pass:?}, draw {k}: {w:?}");
        }
        let total = out.work.iter().fold(DrawWork::default(), |a, w| a.plus(w));
        let pixels = (0..tiles.len()).map(shown).sum::<u64>();
        let [view, shadow] = [0, 1].map(|i| out.fetches.iter().map(|f| u64::from(f[i])).sum::<u64>());
        // A pixel's count adds the gathers that shade its hit (at most two)
        // to the fetches of the rays it shows (in a compute pass, of every
        // ray cast for it). Rays no pixel shows: hull fragments whose rays
        // left their tile or that a nearer tile covered; in a compute pass,
        // a pixel's rays through the boxes of tiles it does not show, and
        // the rays of pixels that show the sky.
        assert!(total.view_fetches + 2 * pixels >= view, "{pass:?}: {total:?} against {view} in {pixels} pixels");
        assert!(total.rays > pixels, "{pass:?}: {total:?} against {pixels} pixels");
        // Shadow rays leave from a pixel's hit, and in a compute pass from
        // its nearest hit only.
        assert!(total.shadow_fetches >= shadow && shadow > 0, "{pass:?}: {total:?} against {shadow}");
        assert!(pass == RayPass::Fragment || total.shadow_fetches == shadow, "{total:?} against {shadow}");
    }
    // Each draw's work is its own whatever the order the tiles come in (the
    // GPU draws them nearest first).
    let forward = counted(RayPass::Fragment, &tiles, &camera, &settings(Traversal::Exact, sun)).work;
    let reversed: Vec<TileData> = tiles.iter().rev().cloned().collect();
    let mut backward = counted(RayPass::Fragment, &reversed, &camera, &settings(Traversal::Exact, sun)).work;
    backward.reverse();
    assert_eq!(forward, backward);
    let linear = counted(RayPass::Fragment, &tiles, &camera, &settings(Traversal::Linear(30), sun)).work;
    assert!(linear.iter().all(|w| w.leaf_cells == 0) && linear.iter().any(|w| w.view_fetches > 0), "{linear:?}");
    let dark = counted(RayPass::Fragment, &tiles, &camera, &settings(Traversal::Exact, None)).work;
    assert!(dark.iter().all(|w| w.shadow_fetches == 0) && dark.iter().any(|w| w.rays > 0), "{dark:?}");
}

#[test]
fn no_sun_casts_no_shadow_rays_and_far_tiles_cast_no_rays() {
    let grid = small_grid();
    let (lon0, lat0) = (7.3, 45.1);
    let plain = move |lon: f64, lat: f64| {
        let (x, y) = metres(lon, lat, lon0, lat0);
        (1000.0 + 0.02 * x + 0.01 * y, 0.0, 0)
    };
    let tiles = synthetic_block(&grid, lon0, lat0, 13, 8, &plain);
    let s = grid.sector(grid.tile_containing(lon0, lat0, 13));
    let view = |height: f64| Camera::looking(Geodetic::new(s.max_lon, s.max_lat, height), 0.0, -90.0, 40.0, (96, 96));
    let near = view(1400.0);
    let with_sun = render_both(&tiles, &near, &settings(Traversal::Exact, Some(sun_at(lon0, lat0, 200.0, 30.0))));
    let no_sun = render_both(&tiles, &near, &settings(Traversal::Exact, None));
    let shadow_fetches = |r: &Rendered| r.fetches.iter().map(|f| f[1] as u64).sum::<u64>();
    assert!(shadow_fetches(&with_sun.gpu) > 0);
    assert_eq!(shadow_fetches(&no_sun.gpu), 0, "no sun, no shadow rays");

    // Far enough that a 30 m canopy would look 1.5 px tall, below the
    // fade's 2 px: no rays (the plane has no mesh error).
    let far = view(1000.0 + 30.0 * near.focal_px() / 1.5);
    let fade = Fade { focal_px: far.focal_px(), canopy_ref_m: 30.0, lo_px: 2.0, hi_px: 4.0, trees: TreeBlend::NONE };
    let faded = FrameSettings { fade, ..settings(Traversal::Exact, None) };
    let out = render_both(&tiles, &far, &faded);
    assert_eq!(out.gpu.stats.tiles_plain, 4, "{:?}", out.gpu.stats);
    assert!(out.gpu.fetches.iter().all(|f| f[0] == 0), "no view rays on far tiles");
    assert!(out.gpu.view_z_m.iter().filter(|&&z| z > 0.0).count() > 1000, "the tiles are drawn");
}

#[test]
fn trees_stand_in_front_of_the_ground_where_they_replace_the_canopy() {
    let (tiles, camera, lit) = forested_hills_from_low();
    let settings = FrameSettings { fade: tree_fade(&camera), ..lit };
    let splats = tree_splats(&tiles, &camera);
    let drawn: usize = splats.iter().map(Vec::len).sum();
    assert!(drawn > 1000, "{drawn} splats");
    for pass in PASSES {
        // Without splats the GPU's canopy, flattened under the trees, is the
        // reference's.
        let bare = render_both_in(pass, &tiles, &camera, &settings);
        assert_close(&format!("canopy blended out near the camera, {pass:?}"), &bare.departure);
        let whole = render_both_in(pass, &tiles, &camera, &FrameSettings { fade: Fade::NONE, ..settings });
        let lowered = bare.gpu.view_z_m.iter().zip(&whole.gpu.view_z_m).filter(|(b, w)| **b > **w * 1.001).count();
        assert!(lowered * 10 > bare.gpu.view_z_m.len(), "the canopy is lowered near the camera ({lowered} pixels)");

        let (wooded, _) = render_trees(pass, &tiles, &splats, &camera, &settings);
        assert_eq!(wooded.stats.splats as usize, drawn);
        let (mut nearer, mut hit) = (0, 0);
        for (with, without) in wooded.view_z_m.iter().zip(&bare.gpu.view_z_m) {
            if *without > 0.0 {
                hit += 1;
                assert!(
                    *with > 0.0 && *with <= without * (1.0 + 1e-5),
                    "a tree behind the ground: {with} vs {without}"
                );
                nearer += usize::from(*with < without * 0.999);
            }
        }
        eprintln!("trees, {pass:?}: {drawn} splats in front of {nearer} of {hit} pixels");
        assert!(nearer * 20 > hit, "trees cover more than 5 % of the view ({nearer} of {hit})");
    }
}

#[test]
fn undrawn_trees_leave_their_canopy_standing_on_the_gpu_as_in_the_reference() {
    let (tiles, camera, lit) = forested_hills_from_low();
    let every = tree_fade(&camera);
    // Every other tree drawn out to half the tree range, none beyond.
    let reach_m = every.trees.range_m + every.trees.band_m / 2.0;
    let trees = (0..200).map(|k| (reach_m * f64::from(k) / 200.0, k < 100 && k % 2 == 0));
    let sparse = Fade { trees: every.trees.with_drawn(trees), ..every };
    for pass in PASSES {
        let render = |fade: Fade| render_both_in(pass, &tiles, &camera, &FrameSettings { fade, ..lit });
        let out = render(sparse);
        assert_close(&format!("canopy of a sparse stand, {pass:?}"), &out.departure);
        let depth = |f: Fade| render(f).gpu.view_z_m;
        let (bare, whole) = (depth(every), depth(Fade::NONE));
        let (mut between, mut hit) = (0, 0);
        for ((z, b), w) in out.gpu.view_z_m.iter().zip(&bare).zip(&whole) {
            if *z > 0.0 && *b > 0.0 {
                hit += 1;
                assert!(*z <= b * 1.001 && *z >= w * 0.999, "the sparse canopy lies between none and all: {z} {b} {w}");
                between += usize::from(*z < b * 0.999 && *z > w * 1.001);
            }
        }
        eprintln!("sparse stand, {pass:?}: canopy partly lowered at {between} of {hit} pixels");
        assert!(between * 20 > hit, "the canopy is partly lowered ({between} of {hit} pixels)");
    }
}

/// Forested hills (tiles of level 13), a camera low over them, and the
/// exact traversal lit by an afternoon sun.
fn forested_hills_from_low() -> (Vec<TileData>, Camera, FrameSettings) {
    let grid = small_grid();
    let (lon0, lat0) = (7.3, 45.1);
    let tiles = synthetic_block(&grid, lon0, lat0, 13, 8, &hills(lon0, lat0));
    let s = grid.sector(tiles[0].id());
    let camera = Camera::looking(Geodetic::new(s.max_lon, s.max_lat, 1060.0), 45.0, -25.0, 60.0, (160, 120));
    (tiles, camera, settings(Traversal::Exact, Some(sun_at(lon0, lat0, 120.0, 30.0))))
}

/// The canopy fade of the default trees seen by `camera`.
fn tree_fade(camera: &Camera) -> Fade {
    Fade { trees: TreeSettings::default().blend(camera.focal_px()), ..Fade::NONE }
}

/// The default trees' splats on `tiles` seen by `camera`, a list per tile.
fn tree_splats(tiles: &[TileData], camera: &Camera) -> Vec<Vec<Splat>> {
    let settings = TreeSettings::default();
    let blend = settings.blend(camera.focal_px());
    let refs: Vec<&TileData> = tiles.iter().collect();
    let groups = trees::groups_near(&settings, &refs, camera, &blend);
    let mut splats = vec![Vec::new(); tiles.len()];
    trees::splats(&settings, &groups, None, (&blend, camera.focal_px()), &mut splats);
    splats
}

/// `tiles` with their `splats` on the GPU, rays cast in `pass`, 10 shadow
/// steps each, and the light each splat received.
fn render_trees(
    pass: RayPass,
    tiles: &[TileData],
    splats: &[Vec<Splat>],
    camera: &Camera,
    settings: &FrameSettings,
) -> (Rendered, Vec<f32>) {
    let draws: Vec<Draw> = tiles
        .iter()
        .zip(splats)
        .map(|(tile, s)| Draw { tile, shadow_steps: 10, splats: s, morph_weight: 1.0 })
        .collect();
    let (samples, halo) = (tiles[0].frame.samples, tiles[0].halo as u32);
    with_renderer_in(pass, samples, halo, |r| {
        let rendered = r.render_draws(camera, &draws, settings, Readback::All).expect("fits");
        (rendered, r.splat_lights())
    })
}

#[test]
fn each_splat_is_lit_once_by_the_ray_casters_shadow_rule() {
    let grid = small_grid();
    let (lon0, lat0) = (7.3, 45.1);
    // A forest on flat ground west of a 150 m wall, the sun low in the east.
    let wall = |lon: f64, lat: f64| {
        let east = metres(lon, lat, lon0, lat0).0 > 0.0;
        if east { (1150.0, 0.0, 0) } else { (1000.0, 20.0, SurfaceType::Forest as u8) }
    };
    let first = grid.tile_containing(lon0, lat0, 13);
    let tiles: Vec<TileData> =
        [first, TileId::new(13, first.row, first.col - 1)].iter().map(|&id| synthetic(&grid, id, 8, &wall)).collect();
    let camera = Camera::looking(Geodetic::new(lon0 - 0.0015, lat0 + 0.0005, 1070.0), 90.0, -30.0, 60.0, (160, 120));
    let settings =
        FrameSettings { fade: tree_fade(&camera), ..settings(Traversal::Exact, Some(sun_at(lon0, lat0, 90.0, 10.0))) };
    let splats = tree_splats(&tiles, &camera);
    let (_, gpu) = render_trees(RayPass::Fragment, &tiles, &splats, &camera, &settings);
    let lighting = lighting_of(&settings);
    let sun = lighting.sun_ecef.expect("sun");
    let cpu: Vec<f64> = tiles
        .iter()
        .zip(&splats)
        .flat_map(|(tile, s)| {
            let view = reference::view_of(&camera, tile, &lighting);
            let sun = tile.frame.basis.transpose() * sun;
            s.iter().map(move |p| {
                let at = tile.frame.sample_of(DVec2::new(f64::from(p.centre[0]), f64::from(p.centre[1])));
                raycast::shadow(&view, at, f64::from(p.centre[2]), sun)
            })
        })
        .collect();
    assert_eq!(gpu.len(), cpu.len());
    let worst = gpu.iter().zip(&cpu).map(|(g, c)| (f64::from(*g) - c).abs()).fold(0.0, f64::max);
    let shaded = cpu.iter().filter(|&&l| l < 0.99).count();
    eprintln!("splat lights: {shaded} of {} shaded, worst difference {worst:.2e}", cpu.len());
    assert!(worst < 1e-3, "a splat's light departs from the reference's by {worst}");
    assert!(shaded * 20 > cpu.len() && shaded < cpu.len(), "{shaded} of {} splats shaded", cpu.len());
}

/// Casts into one place of draw 0: each invocation a ray of 2³⁰ fetches
/// and 3 leaf cells, and a shadow ray of 15 · 2²⁸.
const WIDE_COUNTS: &str = "
@compute @workgroup_size(64)
fn count_many(@builtin(global_invocation_id) id: vec3<u32>) {
    count_cast(0u, vec2<u32>(8u, 4u), 0x40000000u, 3u);
    count_shadow(0u, vec2<u32>(0u, 0u), 0xf0000000u);
}
";

#[test]
fn work_counters_carry_past_a_word() {
    // Regression: a place's counters were one word, which a 4K frame's
    // draw can overflow (260,000 pixels of thousands of fetches).
    let gpu = Gpu::open().expect("a GPU adapter");
    let device = &gpu.device;
    let counters = sylva::client::render::work::WorkCounters::new(device, 1);
    let source = format!("{}\n{WIDE_COUNTS}", sylva::client::render::shaders::WORK_PARTS[0].1);
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("wide counts"),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("wide counts"),
        layout: None,
        module: &module,
        entry_point: Some("count_many"),
        compilation_options: Default::default(),
        cache: None,
    });
    let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("wide counts"),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[wgpu::BindGroupEntry { binding: 6, resource: counters.binding() }],
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    counters.clear(&mut encoder);
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind, &[]);
        pass.dispatch_workgroups(4, 1, 1);
    }
    gpu.queue.submit([encoder.finish()]);
    let work = counters.read(device, &gpu.queue, 1);
    let casts = 256u64;
    let expected =
        DrawWork { rays: casts, view_fetches: casts << 30, leaf_cells: 3 * casts, shadow_fetches: casts * 0xf000_0000 };
    assert_eq!(work, [expected]);
}
