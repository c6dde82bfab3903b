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
fn flight_report(flights: &[std::path::PathBuf], plot_dir: Option<&std::path::Path>) -> Result<String, LodReportError> {
    if flights.is_empty() {
        return Ok("(no flights under a budget given: --flights)\n".into());
    }
    let read = |dir: &std::path::PathBuf| -> Result<(String, String), String> {
        let name = dir.file_name().map_or("flight".into(), |n| n.to_string_lossy().into_owned());
        // `client::fly::STATS_FILE`, in builds without the client too.
        let file = dir.join("stats.csv");
        let csv = std::fs::read_to_string(&file).map_err(|e| format!("{}: {e}", file.display()))?;
        Ok((name, csv))
    };
    let flown = flights.iter().map(read).collect::<Result<Vec<_>, _>>().map_err(LodReportError::Flights)?;
    let (table, plots) = lod_frames::report(&flown).map_err(LodReportError::Flights)?;
    let mut out = format!("### Frame time against the budget\n\n{table}\n");
    for (name, png) in &plots {
        out += &write_plot(plot_dir, &format!("lod_frames_{name}.png"), png)?;
    }
    Ok(out)
}

/// Writes a plot as `name` in `plot_dir`, if given: the line that says
/// where it went.
fn write_plot(plot_dir: Option<&std::path::Path>, name: &str, png: &[u8]) -> Result<String, LodReportError> {
    let Some(dir) = plot_dir else { return Ok(String::new()) };
    let path = dir.join(name);
    crate::outputs::write_all(&[(&path, png)])?;
    Ok(format!("plot: {}\n", path.display()))
}

/// Why `sylva bench lod` stopped.
#[derive(Debug, thiserror::Error)]
pub enum LodReportError {
    /// A region would not load.
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    /// A flight's statistics are missing or unusable (the message names
    /// its file).
    #[error("--flights {0}")]
    Flights(String),
    /// A plot could not be drawn.
    #[error("plot of {0}")]
    Plot(String),
    /// A plot could not be written.
    #[error(transparent)]
    Output(#[from] crate::outputs::OutputError),
    /// The report could not be written.
    #[error("writing the report: {0}")]
    Print(std::io::Error),
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
/// region of `rmnp_config`, each written to `out` once it is done (a plot
/// that fails later loses none); plots go to `plot_dir` when given.
/// `flights` (directories of `sylva fly --lod budget`) add their frame
/// times against the budget.
pub fn lod_report(
    rmnp_config: &std::path::Path,
    frames: usize,
    (plot_dir, flights): (Option<&std::path::Path>, &[std::path::PathBuf]),
    out: &mut dyn std::io::Write,
) -> Result<(), LodReportError> {
    let mut emit = |text: &str| writeln!(out, "{text}").map_err(LodReportError::Print);
    // The flights first: a missing one is said before the long work.
    emit(&flight_report(flights, plot_dir)?)?;
    let mut scenes = vec![("demo", crate::config::load(None)?, 7.0)];
    match crate::config::load(Some(rmnp_config)) {
        Ok(rmnp) => scenes.push(("rmnp", rmnp, 12.0)),
        Err(e) => emit(&format!("(skipping the real-data region: {e})\n"))?,
    }
    for (key, region, spacing_m) in scenes {
        let start = std::time::Instant::now();
        let ground = match lod_scene::Ground::sample(&region, 40_960.0, 20.0) {
            Ok(g) => g,
            Err(e) => {
                emit(&format!("({key}: {e})\n"))?;
                continue;
            }
        };
        let scene = lod_scene::Scene::build(&region.name, ground, 150.0, spacing_m);
        let built_s = start.elapsed().as_secs_f64();
        let result = lod::run(&scene, frames, lod::LOSS_FRACTION);
        emit(&lod::report(&scene, &result))?;
        emit(&format!(
            "Splitting: error against run time ({} frames)\n\n{}\n",
            frames / 3,
            lod::sweep(&scene, frames / 3)
        ))?;
        emit(&format!("(scene built in {built_s:.1} s; trees {spacing_m} m apart at full cover)\n"))?;
        if plot_dir.is_some() {
            let png = lod_plot::png(&region.name, &result).map_err(|e| LodReportError::Plot(format!("{key}: {e}")))?;
            emit(&write_plot(plot_dir, &format!("lod_{key}.png"), &png)?)?;
        }
    }
    Ok(())
}
