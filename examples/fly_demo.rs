//! The client as a library, without the server: ten frames of a camera path
//! over the embedded demo region, rendered headless into `frames/`.
//!
//! `cargo run --release --example fly_demo --no-default-features --features client`
//! from the repository root (the path file is read from `config/paths/`).

use std::sync::Arc;
use sylva::client::source::{RegionSource, TileSource};
use sylva::client::{fly, path::CameraPath};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let region = sylva::config::load(None)?; // the embedded demo; Some(path) for a TOML file
    let source = RegionSource::new(Arc::new(region)); // or client::http::HttpSource::connect(URL)
    let path = CameraPath::load("config/paths/demo_valley.toml".as_ref())?;
    // `overwrite`: a second run replaces the first one's frames.
    let options = fly::FlyOptions {
        frames: 10,
        size: (640, 480),
        out_dir: Some("frames".into()),
        overwrite: true,
        ..Default::default()
    };
    let records = fly::run(&source, &path, &options, 512 << 20)?;
    println!("{}", fly::summary(&records, options.lod.max_error_px, source.why_no_tile().as_deref()));
    Ok(())
}
