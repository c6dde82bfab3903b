//! `sylva cache usage` and `sylva cache prune`: what the tile cache holds
//! per version key, and removing what no configuration reads any more
//! (`sylva::cache::prune`).

use anyhow::{Context, Result};
use std::path::PathBuf;
use std::time::{Duration, SystemTime};
use sylva::cache::prune::{self, Plan, VersionUsage};
use sylva::config::show_size as size;

/// `sylva cache`'s commands.
#[derive(clap::Subcommand)]
pub enum CacheCommand {
    /// What the tile cache holds per version key, and which versions the
    /// configurations make.
    Usage(Caches),
    /// Remove stale versions and trim the least recently used tiles.
    Prune(PruneArgs),
}

impl CacheCommand {
    /// Runs the command.
    pub fn run(self) -> Result<()> {
        match self {
            CacheCommand::Usage(caches) => usage(&caches),
            CacheCommand::Prune(args) => args.run(),
        }
    }
}

/// The cache and the versions that are current.
#[derive(clap::Args)]
pub struct Caches {
    /// A region configuration whose tiles are current; give one for every
    /// region sharing the cache (default: the embedded demo region). The
    /// cache is the first one's `[tile_cache]`.
    #[arg(long = "config")]
    configs: Vec<PathBuf>,
    /// Tile cache directory (default: the first configuration's `[tile_cache]`).
    #[arg(long)]
    cache_dir: Option<PathBuf>,
}

/// The current versions, named by their regions, and the cache's backend.
struct Current {
    regions: Vec<(String, String)>,
    backend: sylva::cache::Backend,
}

impl Caches {
    /// Loads the configurations.
    fn current(&self) -> Result<Current> {
        let paths: Vec<Option<&std::path::Path>> = match self.configs.is_empty() {
            true => vec![None],
            false => self.configs.iter().map(|p| Some(p.as_path())).collect(),
        };
        let mut regions = Vec::new();
        let mut backend = None;
        for path in paths {
            let (config, region) = sylva::config::load_with_config(path)?;
            let theirs = config.tile_cache.backend(self.cache_dir.as_deref());
            if backend.get_or_insert_with(|| theirs.clone()) != &theirs {
                let named = path.map_or("the demo".into(), |p| p.display().to_string());
                return Err(super::usage(format_args!(
                    "{named} keeps its tiles elsewhere than the first configuration: give --cache-dir, or one cache's configurations"
                )));
            }
            regions.push((region.version.clone(), region.name.clone()));
        }
        Ok(Current { regions, backend: backend.context("no configuration")? })
    }
}

/// `sylva cache usage`.
fn usage(caches: &Caches) -> Result<()> {
    let current = caches.current()?;
    let (cache, versions) = prune::usage(&current.backend)?;
    let mut rows = vec![
        format!("tile cache: {cache}"),
        format!("{:<17}  {:>10}  {:>10}  {:<20}  state", "version", "tiles", "size", "last used"),
    ];
    for v in &versions {
        let state = match current.regions.iter().find(|(version, _)| *version == v.version) {
            Some((_, name)) => format!("current ({name})"),
            None => "stale".to_string(),
        };
        rows.push(format!("{}  {state}", row(v)));
    }
    let (tiles, bytes) = versions.iter().fold((0, 0), |(t, b), v| (t + v.tiles, b + v.bytes));
    rows.push(format!("{:<17}  {tiles:>10}  {:>10}", "total", size(bytes)));
    for (version, name) in current.regions.iter().filter(|(version, _)| !versions.iter().any(|v| v.version == *version))
    {
        rows.push(format!("{version} ({name}): no tiles yet"));
    }
    super::print(rows.join("\n"))
}

/// A version's columns.
fn row(v: &VersionUsage) -> String {
    format!("{:<17}  {:>10}  {:>10}  {:<20}", v.version, v.tiles, size(v.bytes), last_used(v, "-"))
}

/// A version in a sentence.
fn described(v: &VersionUsage) -> String {
    format!("{} ({} tiles, {}, last used {})", v.version, v.tiles, size(v.bytes), last_used(v, "never"))
}

/// When a version was last used (UTC, to the second), or `never`.
fn last_used(v: &VersionUsage, never: &str) -> String {
    v.last_used.map_or(never.to_string(), |t| humantime::format_rfc3339_seconds(t).to_string())
}

/// `sylva cache prune`.
#[derive(clap::Args)]
#[command(group = clap::ArgGroup::new("what").required(true).multiple(true).args(["stale", "max_size"]))]
pub struct PruneArgs {
    #[command(flatten)]
    caches: Caches,
    /// Remove every version that no configuration given makes (after a
    /// configuration or a source file changed), unless used within --grace.
    #[arg(long)]
    stale: bool,
    /// With --stale: remove them even if no configuration's version has
    /// tiles in the cache (which suggests the servers run other
    /// configurations, source files or Sylva than this command).
    #[arg(long, requires = "stale")]
    force: bool,
    /// Then remove the least recently used tiles until the cache holds at
    /// most SIZE: 500MiB, 20GiB (powers of 1024), 20G or 20GB (of 1000).
    #[arg(long, value_parser = sylva::config::parse_size)]
    max_size: Option<u64>,
    /// With --stale: a version written, marked in use (servers and seeders
    /// mark theirs every 5 minutes while they run) or read (as far as the
    /// file system records reads; Redis does not) within this long is kept:
    /// 1h, 2days; at least 10m.
    #[arg(long, default_value = "1h", value_parser = grace, requires = "stale")]
    grace: Duration,
    /// Say what would be removed; remove nothing.
    #[arg(long)]
    dry_run: bool,
}

/// `--grace`'s parser: a duration of at least two marks of use.
fn grace(text: &str) -> Result<Duration, String> {
    let least = sylva::cache::in_use::EVERY * 2;
    match humantime::parse_duration(text).map_err(|e| e.to_string())? {
        d if d < least => Err(format!(
            "at least {} (running servers mark their version every {})",
            humantime::format_duration(least),
            humantime::format_duration(sylva::cache::in_use::EVERY)
        )),
        d => Ok(d),
    }
}

impl PruneArgs {
    fn run(self) -> Result<()> {
        let current = self.caches.current()?;
        let plan = Plan {
            keep: current.regions.iter().map(|(version, _)| version.clone()).collect(),
            stale: self.stale,
            force: self.force,
            max_bytes: self.max_size,
            grace: self.grace,
            dry_run: self.dry_run,
        };
        let pruned = prune::prune(&current.backend, &plan, SystemTime::now())?;
        let (removes, trims, leaves) = match self.dry_run {
            true => ("would remove", "would trim", "would leave"),
            false => ("removed", "trimmed", "left"),
        };
        let mut lines = vec![format!("tile cache: {} ({})", pruned.cache, size(pruned.bytes_before))];
        for (version, name) in &current.regions {
            lines.push(format!("current: {version} ({name})"));
        }
        for v in &pruned.removed {
            lines.push(format!("{removes} stale version {}", described(v)));
        }
        for v in &pruned.in_use {
            let grace = humantime::format_duration(self.grace);
            lines.push(format!("kept stale version {}: in use, within --grace {grace}", described(v)));
        }
        if let Some(max) = self.max_size {
            let (entries, bytes) = pruned.trimmed;
            let what = format!("{entries} least recently used tiles and shared entries ({})", size(bytes));
            lines.push(format!("{trims} {what} for --max-size {}", size(max)));
            if pruned.bytes_after > max {
                let over = size(pruned.bytes_after - max);
                lines.push(format!("{over} above --max-size: locks, marks and directories are never trimmed, nor tiles used during the prune"));
            }
        }
        lines.push(format!("{leaves}: {}", size(pruned.bytes_after)));
        super::print(lines.join("\n"))?;
        let mut failures: Vec<String> =
            pruned.failed.iter().map(|(v, why)| format!("stale version {} not removed: {why}", v.version)).collect();
        failures.extend(pruned.trim_failed.iter().map(|why| format!("the trim stopped: {why}")));
        match failures.is_empty() {
            true => Ok(()),
            false => anyhow::bail!("{}", failures.join("; ")),
        }
    }
}
