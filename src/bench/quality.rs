//! Error against run time for the pipeline's accuracy knobs, on real data:
//! - **resampling**: a DEM is decimated 4× and resampled back onto its own
//!   pixels with nearest, bilinear and bicubic kernels; the error is measured
//!   on the pixels the decimation dropped (the reference is 4× supersampled);
//! - **quantization**: the 16-bit encodings of a CEM tile against its f32
//!   heights, with the encoding time;
//! - **morphology**: close sequences on the rmnp Landsat image, scored by
//!   precision and recall against the forest labels made by eye.

use super::{median_ms, table};
use crate::cem::{self, Layer};
use crate::encode::{self, Format, Samples};
use crate::grid::{Axis, SampleGrid};
use crate::raster::resample::Resampling;
use crate::raster::{Raster, Window};
use crate::region::Region;
use crate::source::memory::MemorySource;
use crate::source::{BlockCache, Blocks, GeoRaster, Georef, Reducer};
use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Resampling error of `region`'s DEM (which must be geographic) against the
/// pixels dropped by a 4× decimation: rows of kernel, ms, RMSE, max error.
pub fn resampling(region: &Region) -> Option<String> {
    let g = region.dem.georef().clone();
    if !g.crs.is_geographic() {
        return None;
    }
    let (w, h) = region.dem.size();
    let full = region.dem.base().read_band(Window::new(0, 0, w, h), 0).ok()?;
    let (cw, ch) = (w.div_ceil(4), h.div_ceil(4));
    let coarse = Raster::from_fn(cw, ch, |x, y| full.get(4 * x, 4 * y));
    let cache = BlockCache::new(1 << 28);
    let georef = Georef { dx: 4.0 * g.dx, dy: 4.0 * g.dy, ..g.clone() };
    let src = GeoRaster::new(
        Blocks::new(Arc::new(MemorySource::new("decimated", vec![coarse])?), &cache),
        georef,
        &[Reducer::Mean],
        &cache,
    );
    // The fine pixels inside the coarse lattice's hull.
    let (fw, fh) = (4 * (cw - 1) + 1, 4 * (ch - 1) + 1);
    let grid = SampleGrid { lon: Axis::degrees(g.x0, g.dx, 0, fw), lat: Axis::degrees(g.y0, g.dy, 0, fh) };
    let mut rows = Vec::new();
    for kind in [Resampling::Nearest, Resampling::Bilinear, Resampling::Bicubic] {
        let mut times = Vec::new();
        let mut out = None;
        for _ in 0..7 {
            let start = Instant::now();
            out = src.sample(&grid, 0, kind).ok();
            times.push(start.elapsed());
        }
        let out = out?;
        let (mut sum, mut worst, mut n) = (0.0f64, 0.0f64, 0usize);
        for y in 0..fh {
            for x in 0..fw {
                if x % 4 == 0 && y % 4 == 0 {
                    continue;
                }
                let e = (out.get(x, y) - full.get(x, y)) as f64;
                if e.is_finite() {
                    sum += e * e;
                    worst = worst.max(e.abs());
                    n += 1;
                }
            }
        }
        let per_m = median_ms(&mut times) / (fw * fh) as f64 * 1e6;
        rows.push(vec![
            format!("{kind:?}").to_lowercase(),
            format!("{per_m:.1}"),
            format!("{:.2}", (sum / n as f64).sqrt()),
            format!("{worst:.2}"),
        ]);
    }
    Some(format!(
        "{}: DEM decimated 4× ({w}×{h} → {cw}×{ch}) and resampled back; error on the {} dropped pixels\n{}\n",
        region.name,
        fw * fh - cw * ch,
        table(&["kernel", "ms per Msample", "RMSE m", "max m"], &rows)
    ))
}

/// 16-bit encodings of a warm CEM tile against f32.
pub fn quantization(region: &Region) -> String {
    let tile = super::pipeline::bench_tile(region);
    let grid = region.tiles.tile_samples(tile, 0);
    let cem = cem::compute(region, &grid, &[Layer::Cem])
        .ok()
        .and_then(|p| p.cem)
        .unwrap_or_else(|| Raster::filled(1, 1, f32::NAN));
    let mut rows = Vec::new();
    for format in [Format::Bil32, Format::Bil16, Format::Png16, Format::Tiff] {
        let mut times: Vec<Duration> = Vec::new();
        let mut bytes = Vec::new();
        for _ in 0..7 {
            let start = Instant::now();
            bytes = encode::encode(Layer::Cem, Samples::Float(&cem), &grid, format, region.heights_16)
                .map(|e| e.bytes)
                .unwrap_or_default();
            times.push(start.elapsed());
        }
        let decoded = decode(format, &bytes, region);
        let (rmse, worst) = errors(&cem, &decoded);
        rows.push(vec![
            format!("{format:?}").to_lowercase(),
            format!("{:.2}", median_ms(&mut times)),
            format!("{}", bytes.len()),
            format!("{rmse:.4}"),
            format!("{worst:.4}"),
        ]);
    }
    format!(
        "{}: tile {tile} cem, 513², encodings against f32\n{}\n",
        region.name,
        table(&["format", "encode ms", "bytes", "RMSE m", "max m"], &rows)
    )
}

fn decode(format: Format, bytes: &[u8], region: &Region) -> Vec<f32> {
    match format {
        Format::Bil32 => bytes.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect(),
        Format::Bil16 => bytes.chunks_exact(2).map(|b| i16::from_le_bytes([b[0], b[1]]) as f32).collect(),
        Format::Png16 => image::load_from_memory(bytes)
            .map(|i| {
                i.into_luma16()
                    .pixels()
                    .map(|p| (region.heights_16.offset + region.heights_16.scale * p.0[0] as f64) as f32)
                    .collect()
            })
            .unwrap_or_default(),
        // The GeoTIFF holds the f32 values themselves.
        Format::Tiff => Vec::new(),
    }
}

fn errors(truth: &Raster<f32>, decoded: &[f32]) -> (f64, f64) {
    if decoded.is_empty() {
        return (0.0, 0.0);
    }
    let (mut sum, mut worst, mut n) = (0.0f64, 0.0f64, 0usize);
    for (&t, &d) in truth.data().iter().zip(decoded) {
        if t.is_finite() {
            let e = (t - d) as f64;
            sum += e * e;
            worst = worst.max(e.abs());
            n += 1;
        }
    }
    ((sum / n.max(1) as f64).sqrt(), worst)
}

/// Close sequences on a map-based region (its configuration file) against
/// the labels in `labels_csv` (`lon,lat,forest` rows).
pub fn morphology(config_path: &Path, labels_csv: &Path) -> Option<String> {
    let config = crate::config::parse_file(config_path).ok()?;
    let base = crate::config::base_of(config_path);
    let text = std::fs::read_to_string(labels_csv).ok()?;
    let labels: Vec<(f64, f64, bool)> = text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("lon"))
        .filter_map(|l| {
            let v: Vec<f64> = l.split(',').filter_map(|x| x.parse().ok()).collect();
            (v.len() == 3).then(|| (v[0], v[1], v[2] == 1.0))
        })
        .collect();
    let mut rows = Vec::new();
    let mut name = String::new();
    for seq in ["", "DE", "DDEE", "DEDE", "DDDEEE"] {
        let mut variant = config.clone();
        variant.landcover.as_mut()?.close = Some(seq.to_string());
        let region = crate::config::region_from(&variant, base, config_path).ok()?;
        name.clone_from(&region.name);
        let lc = region.landcover.as_ref()?;
        let (w, h) = lc.size();
        let start = Instant::now();
        let cover = lc.base().read_band(Window::new(0, 0, w, h), 0).ok()?;
        let ms = start.elapsed().as_secs_f64() * 1e3;
        let g = lc.georef();
        let (mut tp, mut fp, mut fneg) = (0, 0, 0);
        for &(lon, lat, truth) in &labels {
            let (x, y) = (((lon - g.x0) / g.dx).round() as usize, ((lat - g.y0) / g.dy).round() as usize);
            let said = x < w && y < h && cover.get(x, y) >= 0.5;
            tp += usize::from(truth && said);
            fp += usize::from(!truth && said);
            fneg += usize::from(truth && !said);
        }
        let p = tp as f64 / (tp + fp).max(1) as f64;
        let r = tp as f64 / (tp + fneg).max(1) as f64;
        let label = if seq.is_empty() { "none".to_string() } else { seq.to_string() };
        rows.push(vec![
            label,
            format!("{ms:.1}"),
            format!("{p:.3}"),
            format!("{r:.3}"),
            format!("{:.3}", 2.0 * p * r / (p + r).max(1e-9)),
        ]);
    }
    Some(format!(
        "{name}: close sequences (3×3 passes) over the whole map, cover ≥ 0.5 scored against {} labelled pixels\n{}\n",
        labels.len(),
        table(&["close", "ms (whole map, cold)", "precision", "recall", "F1"], &rows)
    ))
}
