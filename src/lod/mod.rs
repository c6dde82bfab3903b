//! Level-of-detail selection (issue 7): pure math, no I/O, no tokio, no wgpu.
//! (Interface guide below; filled in as the modules land.)

pub mod calibrate;
pub mod deferral;
pub mod model;
pub mod morph;
pub mod optimizer;
pub mod predict;
pub mod quadtree;
pub mod splats;
pub mod split;
