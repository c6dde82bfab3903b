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
pub fn clouds() -> Vec<(&'static str, Vec<std::path::PathBuf>, f64)> {
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
        let inner = stats::sorted(set.tiles().iter().flat_map(steps));
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

#[test]
fn a_proxy_written_by_sylva_canopy_is_read_by_a_config_and_described_by_info() {
    let dir = TempDir::new("canopy-cli");
    let run = |args: &[&str]| {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_sylva")).args(args).output().expect("run sylva");
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let (proxy, chm) = (dir.join("conifer.tif"), dir.join("chm.tif"));
    let laz = data("lidar_lidR/MixedConifer.laz");
    let report =
        run(&["canopy", "--las", laz.to_str().unwrap(), "-o", proxy.to_str().unwrap(), "--chm", chm.to_str().unwrap()]);
    assert!(report.contains("EPSG:26912") && report.contains("Wang tiles"), "{report}");
    // A region whose forest is all of type "conifer", with that proxy (relative to the config).
    let config = dir.join("region.toml");
    let text = format!(
        "[dem]\npath = {dtm:?}\n[landcover]\nkind = \"canopy_height\"\npath = {chm:?}\nforest = \"conifer\"\n[[forest]]\nname = \"conifer\"\nproxy = \"conifer.tif\"\n",
        dtm = data("nz_pycrown/DTM.tif"),
        chm = data("nz_pycrown/CHM.tif"),
    );
    std::fs::write(&config, text).expect("config");
    let info = run(&["info", "--config", config.to_str().unwrap()]);
    let line = info.lines().find(|l| l.starts_with("forest")).unwrap_or_default();
    assert!(line.contains("conifer") && line.contains("at 0.50 m") && line.contains("heights mean"), "{info}");
    // The same proxy read back holds the same tiles as a fresh build.
    let (_, set) = lidar::build(&Options::new(vec![laz.clone()], 0.5)).expect("build");
    let read = sylva::source::proxy::open(&proxy).expect("proxy file");
    assert_eq!(read.tiles(), set.tiles());
    std::fs::remove_file(&proxy).expect("remove");
    let err = sylva::config::load(Some(&config)).expect_err("missing proxy").to_string();
    assert!(err.contains("conifer.tif") && err.contains("cannot open"), "{err}");
    // Mistakes on the command line are named, and write nothing.
    let las = laz.to_str().unwrap();
    for (args, said) in [
        (vec!["--las", las, "--las", las], "given twice to --las"),
        (vec!["--las", las, "--resolution", "-1"], "not a positive number of metres"),
    ] {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_sylva"))
            .arg("canopy")
            .args(&args)
            .args(["-o", proxy.to_str().unwrap()])
            .output()
            .expect("run sylva");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && err.contains(said) && !proxy.exists(), "{args:?}: {err}");
    }
}

/// Correlation of two equally long series.
fn correlation(a: &[f32], b: &[f32]) -> f64 {
    let n = a.len() as f64;
    let mean = |v: &[f32]| v.iter().map(|&x| f64::from(x)).sum::<f64>() / n;
    let (ma, mb) = (mean(a), mean(b));
    let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
    for (&x, &y) in a.iter().zip(b) {
        let (dx, dy) = (f64::from(x) - ma, f64::from(y) - mb);
        (ab, aa, bb) = (ab + dx * dy, aa + dx * dx, bb + dy * dy);
    }
    ab / (aa * bb).sqrt()
}

#[test]
fn wang_tiles_do_not_repeat_over_kilometres_where_one_periodic_tile_does() {
    let files = vec![data("nz_pycrown/POINTS.laz")];
    let heights = |colours: usize, variants: usize| {
        let options = Options { colours, variants, ..Options::new(files.clone(), 0.5) };
        let (_, set) = lidar::build(&options).expect("proxy");
        let tile_m = set.layout().tile_m();
        let proxy = TiledProxy::new("nz", set, 1);
        // 4 km east along 46.2° N, every 0.5 m, and the same shifted by one tile.
        let metres_per_deg = sylva::geo::METRES_PER_DEGREE * 46.2f64.to_radians().cos();
        let along = |shift_m: f64| -> Vec<f32> {
            (0..8000).map(|i| proxy.height(10.1 + (i as f64 * 0.5 + shift_m) / metres_per_deg, 46.2, 0.25)).collect()
        };
        correlation(&along(0.0), &along(tile_m))
    };
    let (periodic, wang) = (heights(1, 1), heights(2, 2));
    println!(
        "correlation of the canopy with itself one tile east, over 4 km: periodic tile {periodic:.3}, Wang tiles {wang:.3}"
    );
    assert!(periodic > 0.99, "{periodic}");
    assert!(wang < 0.3, "{wang}");
}

/// A tile of `level` around a pixel of Mt Hood's fuel models inside a
/// 7 × 7 block of TL9 (broadleaf litter).
fn broadleaf_tile(region: &sylva::region::Region, level: u32) -> sylva::grid::TileId {
    let options =
        OpenOptions { classes: true, nodata: sylva::source::NodataPolicy::Propagate, ..OpenOptions::default() };
    let fuel =
        open_file(&data("mt_hood/lf_fbfm40_220_mt_hood_utm.tif"), &options, &BlockCache::new(1 << 26)).expect("fuel");
    let (w, h) = fuel.size();
    let px = fuel.base().read(Window::new(0, 0, w, h)).expect("pixels").remove(0);
    let pure = |c: usize, r: usize| (c - 3..=c + 3).all(|x| (r - 3..=r + 3).all(|y| px.get(x, y) == 189.0));
    let (c, r) =
        (3..h - 3).flat_map(|r| (3..w - 3).map(move |c| (c, r))).find(|&(c, r)| pure(c, r)).expect("TL9 block");
    let g = fuel.georef();
    let (lon, lat) = g.crs.to_lon_lat(g.x0 + c as f64 * g.dx, g.y0 + r as f64 * g.dy).expect("lon lat");
    region.tiles.tile_containing(lon, lat, level)
}

#[test]
fn each_forest_type_gets_its_own_proxy_and_tiles_stay_seamless() {
    use sylva::cem::{self, Layer};
    let region = crate::common::region("examples/mt_hood_forest_types.toml");
    assert_eq!(region.forests.len(), 2);
    let tile = broadleaf_tile(&region, 12);
    let grid = region.tiles.tile_samples(tile, 0);
    let p = cem::compute(&region, &grid, &[Layer::Cover, Layer::Canopy]).expect("tile");
    let (cover, canopy) = (p.cover.expect("cover"), p.canopy.expect("canopy"));
    let conifer = region.forests[0].proxy.heights(&grid, None);
    let broadleaf = region.forests[1].proxy.heights(&grid, None);
    let (mut as_conifer, mut as_broadleaf) = (0, 0);
    for i in 0..canopy.data().len() {
        let (c, h, a, b) = (cover.data()[i], canopy.data()[i], conifer.data()[i], broadleaf.data()[i]);
        // A mix of the two where the types meet: between cover × one and cover × the other.
        assert!(
            h >= c * a.min(b) - 1e-3 && h <= c * a.max(b) + 1e-3,
            "sample {i}: {h} from cover {c}, proxies {a} {b}"
        );
        if (a - b).abs() > 1.0 && c > 0.5 {
            as_conifer += usize::from((h - c * a).abs() < 1e-3);
            as_broadleaf += usize::from((h - c * b).abs() < 1e-3);
        }
    }
    println!("mt_hood tile {tile}: {as_conifer} samples of the conifer proxy, {as_broadleaf} of the broadleaf one");
    assert!(as_conifer > 1000 && as_broadleaf > 1000, "{as_conifer} {as_broadleaf}");
    crate::seamless::check_tile(&region, tile, 7);
}
