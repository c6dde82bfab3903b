//! The seed command's options as given, and their checking into a job:
//! every string parsed with an error that names the flag or file and the
//! problem, the configuration and region loaded, the coverage read, the
//! layers and levels checked against the pyramid (a quadtree set's or
//! Cesium's levels default to those the server advertises).

use super::SeedError;
use super::coverage::{Coverage, Relation};
use super::display::Mode;
use super::pyramid::{self, Pyramid};
use super::walk::{Shard, Walk};
use crate::cem::Layer;
use crate::config::Config;
use crate::encode::Format;
use crate::grid::{BBox, TileGrid};
use crate::region::Region;
use crate::server::wms::request::MapLayer;
use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};
use std::time::SystemTime;

/// `sylva seed` as given on the command line.
#[derive(Clone, Debug)]
pub struct SeedOptions {
    /// Region configuration (default: the embedded demo region).
    pub config: Option<PathBuf>,
    /// Cache tiles in this directory instead of `[tile_cache]`.
    pub cache_dir: Option<PathBuf>,
    /// The pyramid: `worldwind`, `xyz`, `crs84` or `cesium`.
    pub grid: String,
    /// Comma-separated layers, e.g. `cem,dem`.
    pub layers: String,
    /// Comma-separated formats of World Wind tiles, e.g. `bil16,png16`
    /// (default `bil16`).
    pub formats: Option<String>,
    /// `FROM-TO` or one level (required for World Wind's tiles unless
    /// `tiles_from`; default for the others: the levels the server
    /// advertises).
    pub levels: Option<String>,
    /// `W,S,E,N` (default: the region's bounds).
    pub bbox: Option<String>,
    /// A GeoJSON file of polygons instead of a box.
    pub coverage: Option<PathBuf>,
    /// Seed the tiles listed in this file instead of walking.
    pub tiles_from: Option<PathBuf>,
    /// Print the tiles per level and stop.
    pub dry_run: bool,
    /// Worker threads (0 = one per core).
    pub concurrency: usize,
    /// Continue the job recorded in the progress file.
    pub resume: bool,
    /// The progress file (default `seed-progress.json`, per shard).
    pub progress_file: Option<PathBuf>,
    /// The failed-tiles file (default `seed-failed.txt`, per shard).
    pub failed_file: Option<PathBuf>,
    /// Remake tiles written before this date (RFC 3339, or `YYYY-MM-DD`).
    pub refresh_before: Option<String>,
    /// Keep every valid tile already there.
    pub skip_existing: bool,
    /// Retries of a failing tile.
    pub retries: u32,
    /// Stop after more failed tiles than this.
    pub max_failures: u64,
    /// `I/N`: seed part I (0-based) of N.
    pub shard: Option<String>,
    /// Build parents from their children where that is exact.
    pub from_children: bool,
    /// How progress is shown.
    pub display: Mode,
}

impl Default for SeedOptions {
    fn default() -> Self {
        SeedOptions {
            config: None,
            cache_dir: None,
            grid: "worldwind".into(),
            layers: "cem".into(),
            formats: None,
            levels: None,
            bbox: None,
            coverage: None,
            tiles_from: None,
            dry_run: false,
            concurrency: 0,
            resume: false,
            progress_file: None,
            failed_file: None,
            refresh_before: None,
            skip_existing: false,
            retries: 2,
            max_failures: 1000,
            shard: None,
            from_children: true,
            display: Mode::Auto,
        }
    }
}

/// A checked job.
pub struct Job {
    /// The configuration.
    pub config: Config,
    /// Its region.
    pub region: Region,
    /// The pyramid seeded.
    pub pyramid: Pyramid,
    /// Layers.
    pub layers: Vec<MapLayer>,
    /// Formats of World Wind's tiles (none for the other pyramids).
    pub formats: Vec<Format>,
    /// The walk (absent for a tile list).
    pub walk: Option<Walk>,
    /// This shard.
    pub shard: Shard,
    /// Entries written before this are remade (`None`: before the job's start).
    pub refresh_before: Option<SystemTime>,
    /// Progress and failed-tiles files.
    pub files: (PathBuf, PathBuf),
    /// Digest of everything that defines the job.
    pub fingerprint: String,
}

/// Most worker threads a seed runs (each holds a tile's planes in memory).
const MAX_CONCURRENCY: usize = 256;

impl Job {
    /// Checks the options, loads the region and reads the coverage.
    pub fn new(o: &SeedOptions) -> Result<Job, SeedError> {
        let shard = o.shard.as_deref().map(parse_shard).transpose()?.unwrap_or(Shard::ALL);
        if o.concurrency > MAX_CONCURRENCY {
            return Err(SeedError::Usage(format!("--concurrency {}: at most {MAX_CONCURRENCY}", o.concurrency)));
        }
        let refresh_before = match (&o.refresh_before, o.skip_existing) {
            (Some(date), false) => Some(parse_date(date)?),
            (None, true) => Some(SystemTime::UNIX_EPOCH),
            (None, false) => None,
            (Some(_), true) => {
                return Err(SeedError::Usage("--refresh-before and --skip-existing exclude each other".into()));
            }
        };
        let (config, region) = crate::config::load_with_config(o.config.as_deref())?;
        let (pyramid, layers, formats) = tiles(o, &region)?;
        let (walk, area) = match &o.tiles_from {
            Some(list) => (None, format!("list {}", list.display())),
            None => {
                let levels = levels(o.levels.as_deref(), &region, pyramid, &layers)?;
                let (coverage, area) = coverage(o, &region)?;
                (Some(Walk::new(pyramid, coverage, levels.clone(), shard)), format!("{area} levels {levels:?}"))
            }
        };
        let suffix = if shard.count > 1 { format!("-{}-of-{}", shard.index, shard.count) } else { String::new() };
        let files = (
            o.progress_file.clone().unwrap_or_else(|| PathBuf::from(format!("seed-progress{suffix}.json"))),
            o.failed_file.clone().unwrap_or_else(|| PathBuf::from(format!("seed-failed{suffix}.txt"))),
        );
        // The failed-tiles file may be the list re-run: it is then replaced at
        // the end, by one shard's failures only if the list is its alone.
        let in_place = o.tiles_from.as_deref().is_some_and(|l| crate::outputs::same_file(l, &files.1));
        if in_place && shard.count > 1 {
            return Err(SeedError::Usage(format!(
                "--shard with --tiles-from {}: that is this shard's failed-tiles file, which the run replaces with its own failures; give each shard its own --failed-file",
                files.1.display()
            )));
        }
        let list = o.tiles_from.as_deref().filter(|_| !in_place);
        let named = config.files(o.config.as_deref().map_or(Path::new("."), crate::config::base_of));
        let given = [o.config.as_deref(), o.coverage.as_deref(), list].into_iter().flatten();
        let inputs: Vec<&Path> = given.chain(named.iter().map(PathBuf::as_path)).collect();
        crate::outputs::check(&inputs, &[&files.0, &files.1])?;
        let job = format!("{area} {shard:?}");
        let fingerprint = fingerprint(&region.version, pyramid, &layers, &formats, &job);
        Ok(Job { config, region, pyramid, layers, formats, walk, shard, refresh_before, files, fingerprint })
    }

    /// The formats of a listed tile: those its line lists, else (World
    /// Wind's) the job's.
    pub fn formats_of<'a>(&'a self, entry: &'a super::failed::Entry) -> &'a [Format] {
        match entry.pyramid {
            Pyramid::WorldWind(_) if entry.formats.is_empty() => &self.formats,
            _ => &entry.formats,
        }
    }

    /// Tile files of a tile of `level`: each layer served there, in each
    /// format (World Wind's) or its one tile.
    pub fn files_at(&self, level: u32) -> u64 {
        let served = self.layers.iter().filter(|&&l| self.pyramid.serves_level(&self.region, l, level));
        served.count() as u64 * super::failed::files(&self.formats)
    }
}

/// The pyramid, the layers it carries and (World Wind's) the formats.
fn tiles(o: &SeedOptions, region: &Region) -> Result<(Pyramid, Vec<MapLayer>, Vec<Format>), SeedError> {
    let pyramid = Pyramid::parse(&o.grid, region.tiles)
        .ok_or_else(|| SeedError::Usage(format!("--grid: unknown {:?}; expected one of {}", o.grid, pyramid::NAMES)))?;
    let known = format!("{} (in {} tiles)", pyramid.layer_names(), pyramid.name());
    let layers = list(&o.layers, "--layers", |n| map_layer(n).filter(|&l| pyramid.carries(l)), &known)?;
    for &layer in &layers {
        if let Some(Err(why)) = pyramid.advertised(region, layer) {
            return Err(SeedError::Usage(format!("--grid {}: {why}", pyramid.name())));
        }
    }
    let formats = match (&o.formats, pyramid) {
        (formats, Pyramid::WorldWind(_)) => {
            list(formats.as_deref().unwrap_or("bil16"), "--formats", Format::parse, "bil16, bil32, png16, tiff")?
        }
        (None, _) => Vec::new(),
        (Some(_), p) => {
            let why = format!("{} tiles come in one format; --formats is for worldwind tiles", p.name());
            return Err(SeedError::Usage(format!("--formats: {why}")));
        }
    };
    Ok((pyramid, layers, formats))
}

/// Digest of everything that defines a job (a World Wind job's as before
/// the other pyramids were seeded, so that its progress file resumes).
fn fingerprint(version: &str, pyramid: Pyramid, layers: &[MapLayer], formats: &[Format], job: &str) -> String {
    let names: Vec<&str> = layers.iter().map(|l| l.name()).collect();
    let what = match pyramid {
        Pyramid::WorldWind(_) => {
            let data: Vec<Layer> =
                layers.iter().filter_map(|l| if let MapLayer::Data(d) = l { Some(*d) } else { None }).collect();
            format!("{version} {data:?} {formats:?} {job}")
        }
        p => format!("{version} {} {names:?} {job}", p.name()),
    };
    format!("{:016x}", crate::cache::digest(what.as_bytes()))
}

/// A layer by name: a data layer or a picture.
fn map_layer(name: &str) -> Option<MapLayer> {
    MapLayer::parse(name).or_else(|| Layer::parse(name).map(MapLayer::Data))
}

/// The levels to seed: those given (their last no deeper than the deepest
/// any layer is served at), or, for a pyramid other than World Wind's,
/// those the server advertises for any of the layers. A layer is seeded at
/// the levels it is served at alone ([`Job::files_at`]).
fn levels(
    text: Option<&str>,
    region: &Region,
    pyramid: Pyramid,
    layers: &[MapLayer],
) -> Result<RangeInclusive<u32>, SeedError> {
    let Some(text) = text else {
        let advertised: Vec<RangeInclusive<u32>> =
            layers.iter().filter_map(|&l| pyramid.advertised(region, l)?.ok()).collect();
        return match (advertised.iter().map(|l| *l.start()).min(), advertised.iter().map(|l| *l.end()).max()) {
            (Some(from), Some(to)) => Ok(from..=to),
            _ => Err(SeedError::Usage("give --levels FROM-TO (or --tiles-from FILE)".into())),
        };
    };
    let levels = parse_levels(text)?;
    let deepest =
        layers.iter().filter_map(|&l| Some((*pyramid.served_levels(region, l)?.end(), l))).max_by_key(|d| d.0);
    match deepest {
        Some((deepest, layer)) if *levels.end() > deepest => Err(SeedError::Usage(format!(
            "--levels {text:?}: {} {} tiles go down to level {deepest}",
            pyramid.name(),
            layer.name()
        ))),
        _ => Ok(levels),
    }
}

/// The coverage and a description that changes with it.
fn coverage(o: &SeedOptions, region: &Region) -> Result<(Coverage, String), SeedError> {
    match (&o.bbox, &o.coverage) {
        (Some(_), Some(_)) => Err(SeedError::Usage("give --bbox or --coverage, not both".into())),
        (Some(text), None) => {
            let b = BBox::parse(text).map_err(|e| SeedError::Usage(format!("--bbox: {e}")))?;
            let r = region.bounds;
            let usage = |why: &str| {
                let bounds = format!("{},{},{},{}", r.west, r.south, r.east, r.north);
                SeedError::Usage(format!("--bbox {text}: {why}; the region's bounds are {bounds}"))
            };
            match b.clipped_to(&r)[..] {
                [] => Err(usage("does not meet the region")),
                [part] => Ok((Coverage::Box(part), format!("bbox {text}"))),
                // Over a region of every longitude the box is one piece on
                // the globe (tiles meet it modulo 360°).
                _ if r.east - r.west >= 360.0 => {
                    let part = BBox { south: b.south.max(r.south), north: b.north.min(r.north), ..b };
                    Ok((Coverage::Box(part), format!("bbox {text}")))
                }
                _ => Err(usage("meets the region on both sides of the antimeridian: give each side its own --bbox")),
            }
        }
        (None, Some(path)) => {
            let text = std::fs::read(path).unwrap_or_default();
            let polygons = Coverage::from_geojson(path)?;
            let r = region.bounds;
            if polygons.relation(&r.sector()) == Relation::Outside {
                let bounds = format!("{},{},{},{}", r.west, r.south, r.east, r.north);
                let why = format!("does not meet the region; the region's bounds are {bounds}");
                return Err(SeedError::Usage(format!("--coverage {}: {why}", path.display())));
            }
            let area = Coverage::Within(Box::new(polygons), r);
            Ok((area, format!("coverage {:016x}", crate::cache::digest(&text))))
        }
        (None, None) => Ok((Coverage::Box(region.bounds), format!("region bounds {:?}", region.bounds))),
    }
}

/// A comma-separated list of names.
fn list<T: PartialEq>(
    text: &str,
    flag: &str,
    parse: impl Fn(&str) -> Option<T>,
    known: &str,
) -> Result<Vec<T>, SeedError> {
    let mut out = Vec::new();
    for name in text.split(',').map(str::trim) {
        let v = parse(name)
            .ok_or_else(|| SeedError::Usage(format!("{flag}: unknown {name:?}; expected some of {known}")))?;
        if !out.contains(&v) {
            out.push(v);
        }
    }
    Ok(out)
}

/// `FROM-TO` or `LEVEL`.
pub fn parse_levels(text: &str) -> Result<RangeInclusive<u32>, SeedError> {
    let bad = |why: &str| SeedError::Usage(format!("--levels {text:?}: {why}"));
    let number = |s: &str| s.trim().parse::<u32>().map_err(|_| bad("expected FROM-TO or one level, e.g. 0-12"));
    let (from, to) = match text.split_once('-') {
        Some((a, b)) => (number(a)?, number(b)?),
        None => (number(text)?, number(text)?),
    };
    if from > to {
        return Err(bad("FROM is above TO"));
    }
    if to > TileGrid::MAX_LEVEL {
        return Err(bad(&format!("levels go up to {}", TileGrid::MAX_LEVEL)));
    }
    Ok(from..=to)
}

/// `I/N`, 0 ≤ I < N.
pub fn parse_shard(text: &str) -> Result<Shard, SeedError> {
    let bad = || SeedError::Usage(format!("--shard {text:?}: expected I/N with 0 <= I < N, e.g. 0/4"));
    let (i, n) = text.split_once('/').ok_or_else(bad)?;
    let (index, count) = (i.trim().parse::<u32>().map_err(|_| bad())?, n.trim().parse::<u32>().map_err(|_| bad())?);
    if index >= count { Err(bad()) } else { Ok(Shard { index, count }) }
}

/// RFC 3339 (`2026-12-01T12:00:00Z`, or with a space) or a day (`2026-12-01`, midnight UTC).
pub fn parse_date(text: &str) -> Result<SystemTime, SeedError> {
    let full = if text.len() == 10 { format!("{text}T00:00:00Z") } else { text.to_string() };
    humantime::parse_rfc3339_weak(full.trim_end_matches('Z')).map_err(|e| {
        SeedError::Usage(format!("--refresh-before {text:?}: {e}; expected e.g. 2026-12-01 or 2026-12-01T12:00:00Z"))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flags_parse_and_bad_ones_say_why() {
        assert_eq!(parse_levels("0-12").unwrap(), 0..=12);
        assert_eq!(parse_levels("7").unwrap(), 7..=7);
        for bad in ["12-3", "a-b", "0-99", ""] {
            assert!(parse_levels(bad).unwrap_err().to_string().contains("--levels"), "{bad}");
        }
        assert_eq!(parse_shard("2/4").unwrap(), Shard { index: 2, count: 4 });
        assert!(parse_shard("4/4").is_err() && parse_shard("1").is_err());
        let day = parse_date("2026-12-01").unwrap();
        assert_eq!(day.duration_since(SystemTime::UNIX_EPOCH).unwrap().as_secs(), 1_796_083_200);
        assert!(parse_date("2026-12-01T12:00:00Z").unwrap() > day);
        assert!(parse_date("yesterday").unwrap_err().to_string().contains("--refresh-before"));
        assert!(list("cem,trees", "--layers", Layer::parse, "…").unwrap_err().to_string().contains("\"trees\""));
    }
}
