//! Tiles that failed after their retries: one line each,
//! `layer/level/row/col formats`, the formats whose files failed
//! (`png16,tiff`), then a tab and `# why`. The same format is read by
//! `--tiles-from`, so the failures of a run are re-run with
//! `--tiles-from FILE`, each tile in the formats it lists (a line without
//! formats takes `--formats`). Blank lines and `#` comments are ignored.

use super::progress::parse_tile;
use crate::cem::Layer;
use crate::encode::Format;
use crate::grid::{BBox, TileGrid, TileId};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// A tile of a list: its layer, and the formats it is listed in.
#[derive(Clone, Debug, PartialEq)]
pub struct Entry {
    /// The layer.
    pub layer: Layer,
    /// The tile.
    pub tile: TileId,
    /// Its formats (none listed: the run's `--formats`).
    pub formats: Vec<Format>,
}

/// A tile list that cannot be read.
#[derive(Debug, thiserror::Error)]
#[error("{}: {message}", where_in(path, *line))]
pub struct ListError {
    /// The file.
    pub path: PathBuf,
    /// Line number (1-based; 0 = the whole file).
    pub line: usize,
    /// What is wrong.
    pub message: String,
}

/// `FILE:LINE`, or the file alone for line 0.
fn where_in(path: &Path, line: usize) -> String {
    match line {
        0 => path.display().to_string(),
        n => format!("{}:{n}", path.display()),
    }
}

/// Reads a tile list; every tile must exist in `tiles` and meet the
/// region's `bounds` (a tile off them has no data: the server answers 404
/// there and keeps nothing, so a seed has nothing to store).
pub fn read(path: &Path, tiles: &TileGrid, bounds: &BBox) -> Result<Vec<Entry>, ListError> {
    let fail = |line: usize, message: String| ListError { path: path.to_path_buf(), line, message };
    let text = std::fs::read_to_string(path).map_err(|e| fail(0, format!("cannot read: {e}")))?;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let entry = line.split('#').next().unwrap_or("").trim();
        if entry.is_empty() {
            continue;
        }
        let e = parse_entry(entry).map_err(|why| {
            fail(
                i + 1,
                format!("{entry:?}: {why}; expected layer/level/row/col [formats], e.g. cem/12/2254/3108 bil16,png16"),
            )
        })?;
        tiles.check(e.tile).map_err(|why| fail(i + 1, why.to_string()))?;
        if !tiles.sector(e.tile).bbox().meets(bounds) {
            let b = bounds;
            let why = format!("does not meet the region; its bounds are {},{},{},{}", b.west, b.south, b.east, b.north);
            return Err(fail(i + 1, format!("tile {} {why}", e.tile)));
        }
        out.push(e);
    }
    Ok(out)
}

/// `layer/level/row/col`, then perhaps a comma-separated list of formats;
/// an error names the part that is wrong.
fn parse_entry(entry: &str) -> Result<Entry, String> {
    let mut fields = entry.split_whitespace();
    let (layer, tile) = fields.next().and_then(|f| f.split_once('/')).ok_or("no layer/ before the tile")?;
    let layer = Layer::parse(layer).ok_or_else(|| format!("unknown layer {layer:?}"))?;
    let tile = parse_tile(tile).ok_or_else(|| format!("{tile:?} is not level/row/col"))?;
    let mut formats = Vec::new();
    for name in fields.next().into_iter().flat_map(|list| list.split(',')) {
        let format = Format::parse(name).ok_or_else(|| format!("unknown format {name:?}"))?;
        // Each once (`png16,png16` is one file).
        if !formats.contains(&format) {
            formats.push(format);
        }
    }
    match fields.next() {
        Some(extra) => Err(format!("{extra:?} follows the formats")),
        None => Ok(Entry { layer, tile, formats }),
    }
}

/// The failed-tiles file of a run.
pub struct Failed {
    path: PathBuf,
    /// The list this run re-runs, replaced by `path` when the run ends.
    replaces: Option<PathBuf>,
    file: Mutex<std::fs::File>,
}

impl Failed {
    /// Opens `path`, emptied.
    pub fn open(path: &Path) -> std::io::Result<Failed> {
        let file = std::fs::OpenOptions::new().create(true).append(true).truncate(false).open(path)?;
        file.set_len(0)?;
        Ok(Failed { path: path.to_path_buf(), replaces: None, file: Mutex::new(file) })
    }

    /// Records into `LIST.next` while `list`, the tiles this run re-runs
    /// (a list given, or a resumed run's earlier failures), stays whole:
    /// [`Failed::finish`] puts the new failures in its place, so an
    /// interrupted run loses no tile of the list.
    pub fn replacing(list: &Path) -> std::io::Result<Failed> {
        let mut next = list.as_os_str().to_owned();
        next.push(".next");
        let mut failed = Failed::open(Path::new(&next))?;
        failed.replaces = Some(list.to_path_buf());
        Ok(failed)
    }

    /// The file failures are written to.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Ends a run that went through all its tiles; returns the failed-tiles
    /// file.
    pub fn finish(self) -> std::io::Result<PathBuf> {
        match self.replaces {
            Some(list) => std::fs::rename(&self.path, &list).map(|()| list),
            None => Ok(self.path),
        }
    }

    /// Records a failed tile.
    pub fn record(&self, entry: &Entry, why: &str) -> std::io::Result<()> {
        let why = why.replace(['\n', '\r'], " ");
        let formats: Vec<&str> = entry.formats.iter().map(|f| f.name()).collect();
        let mut file = self.file.lock().map_err(|_| std::io::Error::other("failed-tiles file lock poisoned"))?;
        writeln!(file, "{}/{} {}\t# {why}", entry.layer.name(), entry.tile, formats.join(","))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(layer: Layer, (level, row, col): (u32, u64, u64), formats: &[Format]) -> Entry {
        Entry { layer, tile: TileId::new(level, row, col), formats: formats.to_vec() }
    }

    #[test]
    fn a_list_re_run_in_place_stays_whole_until_the_run_ends() {
        let path = std::env::temp_dir().join(format!("sylva-rerun-{}.txt", std::process::id()));
        std::fs::write(&path, "cem/12/3/4\ndem/5/1/2\n").unwrap();
        let f = Failed::replacing(&path).unwrap();
        f.record(&entry(Layer::Dem, (5, 1, 2), &[Format::Bil16]), "still failing").unwrap();
        let grid = TileGrid::new(36.0, 513).unwrap();
        assert_eq!(read(&path, &grid, &BBox::WORLD).unwrap().len(), 2, "an interrupted run would leave the list whole");
        assert_eq!(f.finish().unwrap(), path);
        assert_eq!(read(&path, &grid, &BBox::WORLD).unwrap(), vec![entry(Layer::Dem, (5, 1, 2), &[Format::Bil16])]);
        std::fs::remove_file(&path).unwrap();
    }

    #[test]
    fn recorded_failures_read_back_with_their_formats_and_bad_lines_are_named() {
        let path = std::env::temp_dir().join(format!("sylva-failed-{}.txt", std::process::id()));
        let f = Failed::open(&path).unwrap();
        let failed = [
            entry(Layer::Cem, (12, 3, 4), &[Format::Png16, Format::Tiff]),
            entry(Layer::Dem, (5, 1, 2), &[Format::Bil32]),
        ];
        f.record(&failed[0], "upstream: 500\nInternal").unwrap();
        f.record(&failed[1], "x").unwrap();
        let grid = TileGrid::new(36.0, 513).unwrap();
        assert_eq!(read(&path, &grid, &BBox::WORLD).unwrap(), failed);
        assert!(
            std::fs::read_to_string(&path).unwrap().starts_with("cem/12/3/4 png16,tiff\t# upstream: 500 Internal\n")
        );
        // Lines without formats take the run's.
        std::fs::write(&path, "# a comment\n\ncem/1/2/3\ntrees/1/2/3\n").unwrap();
        let err = read(&path, &grid, &BBox::WORLD).unwrap_err().to_string();
        assert!(err.contains(":4:") && err.contains("unknown layer \"trees\""), "{err}");
        std::fs::write(&path, "cem/1/2/3 png16,tiff,png16\n").unwrap();
        assert_eq!(
            read(&path, &grid, &BBox::WORLD).unwrap(),
            vec![entry(Layer::Cem, (1, 2, 3), &[Format::Png16, Format::Tiff])]
        );
        for (bad, why) in [
            ("cem/1/2/3 png17", "unknown format \"png17\""),
            ("cem/1/2/3 png16 tiff", "\"tiff\" follows the formats"),
            ("cem/1/2/3 png16,", "unknown format \"\""),
            ("cem/1/2", "\"1/2\" is not level/row/col"),
        ] {
            std::fs::write(&path, format!("{bad}\n")).unwrap();
            let err = read(&path, &grid, &BBox::WORLD).unwrap_err().to_string();
            assert!(err.contains(":1:") && err.contains(why), "{bad}: {err}");
        }
        std::fs::write(&path, "cem/1/99/3\n").unwrap();
        assert!(read(&path, &grid, &BBox::WORLD).unwrap_err().to_string().contains(":1: tile 1/99/3 does not exist"));
        // A tile off the region: the server keeps nothing there, nor does a seed.
        std::fs::write(&path, "cem/5/1/1\ncem/5/0/0\n").unwrap();
        let region = BBox { west: -180.0, south: -90.0, east: -179.0, north: -89.0 };
        let err = read(&path, &grid, &region).unwrap_err().to_string();
        assert!(err.contains(":1: tile 5/1/1 does not meet the region; its bounds are -180,-90,-179,-89"), "{err}");
        std::fs::remove_file(&path).unwrap();
    }
}
