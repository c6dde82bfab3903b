//! The client: a World-Wind-style quadtree flyover of CEM tiles, ray cast
//! per pixel (dissertation 6.4).
//!
//! The pure parts — the ellipsoid ([`globe`]), tile frames ([`frame`]), the
//! camera ([`camera`]), prepared tiles and their hulls ([`tile`],
//! [`hull`]), the ray-casting model shared by both ray casters
//! ([`raycast`]), the exact CPU reference ([`reference`](mod@reference)) and the LOD
//! selection under a frame budget ([`lod`]) and the trees drawn as splats
//! near the camera ([`trees`]) — know nothing of wgpu; the GPU
//! path lives in `render` (feature `client`).
//!
//! Positions are `f64` on the CPU; the GPU sees tile-local `f32` values only.

pub mod camera;
pub mod cull;
pub mod envelope;
#[cfg(feature = "client")]
pub mod fly;
pub mod frame;
pub mod globe;
#[cfg(feature = "http")]
pub mod http;
pub mod hull;
pub mod lod;
pub mod path;
pub mod quadtree;
pub mod raycast;
pub mod reference;
#[cfg(feature = "client")]
pub mod render;
pub mod source;
pub mod sse;
pub mod store;
pub mod terrain;
pub mod tile;
pub mod tiletree;
pub mod trees;
#[cfg(feature = "window")]
pub mod view;
