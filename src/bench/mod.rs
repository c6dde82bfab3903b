//! `sylva bench …`: benchmarks that print tables (speed targets live here,
//! never in tests). Numbers from one run are comparable with each other;
//! compare across runs only as ratios.

pub mod lod;
pub mod lod_frames;
mod lod_plot;
pub mod lod_scene;
pub mod lod_sse;
pub mod pipeline;
pub mod plot;
pub mod quality;
#[cfg(feature = "client")]
pub mod raycast;
#[cfg(feature = "server")]
pub mod seed;
#[cfg(feature = "server")]
pub mod serve;

use std::time::Duration;

/// Resident and peak resident memory of this process, MiB.
pub fn rss_mib() -> (f64, f64) {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let field = |name: &str| {
        status
            .lines()
            .find(|l| l.starts_with(name))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|v| v.parse::<f64>().ok())
            .map_or(f64::NAN, |kib| kib / 1024.0)
    };
    (field("VmRSS:"), field("VmHWM:"))
}

/// Median of durations, in milliseconds.
pub fn median_ms(samples: &mut [Duration]) -> f64 {
    if samples.is_empty() {
        return f64::NAN;
    }
    samples.sort();
    samples[samples.len() / 2].as_secs_f64() * 1e3
}

/// A plain-text table with a header row, columns padded to their widest cell.
pub fn table(header: &[&str], rows: &[Vec<String>]) -> String {
    let widths: Vec<usize> = (0..header.len())
        .map(|i| {
            rows.iter()
                .map(|r| r.get(i).map_or(0, |c| c.chars().count()))
                .max()
                .unwrap_or(0)
                .max(header[i].chars().count())
        })
        .collect();
    let line = |cells: Vec<String>| {
        let padded: Vec<String> = cells.iter().zip(&widths).map(|(c, w)| format!("{c:>w$}")).collect();
        format!("| {} |", padded.join(" | "))
    };
    let mut out = vec![line(header.iter().map(|s| s.to_string()).collect())];
    out.push(format!("|{}|", widths.iter().map(|w| format!("{}:", "-".repeat(w + 1))).collect::<Vec<_>>().join("|")));
    out.extend(rows.iter().map(|r| line(r.clone())));
    out.join("\n")
}

/// The frame-time table of `flights` and their plots
/// (`lod_frames_<directory name>.png`).
fn flight_report(flights: &[std::path::PathBuf], plot_dir: Option<&std::path::Path>) -> String {
    if flights.is_empty() {
        return "(no flights under a budget given: --flights)\n".into();
    }
    let read = |dir: &std::path::PathBuf| -> Result<(String, String), String> {
        let name = dir.file_name().map_or("flight".into(), |n| n.to_string_lossy().into_owned());
        let csv = std::fs::read_to_string(dir.join("stats.csv")).map_err(|e| format!("{}: {e}", dir.display()))?;
        Ok((name, csv))
    };
    let report = flights.iter().map(read).collect::<Result<Vec<_>, _>>().and_then(|f| lod_frames::report(&f));
    let (table, plots) = match report {
        Ok(r) => r,
        Err(e) => return format!("(flights: {e})\n"),
    };
    let mut out = format!("### Frame time against the budget\n\n{table}\n");
    let Some(dir) = plot_dir else { return out };
    for (name, png) in &plots {
        let path = dir.join(format!("lod_frames_{name}.png"));
        out += &match std::fs::write(&path, png) {
            Ok(()) => format!("plot: {}\n", path.display()),
            Err(e) => format!("(no plot: {e})\n"),
        };
    }
    out
}

/// `sylva bench pipeline`: the tables for the demo and, when its data is
/// there, the region of `rmnp_config`; `labels` scores the close sequences.
pub fn pipeline_report(
    rmnp_config: &std::path::Path,
    labels: &std::path::Path,
    build_side: usize,
) -> Result<String, crate::config::ConfigError> {
    let mut out = Vec::new();
    let demo = crate::config::load(None)?;
    let mut regions = vec![(demo, None, "demo".to_string())];
    match crate::config::load(Some(rmnp_config)) {
        Ok(rmnp) => {
            let key = rmnp_config.file_stem().map_or("real".into(), |s| s.to_string_lossy().into_owned());
            regions.push((rmnp, Some(rmnp_config), key));
        }
        Err(e) => out.push(format!("(skipping the real-data region: {e})\n")),
    }
    for (region, path, key) in &regions {
        let reload = || crate::config::load(*path).unwrap_or_else(|_| region.clone());
        let result = pipeline::run(region, &reload, build_side);
        out.push(pipeline::report(&result, key, build_side));
        out.extend(quality::resampling(region));
        out.push(quality::quantization(region));
    }
    out.extend(quality::morphology(rmnp_config, labels));
    Ok(out.join("\n"))
}

/// `sylva bench lod`: the flyover tables for the demo region (trees
/// `spacing_m` apart at full cover) and, when its data is there, for the
/// region of `rmnp_config`; plots go to `plot_dir` when given. `flights`
/// (directories of `sylva fly --lod budget`) add their frame times against
/// the budget.
pub fn lod_report(
    rmnp_config: &std::path::Path,
    frames: usize,
    plot_dir: Option<&std::path::Path>,
    flights: &[std::path::PathBuf],
) -> Result<String, crate::config::ConfigError> {
    let mut scenes = vec![("demo", crate::config::load(None)?, 7.0)];
    let mut out = vec![flight_report(flights, plot_dir)];
    match crate::config::load(Some(rmnp_config)) {
        Ok(rmnp) => scenes.push(("rmnp", rmnp, 12.0)),
        Err(e) => out.push(format!("(skipping the real-data region: {e})\n")),
    }
    for (key, region, spacing_m) in scenes {
        let start = std::time::Instant::now();
        let ground = match lod_scene::Ground::sample(&region, 40_960.0, 20.0) {
            Ok(g) => g,
            Err(e) => {
                out.push(format!("({key}: {e})\n"));
                continue;
            }
        };
        let scene = lod_scene::Scene::build(&region.name, ground, 150.0, spacing_m);
        let built_s = start.elapsed().as_secs_f64();
        let result = lod::run(&scene, frames, lod::LOSS_FRACTION);
        out.push(lod::report(&scene, &result));
        out.push(format!(
            "Splitting: error against run time ({} frames)\n\n{}\n",
            frames / 3,
            lod::sweep(&scene, frames / 3)
        ));
        out.push(format!("(scene built in {built_s:.1} s; trees {spacing_m} m apart at full cover)\n"));
        if let Some(dir) = plot_dir {
            let path = dir.join(format!("lod_{key}.png"));
            let written = lod_plot::png(&region.name, &result)
                .and_then(|png| std::fs::write(&path, png).map_err(|e| e.to_string()));
            out.push(match written {
                Ok(()) => format!("plot: {}\n", path.display()),
                Err(e) => format!("(no plot: {e})\n"),
            });
        }
    }
    Ok(out.join("\n"))
}
