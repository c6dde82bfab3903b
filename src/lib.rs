//! Sylva builds combined elevation maps (CEM: terrain plus forest canopy) on
//! demand from real elevation and land-cover data.
//!
//! The pipeline follows Figure 6.1 of the dissertation in
//! `shared/seeds/002_…`: a vegetation cover map from a map, classes or canopy
//! percentages ([`cem::landcover`]); the DEM resampled onto the tile's sample grid
//! ([`raster::resample`]); a world-anchored canopy proxy scaled by the cover and
//! added to the ground ([`canopy`], [`cem::combine`]); a surface-type channel
//! ([`cem::surface`]); and conservative ray-casting acceleration data
//! ([`cem::accel`]). [`grid`] holds the World Wind tile math, [`source`] the
//! raster and point-cloud readers, [`encode`] the tile formats, [`lidar`]
//! the canopy proxies built from LiDAR (`sylva canopy`) and [`demo`] the
//! embedded procedural region used when no configuration is given. The
//! client ([`client`]) flies over the tiles, ray casting them on the GPU;
//! [`lod`] selects its levels of detail under a frame budget.
//!
//! See `ARCHITECTURE.md` for the code map and the invariants.

pub mod bench;
pub mod cache;
pub mod canopy;
pub mod cem;
pub mod client;
pub mod config;
pub mod demo;
pub mod encode;
pub mod geo;
pub mod grid;
pub mod interrupt;
pub mod lidar;
pub mod lod;
pub mod noise;
pub mod outputs;
pub mod produce;
pub mod raster;
pub mod region;
#[cfg(feature = "server")]
pub mod seed;
#[cfg(feature = "server")]
pub mod server;
pub mod source;
