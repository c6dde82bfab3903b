//! Sylva's integration tests, one binary, by topic.
//!
//! Tests on real data read `../shared/data` beside the repository (CI has it);
//! they fail with a clear message when it is missing.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod cache_prune; // sylva cache: usage, stale versions removed, trims by least recent use, on a directory and on Redis
mod canopy; // LiDAR canopy proxies: CHM vs a published one, seams, tileability, bad input
mod canopy_report; // the pictures of docs/canopy.md (ignored: writes files)
mod cli; // the `sylva` binary: tile, build, info, errors that name the file
mod clients; // GDAL's WMS driver and OWSLib against the server, values against build
mod common; // shared helpers: data paths, regions, comparisons
mod config_files; // every file in config/ parses and builds its region
mod conservative; // acceleration bounds never below the surface, exhaustively
mod extreme; // stiff and extreme inputs: huge ranges, cliffs, nodata, poles, sizes
mod fly; // `sylva fly` in process and against a server; tiles over HTTP equal tiles in process
mod fly_faults; // `sylva fly` against servers without tiles or that hang, and stopped at once: what it says and leaves
mod http; // a `sylva serve` process for tests, and an HTTP client
mod real_data; // rmnp, mt_hood, storm_lake, nz_forest against their sources
mod render; // the GPU ray caster against the exact CPU reference
mod seamless; // tiles equal windows of whole-area builds; neighbours agree, in the data and the relief
mod seed; // sylva seed: cache hits identical to the server's, dry runs, coverages, kill and resume, failures
mod seed_shared; // many seeders and servers on one directory or Redis cache, shards
mod server; // the server over HTTP: WMS, tiles, cache, concurrency, bad input, shutdown
mod skipped_work; // stages nobody needs do not run (counted)
mod sources; // broken and hostile files give errors that name them
mod sse; // the flight's SSE selection: deferred equals full re-evaluation along the flyovers, fewer nodes
mod upstream; // proxy sources over HTTP: WMS and Terrarium upstreams, failures, stale tiles
mod view; // `sylva view` on a virtual X display: scripted runs, no display
