//! Tiles that failed after their retries: one line each, then a tab and
//! `# why`. A World Wind tile is `layer/level/row/col formats`, the formats
//! whose files failed (`png16,tiff`); a tile of another pyramid is its
//! path as its URL and cache key write it, `xyz/relief/12/655/1400` (the
//! pyramid, the layer, `z/x/y`). The same lines are read by `--tiles-from`,
//! so the failures of a run are re-run with `--tiles-from FILE`, each World
//! Wind tile in the formats it lists (a line without formats takes
//! `--formats`). Blank lines and `#` comments are ignored.

use super::pyramid::Pyramid;
use crate::encode::Format;
use crate::grid::{TileGrid, TileId};
use crate::region::Region;
use crate::server::wms::request::MapLayer;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// A tile of a list: its layer, and the formats it is listed in.
#[derive(Clone, Debug, PartialEq)]
pub struct Entry {
    /// The pyramid.
    pub pyramid: Pyramid,
    /// The layer.
    pub layer: MapLayer,
    /// The tile.
    pub tile: TileId,
    /// Its formats (none listed: the run's `--formats`; none in the other
    /// pyramids).
    pub formats: Vec<Format>,
}

impl Entry {
    /// The tile files it stands for.
    pub fn files(&self) -> u64 {
        files(&self.formats)
    }
}

/// The tile files of one layer of a tile in `formats`: one per format (World
/// Wind's), or the one tile of a pyramid without formats (none given).
pub fn files(formats: &[Format]) -> u64 {
    formats.len().max(1) as u64
}

impl std::fmt::Display for Entry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (layer, tile) = (self.layer.name(), self.pyramid.address(self.tile));
        match self.pyramid {
            Pyramid::WorldWind(_) if self.formats.is_empty() => write!(f, "{layer}/{tile}"),
            Pyramid::WorldWind(_) => {
                let formats: Vec<&str> = self.formats.iter().map(|f| f.name()).collect();
                write!(f, "{layer}/{tile} {}", formats.join(","))
            }
            p => write!(f, "{}/{layer}/{tile}", p.name()),
        }
    }
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

/// Reads a tile list; every tile must exist in its pyramid (World Wind's on
/// the region's tiling), meet the region's bounds (a tile off them has no
/// data: the server keeps nothing there, so a seed has nothing to store),
/// and be one the server answers (at a level it serves, within a WMTS
/// layer's limits, listed in Cesium's `layer.json`).
pub fn read(path: &Path, region: &Region) -> Result<Vec<Entry>, ListError> {
    let fail = |line: usize, message: String| ListError { path: path.to_path_buf(), line, message };
    let text = std::fs::read_to_string(path).map_err(|e| fail(0, format!("cannot read: {e}")))?;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let entry = line.split('#').next().unwrap_or("").trim();
        if entry.is_empty() {
            continue;
        }
        let e = parse_entry(entry, region.tiles).map_err(|why| {
            let expected = "expected layer/level/row/col [formats] or pyramid/layer/z/x/y, e.g. cem/12/2254/3108 bil16,png16 or xyz/relief/12/655/1400";
            fail(i + 1, format!("{entry:?}: {why}; {expected}"))
        })?;
        e.pyramid.check(e.tile).map_err(|why| fail(i + 1, why))?;
        let tile = format!("tile {}", e.pyramid.address(e.tile));
        if !e.pyramid.footprint(e.tile).bbox().meets(&region.bounds) {
            let b = region.bounds;
            let why = format!("does not meet the region; its bounds are {},{},{},{}", b.west, b.south, b.east, b.north);
            return Err(fail(i + 1, format!("{tile} {why}")));
        }
        if !e.pyramid.serves(region, e.layer, e.tile) {
            let (name, layer) = (e.pyramid.name(), e.layer.name());
            return Err(fail(
                i + 1,
                format!("{tile} is not served: not among the {name} {layer} tiles the server lists"),
            ));
        }
        out.push(e);
    }
    Ok(out)
}

/// `layer/level/row/col`, then perhaps a comma-separated list of formats,
/// or `pyramid/layer/z/x/y`; an error names the part that is wrong.
fn parse_entry(entry: &str, tiles: TileGrid) -> Result<Entry, String> {
    let mut fields = entry.split_whitespace();
    let field = fields.next().unwrap_or("");
    let (first, rest) = field.split_once('/').ok_or("no layer/ before the tile")?;
    let (pyramid, path) = match Pyramid::parse(first, tiles).filter(|p| !matches!(p, Pyramid::WorldWind(_))) {
        Some(p) => (p, rest),
        None => (Pyramid::WorldWind(tiles), field),
    };
    let (layer, tile) = path.split_once('/').ok_or("no layer/ before the tile")?;
    let layer = MapLayer::parse(layer)
        .or_else(|| crate::cem::Layer::parse(layer).map(MapLayer::Data))
        .filter(|&l| pyramid.carries(l))
        .ok_or_else(|| format!("unknown layer {layer:?} for {} tiles", pyramid.name()))?;
    let tile = pyramid.parse_address(tile).ok_or_else(|| match pyramid {
        Pyramid::WorldWind(_) => format!("{tile:?} is not level/row/col"),
        _ => format!("{tile:?} is not z/x/y"),
    })?;
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
        None if !formats.is_empty() && pyramid != Pyramid::WorldWind(tiles) => {
            Err(format!("{} tiles have no formats to list", pyramid.name()))
        }
        None => Ok(Entry { pyramid, layer, tile, formats }),
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

    /// Ends a run stopped by a signal: the list it re-runs stays whole (its
    /// tiles not reached yet are in it), and the new failures' file goes.
    pub fn abandon(self) {
        if self.replaces.is_some() {
            let _ = std::fs::remove_file(&self.path);
        }
    }

    /// Records a failed tile.
    pub fn record(&self, entry: &Entry, why: &str) -> std::io::Result<()> {
        let why = why.replace(['\n', '\r'], " ");
        let mut file = self.file.lock().map_err(|_| std::io::Error::other("failed-tiles file lock poisoned"))?;
        writeln!(file, "{entry}\t# {why}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cem::Layer;
    use crate::grid::BBox;
    use crate::grid::quad::TileSet;

    fn grid() -> TileGrid {
        TileGrid::new(36.0, 513).unwrap()
    }

    /// Asserts that a list of the one line `bad` is refused, saying `why`.
    fn refused(path: &Path, bad: &str, why: &str) {
        std::fs::write(path, format!("{bad}\n")).unwrap();
        let err = read(path, &region(BBox::WORLD)).unwrap_err().to_string();
        assert!(err.contains(":1:") && err.contains(why), "{bad}: {err}");
    }

    /// The demo region over `bounds`, on tiles of 36° at level 0.
    fn region(bounds: BBox) -> Region {
        let mut region = crate::config::load(None).unwrap();
        (region.bounds, region.tiles) = (bounds, grid());
        region
    }

    fn entry(layer: Layer, (level, row, col): (u32, u64, u64), formats: &[Format]) -> Entry {
        let (pyramid, layer) = (Pyramid::WorldWind(grid()), MapLayer::Data(layer));
        Entry { pyramid, layer, tile: TileId::new(level, row, col), formats: formats.to_vec() }
    }

    #[test]
    fn a_list_re_run_in_place_stays_whole_until_the_run_ends() {
        let path = std::env::temp_dir().join(format!("sylva-rerun-{}.txt", std::process::id()));
        std::fs::write(&path, "cem/12/3/4\ndem/5/1/2\n").unwrap();
        let f = Failed::replacing(&path).unwrap();
        f.record(&entry(Layer::Dem, (5, 1, 2), &[Format::Bil16]), "still failing").unwrap();
        assert_eq!(
            read(&path, &region(BBox::WORLD)).unwrap().len(),
            2,
            "an interrupted run would leave the list whole"
        );
        assert_eq!(f.finish().unwrap(), path);
        assert_eq!(read(&path, &region(BBox::WORLD)).unwrap(), vec![entry(Layer::Dem, (5, 1, 2), &[Format::Bil16])]);
        // Stopped by a signal: the list stays, its new failures' file goes.
        let f = Failed::replacing(&path).unwrap();
        let next = f.path().to_path_buf();
        f.record(&entry(Layer::Dem, (5, 1, 2), &[Format::Bil16]), "again").unwrap();
        f.abandon();
        assert!(!next.exists() && read(&path, &region(BBox::WORLD)).unwrap().len() == 1);
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
        assert_eq!(read(&path, &region(BBox::WORLD)).unwrap(), failed);
        assert!(
            std::fs::read_to_string(&path).unwrap().starts_with("cem/12/3/4 png16,tiff\t# upstream: 500 Internal\n")
        );
        // Lines without formats take the run's.
        std::fs::write(&path, "# a comment\n\ncem/1/2/3\ntrees/1/2/3\n").unwrap();
        let err = read(&path, &region(BBox::WORLD)).unwrap_err().to_string();
        assert!(err.contains(":4:") && err.contains("unknown layer \"trees\""), "{err}");
        std::fs::write(&path, "cem/1/2/3 png16,tiff,png16\n").unwrap();
        assert_eq!(
            read(&path, &region(BBox::WORLD)).unwrap(),
            vec![entry(Layer::Cem, (1, 2, 3), &[Format::Png16, Format::Tiff])]
        );
        for (bad, why) in [
            ("cem/1/2/3 png17", "unknown format \"png17\""),
            ("cem/1/2/3 png16 tiff", "\"tiff\" follows the formats"),
            ("cem/1/2/3 png16,", "unknown format \"\""),
            ("cem/1/2", "\"1/2\" is not level/row/col"),
        ] {
            refused(&path, bad, why);
        }
        std::fs::write(&path, "cem/1/99/3\n").unwrap();
        assert!(read(&path, &region(BBox::WORLD)).unwrap_err().to_string().contains(":1: tile 1/99/3 does not exist"));
        // A tile off the region: the server keeps nothing there, nor does a seed.
        std::fs::write(&path, "cem/5/1/1\ncem/5/0/0\n").unwrap();
        let corner = BBox { west: -180.0, south: -90.0, east: -179.0, north: -89.0 };
        let err = read(&path, &region(corner)).unwrap_err().to_string();
        assert!(err.contains(":1: tile 5/1/1 does not meet the region; its bounds are -180,-90,-179,-89"), "{err}");
        std::fs::remove_file(&path).unwrap();
    }

    #[test]
    fn tiles_of_the_other_pyramids_are_listed_by_their_paths() {
        let path = std::env::temp_dir().join(format!("sylva-failed-quad-{}.txt", std::process::id()));
        let f = Failed::open(&path).unwrap();
        let quad = |pyramid, layer, (z, x, y)| Entry { pyramid, layer, tile: TileId::new(z, y, x), formats: vec![] };
        let failed = [
            quad(Pyramid::Quad(TileSet::WebMercator), MapLayer::Relief, (12, 655, 1400)),
            quad(Pyramid::Quad(TileSet::Crs84), MapLayer::Data(Layer::Dem), (3, 15, 2)),
            quad(Pyramid::Cesium, MapLayer::Data(Layer::Cem), (1, 3, 0)),
        ];
        for e in &failed {
            f.record(e, "x").unwrap();
        }
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.starts_with("xyz/relief/12/655/1400\t# x\ncrs84/dem/3/15/2\t# x\ncesium/cem/1/3/0\t"), "{text}");
        assert_eq!(read(&path, &region(BBox::WORLD)).unwrap(), failed);
        assert_eq!(failed.iter().map(Entry::files).sum::<u64>(), 3);
        for (bad, why) in [
            ("xyz/relief/3/1/2 png16", "xyz tiles have no formats to list"),
            ("cesium/relief/3/1/2", "unknown layer \"relief\" for cesium tiles"),
            ("crs84/surface/3/1/2", "unknown layer \"surface\" for crs84 tiles"),
            ("xyz/dem/3/1", "\"3/1\" is not z/x/y"),
            ("xyz/dem/3/8/1", "tile 3/8/1 does not exist (zoom 3 has 8 columns × 8 rows)"),
            ("xyz/dem/25/1/1", "tile 25/1/1 is not served: not among the xyz dem tiles"),
            ("cesium/dem/20/1/1", "tile 20/1/1 is not served: not among the cesium dem tiles"),
        ] {
            refused(&path, bad, why);
        }
        std::fs::remove_file(&path).unwrap();
    }
}
