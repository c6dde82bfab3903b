//! Per-request accounting of pipeline stages: how often each ran and how long
//! it took. Tests use the counts to prove that work nobody needs is skipped;
//! `sylva bench pipeline` prints the times.

use std::time::{Duration, Instant};

/// The stages of Figure 6.1, in pipeline order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Stage {
    /// b: the DEM resampled onto the grid.
    Elevation,
    /// a: land-cover pixels read (and derived, on a cache miss) for the grid.
    Landcover,
    /// a: the cover map resampled onto the grid.
    Cover,
    /// c: the canopy proxy evaluated and scaled by the cover.
    Canopy,
    /// c: ground plus canopy.
    Combine,
    /// The surface-type channel.
    Surface,
    /// d: safety zones.
    Zones,
}

impl Stage {
    /// All stages in order.
    pub const ALL: [Stage; 7] =
        [Stage::Elevation, Stage::Landcover, Stage::Cover, Stage::Canopy, Stage::Combine, Stage::Surface, Stage::Zones];

    /// Short name for tables.
    pub fn name(self) -> &'static str {
        match self {
            Stage::Elevation => "elevation",
            Stage::Landcover => "landcover",
            Stage::Cover => "cover",
            Stage::Canopy => "canopy",
            Stage::Combine => "combine",
            Stage::Surface => "surface",
            Stage::Zones => "zones",
        }
    }
}

/// Runs and time per stage for one request.
#[derive(Clone, Debug, Default)]
pub struct Stats {
    runs: [u32; 7],
    time: [Duration; 7],
}

impl Stats {
    /// Runs `f` as `stage`, counting and timing it.
    pub fn time<T>(&mut self, stage: Stage, f: impl FnOnce() -> T) -> T {
        let start = Instant::now();
        let out = f();
        let i = stage as usize;
        self.runs[i] += 1;
        self.time[i] += start.elapsed();
        out
    }

    /// How many times `stage` ran.
    pub fn runs(&self, stage: Stage) -> u32 {
        self.runs[stage as usize]
    }

    /// Time spent in `stage`.
    pub fn elapsed(&self, stage: Stage) -> Duration {
        self.time[stage as usize]
    }

    /// Time spent in all stages.
    pub fn total(&self) -> Duration {
        self.time.iter().sum()
    }
}

/// The runs and times of two computations of one request.
impl std::ops::AddAssign for Stats {
    fn add_assign(&mut self, other: Stats) {
        for i in 0..self.runs.len() {
            self.runs[i] += other.runs[i];
            self.time[i] += other.time[i];
        }
    }
}
