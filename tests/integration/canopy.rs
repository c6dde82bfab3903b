//! Canopy proxies from real LiDAR (`sylva canopy`): the CHM against a
//! published one, continuity across the seam of two clouds, tileability of
//! the Wang tile sets, and bad input.

use crate::common::{TempDir, data};
use sylva::canopy::chm::Chm;
use sylva::canopy::grid::MetricGrid;
use sylva::canopy::stats;
use sylva::canopy::{TileSet, TiledProxy};
use sylva::lidar::{self, Options};
use sylva::raster::{Raster, Window};
use sylva::source::{BlockCache, OpenOptions, open_file};

/// The published CHM's grid and heights.
fn published_chm() -> (MetricGrid, Raster<f32>) {
    let options = OpenOptions { nodata: sylva::source::NodataPolicy::Propagate, ..OpenOptions::default() };
    let chm = open_file(&data("nz_pycrown/CHM.tif"), &options, &BlockCache::new(1 << 24)).expect("CHM.tif");
    let (w, h) = chm.size();
    let g = chm.georef();
    let grid = MetricGrid { x0: g.x0 - 0.5 * g.dx, y0: g.y0 - 0.5 * g.dy, cell_m: g.dx, width: w, height: h };
    (grid, chm.base().read(Window::new(0, 0, w, h)).expect("pixels").remove(0))
}

#[test]
fn nz_chm_from_points_matches_the_published_chm() {
    let (grid, published) = published_chm();
    let options = Options { grid: Some(grid), ..Options::new(vec![data("nz_pycrown/POINTS.laz")], 1.0) };
    let model = lidar::model(&options).expect("model");
    let (mut sum, mut sum2, mut n) = (0.0f64, 0.0f64, 0usize);
    for (&ours, &theirs) in model.chm.heights.data().iter().zip(published.data()) {
        assert!(!ours.is_nan(), "the scan covers the whole grid");
        let d = f64::from(ours - theirs);
        (sum, sum2, n) = (sum + d, sum2 + d * d, n + 1);
    }
    let (bias, rmse) = (sum / n as f64, (sum2 / n as f64).sqrt());
    println!("nz_pycrown CHM from POINTS.laz vs CHM.tif, {n} cells of 1 m: RMSE {rmse:.3} m, bias {bias:+.3} m");
    assert!(model.chm.normalised);
    assert!(rmse <= 1.5 && bias.abs() <= 0.5, "RMSE {rmse}, bias {bias}");
}

/// The mean absolute difference between the rows on either side of the
/// line `y`, and between other neighbouring rows within 40 m of it, over
/// the columns with data in all those rows.
fn step_across(r: &Raster<f32>, grid: &MetricGrid, y: f64) -> (f64, f64) {
    let seam = ((grid.y0 - y) / grid.cell_m).round() as usize;
    let band = (40.0 / grid.cell_m) as usize;
    let rows = seam - band..seam + band;
    let cols: Vec<usize> = (0..r.width()).filter(|&c| rows.clone().all(|row| !r.get(c, row).is_nan())).collect();
    assert!(cols.len() * 4 > r.width() * 3, "{} of {} columns with data around the seam", cols.len(), r.width());
    let mean_step = |row: usize| {
        cols.iter().map(|&c| f64::from((r.get(c, row) - r.get(c, row - 1)).abs())).sum::<f64>() / cols.len() as f64
    };
    let others: Vec<f64> = rows.skip(1).filter(|&row| row != seam).map(mean_step).collect();
    (mean_step(seam), others.iter().sum::<f64>() / others.len() as f64)
}

#[test]
fn bcts_ground_and_chm_are_continuous_across_the_seam_of_the_two_files() {
    let files = vec![data("lidar_bcts/bcts_1.laz"), data("lidar_bcts/bcts_2.laz")];
    let model = lidar::model(&Options::new(files, 0.5)).expect("model");
    let chm: &Chm = &model.chm;
    assert!(!chm.normalised, "bcts heights are elevations");
    let ground = chm.ground.as_ref().expect("a ground model");
    // The files meet at y = 629400 (SOURCES.md).
    for (what, r, factor) in [("ground", ground, 1.5), ("chm", &chm.heights, 1.5)] {
        let (seam, elsewhere) = step_across(r, &chm.grid, 629_400.0);
        println!("bcts {what}: mean step across the seam {seam:.3} m, between other rows {elsewhere:.3} m");
        assert!(seam <= factor * elsewhere, "{what}: {seam} vs {elsewhere}");
    }
}

/// The clouds of `../shared/data` and the resolutions their densities
/// allow (Topography has 0.9 points per m²).
fn clouds() -> Vec<(&'static str, Vec<std::path::PathBuf>, f64)> {
    vec![
        ("nz_pycrown", vec![data("nz_pycrown/POINTS.laz")], 0.5),
        ("MixedConifer", vec![data("lidar_lidR/MixedConifer.laz")], 0.5),
        ("bcts", vec![data("lidar_bcts/bcts_1.laz"), data("lidar_bcts/bcts_2.laz")], 0.5),
        ("Topography", vec![data("lidar_lidR/Topography.laz")], 1.0),
    ]
}

/// Absolute differences between horizontal and vertical neighbours.
fn steps(r: &Raster<f32>) -> impl Iterator<Item = f32> + '_ {
    let (w, h) = (r.width(), r.height());
    let across = (0..h).flat_map(move |y| (1..w).map(move |x| (r.get(x, y) - r.get(x - 1, y)).abs()));
    across.chain((1..h).flat_map(move |y| (0..w).map(move |x| (r.get(x, y) - r.get(x, y - 1)).abs())))
}

/// The largest step where `a` meets `b` placed to its south, and to its east.
fn seams(a: &Raster<f32>, b: &Raster<f32>) -> (f32, f32) {
    let t = a.width();
    let south = (0..t).map(|x| (a.get(x, t - 1) - b.get(x, 0)).abs()).fold(0.0, f32::max);
    let east = (0..t).map(|y| (a.get(t - 1, y) - b.get(0, y)).abs()).fold(0.0, f32::max);
    (south, east)
}

/// The largest step along any edge two tiles may share, and along the
/// wrapped edges of the periodic tiles (north = south and east = west).
fn edge_steps(set: &TileSet) -> (f32, f32) {
    let l = *set.layout();
    let (mut shared, mut wrapped) = (0.0f32, 0.0f32);
    for (i, a) in set.tiles().iter().enumerate() {
        let ea = l.edges(i);
        if ea.n == ea.s && ea.e == ea.w {
            let (s, e) = seams(a, a);
            wrapped = wrapped.max(s).max(e);
        }
        for (j, b) in set.tiles().iter().enumerate() {
            let eb = l.edges(j);
            let (s, e) = seams(a, b);
            shared = shared.max(if ea.s == eb.n { s } else { 0.0 }).max(if ea.e == eb.w { e } else { 0.0 });
        }
    }
    (shared, wrapped)
}

#[test]
fn proxies_wrap_match_along_edges_and_keep_the_chm_histogram() {
    for (name, files, cell_m) in clouds() {
        let (model, set) = lidar::build(&Options::new(files, cell_m)).expect("proxy");
        let inner = stats::sorted(set.tiles().iter().flat_map(|t| steps(t)));
        let p99 = stats::sorted_quantile(&inner, 0.99);
        let (shared, wrapped) = edge_steps(&set);
        println!(
            "{name}: largest step along shared edges {shared:.2} m, wrapped edges {wrapped:.2} m; p99 of steps inside {p99:.2} m"
        );
        assert!(shared <= p99 && wrapped <= p99, "{name}: {shared} / {wrapped} vs {p99}");
        let source = stats::sorted(model.chm.heights.data().iter().copied());
        let proxy = stats::sorted(set.tiles().iter().flat_map(|t| t.data().iter().copied()));
        let mut worst = 0.0f32;
        for k in 1..20 {
            let q = k as f64 / 20.0;
            let (a, b) = (stats::sorted_quantile(&source, q), stats::sorted_quantile(&proxy, q));
            // 5 %, or 15 cm (a LiDAR return's vertical precision) near the ground.
            assert!((a - b).abs() <= (0.05 * a).max(0.15), "{name}: quantile {q}: CHM {a} m, proxy {b} m");
            worst = worst.max((a - b).abs() / a.max(0.15 / 0.05));
        }
        println!("{name}: quantiles 5 %..95 % of the proxy within {:.1} % of the CHM's", 100.0 * worst);
    }
}

/// A LAS file of `points` (x, y, z) at `path`, with a GeoKey VLR for
/// `epsg` when given.
fn write_las(path: &std::path::Path, epsg: Option<u16>, points: &[(f64, f64, f64)]) {
    let mut builder = las::Builder::from((1, 2));
    if let Some(code) = epsg {
        let keys: [u16; 8] = [1, 1, 0, 1, 3072, 0, 1, code];
        let data = keys.iter().flat_map(|k| k.to_le_bytes()).collect();
        builder.vlrs.push(las::Vlr {
            user_id: "LASF_Projection".into(),
            record_id: 34735,
            description: String::new(),
            data,
        });
    }
    let mut writer = las::Writer::from_path(path, builder.into_header().expect("header")).expect("writer");
    for &(x, y, z) in points {
        writer.write_point(las::Point { x, y, z, ..Default::default() }).expect("point");
    }
    writer.close().expect("close");
}

#[test]
fn bad_clouds_give_errors_that_name_the_file_and_the_problem() {
    let dir = TempDir::new("bad-las");
    let bytes = std::fs::read(data("nz_pycrown/POINTS.laz")).expect("laz");
    let truncated = dir.join("truncated.laz");
    std::fs::write(&truncated, &bytes[..bytes.len() * 3 / 5]).expect("write");
    let empty = dir.join("empty.las");
    write_las(&empty, Some(2193), &[]);
    // A 10 × 10 m stand: ground and crowns 10 m up, every half metre.
    let stand: Vec<(f64, f64, f64)> =
        (0..400).map(|i| (f64::from(i % 20) * 0.5, f64::from(i / 20) * 0.5, f64::from(i % 2) * 10.0)).collect();
    let no_crs = dir.join("no_crs.las");
    write_las(&no_crs, None, &stand);
    let short = dir.join("short.las");
    write_las(&short, Some(2193), &stand);
    let len = std::fs::metadata(&short).expect("las").len();
    std::fs::OpenOptions::new().write(true).open(&short).and_then(|f| f.set_len(len - 100)).expect("truncate");
    let geographic = dir.join("geographic.las");
    write_las(&geographic, Some(4326), &[(170.0, -40.0, 3.0)]);
    let not_las = dir.join("not_las.laz");
    std::fs::write(&not_las, b"this is not a point cloud").expect("write");
    for (path, problem) in [
        (&truncated, "truncated"),
        (&short, "truncated or corrupt point data after 0 of 400 points"),
        (&empty, "empty (0 points)"),
        (&no_crs, "no CRS"),
        (&geographic, "is geographic"),
        (&not_las, "not a readable LAS/LAZ file"),
        (&dir.join("missing.laz"), "cannot open"),
    ] {
        let err = lidar::model(&Options::new(vec![path.clone()], 0.5)).expect_err(problem).to_string();
        println!("{err}");
        assert!(err.contains(path.to_str().unwrap()) && err.contains(problem), "{err}");
    }
    // A CRS given by hand makes the cloud without one usable.
    let options = Options { crs: Some(2193), ..Options::new(vec![no_crs], 0.5) };
    assert!(lidar::model(&options).is_ok());
}
