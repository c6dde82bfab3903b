//! A flight's or a view's outputs in its directory: `frame_NNNNN.png` (a
//! view's `view_NNNNN.png`),
//! [`STATS_FILE`] (`docs/stats-csv.md`) and a budget flight's cost model;
//! an earlier run's outputs there refused, or replaced whole.
//!
//! A flight's outputs are never owed: whenever it ends — after its last
//! frame, stopped by an error or a first signal, or at once by a second
//! Ctrl-C or a SIGKILL — what is in its directory is consistent. The
//! directory is made with the first output written, so a run ended before
//! leaves none; each frame's PNG is written whole once rendered, and its
//! row of [`STATS_FILE`] follows at once ([`StatsCsv`]: the header and the
//! first row replace an earlier file whole, each later row is appended).
//! A flight that ends of itself writes the statistics whole again, with a
//! budget flight's cost model (all or none).

use super::{FlyError, FrameRecord};
use crate::client::render::Rendered;
use crate::lod::model::CostModel;
use std::io::Write;
use std::path::{Path, PathBuf};

/// The flight's statistics in its output directory.
pub const STATS_FILE: &str = "stats.csv";
/// The calibrated cost model of a budget flight, in its output directory.
pub(super) const MODEL_FILE: &str = "cost_model.json";

/// Checks that `dir` can take a flight's or a view's outputs — a directory,
/// or none yet where one can be made (it is made with the first output) —
/// and returns an earlier run's outputs there ([`STATS_FILE`], the cost
/// model, frames): refused, or with `overwrite` returned, for
/// [`remove_outputs`] once the new run has something to write: a directory
/// never mixes two runs, and a run that fails before its first frame leaves
/// the earlier one whole.
pub fn prepare_out_dir(dir: &Path, overwrite: bool) -> Result<Vec<PathBuf>, FlyError> {
    let missing = dir.ancestors().take_while(|d| !d.as_os_str().is_empty() && !d.exists()).last();
    match missing {
        // One that cannot be made is refused before the work.
        Some(top) => Ok(crate::outputs::check(&[], &[top]).map(|()| Vec::new())?),
        None if !dir.is_dir() => {
            Err(io(dir, std::io::Error::new(std::io::ErrorKind::NotADirectory, "not a directory")))
        }
        None => checked_earlier(dir, overwrite),
    }
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
    write(&[(&dir.join(STATS_FILE), to_csv(records).as_bytes())])
}

/// [`STATS_FILE`] as a flight goes: a row for each frame once it is done.
pub(super) struct StatsCsv {
    path: PathBuf,
    /// Open to append rows, once the header and the first row are written.
    file: Option<std::fs::File>,
}

impl StatsCsv {
    /// The statistics of a flight into `dir`; nothing written yet.
    pub(super) fn new(dir: &Path) -> StatsCsv {
        StatsCsv { path: dir.join(STATS_FILE), file: None }
    }

    /// Adds a frame's row: the first with the header, in a new file that
    /// replaces an earlier one whole; the others appended, each in one
    /// write (a process ended at once loses no row already added, and
    /// leaves none cut).
    pub(super) fn add(&mut self, record: &FrameRecord) -> Result<(), FlyError> {
        let row = csv_row(record);
        if let Some(file) = &mut self.file {
            return file.write_all(row.as_bytes()).map_err(|e| io(&self.path, e));
        }
        write(&[(&self.path, format!("{CSV_HEADER}\n{row}").as_bytes())])?;
        let file = std::fs::OpenOptions::new().append(true).open(&self.path).map_err(|e| io(&self.path, e))?;
        self.file = Some(file);
        Ok(())
    }
}

/// Writes `files` whole ([`crate::outputs::write_all`]), their directory
/// made first where it is missing: a run's directory is made with its
/// first output.
fn write(files: &[(&Path, &[u8])]) -> Result<(), FlyError> {
    for dir in files.iter().filter_map(|(file, _)| file.parent()).filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| io(dir, e))?;
    }
    Ok(crate::outputs::write_all(files)?)
}

/// Writes a frame's colour as PNG (whole or not at all: a flight killed
/// while writing leaves no half frame).
pub fn write_png(file: &Path, rendered: &Rendered, size: (u32, u32)) -> Result<(), FlyError> {
    let bytes: Vec<u8> = rendered.colour.iter().flatten().copied().collect();
    let png = crate::encode::png(&bytes, size.0 as usize, size.1 as usize, image::ExtendedColorType::Rgba8)
        .map_err(|e| io(file, std::io::Error::other(e.0)))?;
    write(&[(file, &png)])
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
    write(&files)
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
    std::iter::once(format!("{CSV_HEADER}\n")).chain(records.iter().map(csv_row)).collect()
}

/// The first line of [`STATS_FILE`]: its columns.
const CSV_HEADER: &str = "frame,cpu_ms,gpu_ms,gpu_rays_ms,gpu_fill_ms,render_ms,tiles,levels,tiles_ray,tiles_plain,error_px,ray_pixels,view_fetches_mean,view_fetches_max,shadow_fetches_mean,bytes_fetched,gpu_bytes,cpu_bytes,rss_mib,selection_ms,budget_ms,predicted_ms,model_ms,shadow_steps_mean,candidates,benefit_bound,bound,morphing,trees,splats,splat_fill_mpx,nodes_touched,rays_cast,rays_view_fetches,rays_leaf_cells,rays_shadow_fetches,clearance_m";

/// A frame's row of [`STATS_FILE`], its line end included.
fn csv_row(r: &FrameRecord) -> String {
    let mut row = Vec::new();
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
        row,
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
    String::from_utf8_lossy(&row).into_owned()
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
