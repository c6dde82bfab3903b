//! The GPU ray caster against the exact CPU reference, on real tiles.

use crate::common;
use glam::DVec3;
use std::sync::Arc;
use sylva::client::camera::Camera;
use sylva::client::globe::Geodetic;
use sylva::client::raycast::{Fade, Traversal};
use sylva::client::reference::{self, Lighting};
use sylva::client::render::gpu::Gpu;
use sylva::client::render::uniforms::FrameSettings;
use sylva::client::render::{Readback, Renderer};
use sylva::client::source::{RegionSource, TileSource};
use sylva::client::tile::TileData;
use sylva::grid::TileId;

fn block(source: &RegionSource, centre: TileId, halo: usize) -> Vec<TileData> {
    let grid = source.grid();
    let mut out = Vec::new();
    for dr in 0..2 {
        for dc in 0..2 {
            let id = TileId::new(centre.level, centre.row + dr, centre.col + dc);
            if let Some(p) = source.fetch(id, halo).unwrap() {
                out.push(TileData::prepare(&grid, p).unwrap());
            }
        }
    }
    out
}

#[test]
fn scratch_demo_view() {
    let region = Arc::new(common::demo());
    let source = RegionSource::new(region.clone());
    let grid = source.grid();
    let id = grid.tile_containing(10.12, 46.37, 11);
    let tiles = block(&source, id, 32);
    let sector = grid.sector(id);
    let eye = Geodetic::new(sector.max_lon, sector.max_lat - 0.004, 2600.0);
    let camera = Camera::looking(eye, 0.0, -25.0, 60.0, (160, 120));
    let sun = sylva::client::globe::enu_basis(eye.lon_deg, eye.lat_deg) * DVec3::new(-0.5, 0.5, 0.7).normalize();
    let settings = FrameSettings { traversal: Traversal::Exact, shadow_steps: 10, sun_ecef: Some(sun), fade: Fade::NONE };
    let gpu = Gpu::open().unwrap();
    eprintln!("{}", gpu.describe());
    let mut renderer = Renderer::new(gpu, grid.samples(), 32, 64 << 20);
    let refs: Vec<&TileData> = tiles.iter().collect();
    let out = renderer.render(&camera, &refs, &settings, Readback::All).unwrap();
    let lighting = Lighting { sun_ecef: Some(sun), shadow_steps: 10, fade: Fade::NONE };
    let cpu = reference::render(&camera, &tiles, &lighting);
    let dir = std::path::Path::new("/tmp/sylva-scratch");
    std::fs::create_dir_all(dir).unwrap();
    let save = |name: &str, px: &[[u8; 4]]| {
        let bytes: Vec<u8> = px.iter().flatten().copied().collect();
        std::fs::write(dir.join(name), sylva::encode::png(&bytes, 160, 120, image::ExtendedColorType::Rgba8).unwrap()).unwrap();
    };
    save("gpu.png", &out.colour);
    save("cpu.png", &cpu.colour);
    let hits_gpu = out.view_z_m.iter().filter(|&&z| z > 0.0).count();
    let hits_cpu = cpu.view_z_m.iter().filter(|&&z| z > 0.0).count();
    eprintln!("hits gpu {hits_gpu} cpu {hits_cpu} stats {:?}", out.stats);
}
