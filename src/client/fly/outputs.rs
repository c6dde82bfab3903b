//! A flight's or a view's outputs in its directory: `frame_NNNNN.png` (a
//! view's `view_NNNNN.png`),
//! [`STATS_FILE`] (`docs/stats-csv.md`) and a budget flight's cost model;
//! an earlier run's outputs there refused, or replaced whole.

use super::{FlyError, FrameRecord};
use crate::client::render::Rendered;
use crate::lod::model::CostModel;
use std::io::Write;
use std::path::{Path, PathBuf};

/// The flight's statistics in its output directory.
pub const STATS_FILE: &str = "stats.csv";
/// The calibrated cost model of a budget flight, in its output directory.
pub(super) const MODEL_FILE: &str = "cost_model.json";

/// An output directory made ready for a run ([`prepare_out_dir`]).
#[derive(Debug, Default)]
pub struct OutDir {
    /// An earlier run's outputs there, to go once the new run has
    /// something to write ([`remove_outputs`]).
    pub earlier: Vec<PathBuf>,
    /// The directories made for the run, deepest first: a run that fails
    /// before writing anything removes them ([`OutDir::remove_made`]).
    made: Vec<PathBuf>,
}

impl OutDir {
    /// Removes the directories made for the run while they are empty: a
    /// run that failed before writing anything leaves no trace.
    pub fn remove_made(&self) {
        self.made.iter().take_while(|d| std::fs::remove_dir(d).is_ok()).for_each(drop);
    }
}

/// Makes `dir` ready for a flight's or a view's outputs: made if missing;
/// an earlier run's outputs there ([`STATS_FILE`], the cost model, frames)
/// refused, or with `overwrite` returned, for [`remove_outputs`] once the
/// new run has something to write: a directory never mixes two runs, and a
/// run that fails before its first frame leaves the earlier one whole.
pub fn prepare_out_dir(dir: &Path, overwrite: bool) -> Result<OutDir, FlyError> {
    if dir.exists() && !dir.is_dir() {
        return Err(io(dir, std::io::Error::new(std::io::ErrorKind::NotADirectory, "not a directory")));
    }
    let made: Vec<PathBuf> =
        dir.ancestors().take_while(|d| !d.as_os_str().is_empty() && !d.exists()).map(Path::to_path_buf).collect();
    std::fs::create_dir_all(dir).map_err(|e| io(dir, e))?;
    // A directory just made holds nothing to refuse.
    Ok(OutDir { earlier: checked_earlier(dir, overwrite)?, made })
}

/// An earlier run's outputs in `dir`: refused without `overwrite`.
fn checked_earlier(dir: &Path, overwrite: bool) -> Result<Vec<PathBuf>, FlyError> {
    crate::outputs::check(&[], &[&dir.join(STATS_FILE), &dir.join(MODEL_FILE)])?;
    let earlier = earlier_outputs(dir).map_err(|e| io(dir, e))?;
    if !earlier.is_empty() && !overwrite {
        return Err(FlyError::Earlier(dir.to_path_buf(), describe_outputs(&earlier)));
    }
    Ok(earlier)
}

/// Removes an earlier run's outputs (from [`prepare_out_dir`]).
pub fn remove_outputs(files: &[PathBuf]) -> Result<(), FlyError> {
    files.iter().try_for_each(|f| std::fs::remove_file(f).map_err(|e| io(f, e)))
}

/// The files in `dir` a flight or view writes: [`STATS_FILE`], the cost
/// model, a flight's `frame_NNNNN.png` and a view's `view_NNNNN.png`.
fn earlier_outputs(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    let mut found = Vec::new();
    for entry in std::fs::read_dir(dir)? {
        let path = entry?.path();
        let name = path.file_name().and_then(|n| n.to_str()).unwrap_or_default();
        let frame = is_frame(name);
        if path.is_file() && (frame || name == STATS_FILE || name == MODEL_FILE) {
            found.push(path);
        }
    }
    Ok(found)
}

/// A flight's or a view's frame as they name it: `frame_NNNNN.png`,
/// `view_NNNNN.png` or `view_NNNNN-K.png` (the index as `{:05}` writes
/// it; `K` from 1). A user's file named otherwise, such as `frame_1.png`,
/// is none: `--overwrite` leaves it.
fn is_frame(name: &str) -> bool {
    let index = |n: &str| n.parse::<u64>().is_ok_and(|k| format!("{k:05}") == n);
    let suffix = |n: &str| n.parse::<u64>().is_ok_and(|k| k > 0 && k.to_string() == n);
    let Some(stem) = name.strip_suffix(".png") else { return false };
    match (stem.strip_prefix("frame_"), stem.strip_prefix("view_")) {
        (Some(n), _) => index(n),
        (None, Some(n)) => match n.split_once('-') {
            Some((n, k)) => index(n) && suffix(k),
            None => index(n),
        },
        (None, None) => false,
    }
}

/// What an earlier run left, as "stats.csv, cost_model.json, 12 frames".
fn describe_outputs(files: &[PathBuf]) -> String {
    let names: Vec<&str> = files.iter().filter_map(|f| f.file_name()?.to_str()).collect();
    let frames = names.iter().filter(|n| is_frame(n)).count();
    let mut parts: Vec<String> = names.iter().filter(|n| !is_frame(n)).map(|n| n.to_string()).collect();
    parts.sort();
    match frames {
        0 => {}
        1 => parts.push("1 frame".into()),
        n => parts.push(format!("{n} frames")),
    }
    parts.join(", ")
}

/// Writes `records` as [`STATS_FILE`] in `dir`.
pub fn write_stats(dir: &Path, records: &[FrameRecord]) -> Result<(), FlyError> {
    Ok(crate::outputs::write_all(&[(&dir.join(STATS_FILE), to_csv(records).as_bytes())])?)
}

/// Writes a frame's colour as PNG (whole or not at all: a flight killed
/// while writing leaves no half frame).
pub fn write_png(file: &Path, rendered: &Rendered, size: (u32, u32)) -> Result<(), FlyError> {
    let bytes: Vec<u8> = rendered.colour.iter().flatten().copied().collect();
    let png = crate::encode::png(&bytes, size.0 as usize, size.1 as usize, image::ExtendedColorType::Rgba8)
        .map_err(|e| io(file, std::io::Error::other(e.0)))?;
    Ok(crate::outputs::write_all(&[(file, &png)])?)
}

/// Writes a flight's results in `dir`, all or none: its statistics and a
/// budget flight's calibrated cost model (for `--cost-model` on the next
/// flight).
pub(super) fn write_results(dir: &Path, records: &[FrameRecord], model: Option<&CostModel>) -> Result<(), FlyError> {
    let csv = to_csv(records);
    let json = model.map(CostModel::to_json);
    let (stats, model_file) = (dir.join(STATS_FILE), dir.join(MODEL_FILE));
    let mut files: Vec<(&Path, &[u8])> = vec![(&stats, csv.as_bytes())];
    files.extend(json.as_deref().map(|j| (model_file.as_path(), j.as_bytes())));
    Ok(crate::outputs::write_all(&files)?)
}

/// Writes the results of a flight stopped after `records` and says what
/// is kept: "; their frames and stats.csv are in DIR" (`frames`: PNGs
/// were written), or why not.
pub(super) fn keep(dir: &Path, records: &[FrameRecord], model: Option<&CostModel>, frames: bool) -> String {
    if let Err(e) = write_results(dir, records, model) {
        return format!("; their statistics were not written: {e}");
    }
    let mut names: Vec<&str> = Vec::new();
    names.extend(frames.then_some("frames"));
    names.push(STATS_FILE);
    names.extend(model.map(|_| MODEL_FILE));
    let last = names.pop().unwrap_or_default();
    let (list, verb) = match names.len() {
        0 => (last.to_string(), "is"),
        _ => (format!("{} and {last}", names.join(", ")), "are"),
    };
    format!("; their {list} {verb} in {}", dir.display())
}

/// The statistics as CSV, one row per frame.
pub fn to_csv(records: &[FrameRecord]) -> String {
    let mut out = Vec::new();
    let _ = writeln!(
        out,
        "frame,cpu_ms,gpu_ms,gpu_rays_ms,gpu_fill_ms,render_ms,tiles,levels,tiles_ray,tiles_plain,error_px,ray_pixels,view_fetches_mean,view_fetches_max,shadow_fetches_mean,bytes_fetched,gpu_bytes,cpu_bytes,rss_mib,selection_ms,budget_ms,predicted_ms,model_ms,shadow_steps_mean,candidates,benefit_bound,bound,morphing,trees,splats,splat_fill_mpx,nodes_touched,rays_cast,rays_view_fetches,rays_leaf_cells,rays_shadow_fetches,clearance_m"
    );
    for r in records {
        let levels: Vec<String> = r.levels.iter().map(|(l, n)| format!("{l}:{n}")).collect();
        let optional = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.3}"));
        let count = |n: Option<usize>| n.map_or(String::new(), |n| n.to_string());
        let gpu = optional(r.gpu_ms);
        let (rays, fill) = (optional(r.gpu_rays_ms.map(|t| t.0)), optional(r.gpu_rays_ms.map(|t| t.1)));
        let work: [String; 4] = r
            .work
            .map(|w| [w.rays, w.view_fetches, w.leaf_cells, w.shadow_fetches].map(|n| n.to_string()))
            .unwrap_or_default();
        let _ = writeln!(
            out,
            "{},{:.3},{gpu},{rays},{fill},{:.3},{},{},{},{},{},{},{:.2},{},{:.2},{},{},{},{:.1},{:.3},{},{},{},{:.2},{},{},{},{},{},{},{:.4},{},{},{},{},{},{}",
            r.frame,
            r.cpu_ms,
            r.render_ms,
            r.tiles_ray + r.tiles_plain,
            levels.join(" "),
            r.tiles_ray,
            r.tiles_plain,
            r.error_px.map_or(String::new(), |e| format!("{e:.2}")),
            r.ray_pixels,
            r.view_fetches.0,
            r.view_fetches.1,
            r.shadow_fetches_mean,
            r.bytes_fetched,
            r.gpu_bytes,
            r.cpu_bytes,
            r.rss_mib,
            r.selection_ms,
            optional(r.budget_ms),
            optional(r.predicted_ms),
            optional(r.model_ms),
            r.shadow_steps_mean,
            count(r.candidates),
            optional(r.benefit_bound),
            r.bound.unwrap_or_default(),
            count(r.morphing),
            r.trees,
            r.splats,
            r.splat_fill_px / 1e6,
            count(r.nodes_touched),
            work[0],
            work[1],
            work[2],
            work[3],
            r.clearance_m.map_or(String::new(), |c| format!("{c:.1}"))
        );
    }
    String::from_utf8_lossy(&out).into_owned()
}

fn io(path: &Path, source: std::io::Error) -> FlyError {
    FlyError::Io { path: path.display().to_string(), source }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn overwrite_replaces_only_the_files_a_flight_or_a_view_writes() {
        // Regression, from a user's trial: `--overwrite` removed a user's
        // own `frame_1.png` from --out, as any `frame_*.png`.
        let dir = std::env::temp_dir().join(format!("sylva-fly-earlier-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let written =
            ["frame_00000.png", "frame_123456.png", "view_00004.png", "view_00004-2.png", STATS_FILE, MODEL_FILE];
        let theirs = [
            "frame_1.png",
            "frame_0001.png",
            "frame_+0001.png",
            "frame_00001-1.png",
            "view_00004-0.png",
            "frame_notes.png",
            "notes.txt",
        ];
        for name in written.iter().chain(&theirs) {
            std::fs::write(dir.join(name), b"x").unwrap();
        }
        let refused = prepare_out_dir(&dir, false).unwrap_err().to_string();
        assert!(refused.contains("(cost_model.json, stats.csv, 4 frames)"), "{refused}");
        let mut earlier: Vec<String> = prepare_out_dir(&dir, true)
            .unwrap()
            .earlier
            .iter()
            .map(|f| f.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        earlier.sort();
        let mut expected = written.map(String::from).to_vec();
        expected.sort();
        assert_eq!(earlier, expected);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
