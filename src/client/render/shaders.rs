//! The table of WGSL sources under `shaders/`. WGSL has no includes, so a
//! module is a concatenation of them: the shared declarations and the ray
//! casting's functions, then the parts of one way of drawing. The fragment
//! module (hull fragments, plain meshes, splats) reads its tile from a
//! uniform at a dynamic offset, and holds the entry point that needs
//! `SHADER_EARLY_DEPTH_TEST` only where the device has it; the compute
//! module casts rays in a compute pass and reads its tiles from an array;
//! the window's module stands alone.

/// `(file name, source)` of the parts both modules share, in order.
pub const SHARED_PARTS: [(&str, &str); 5] = [
    ("common.wgsl", include_str!("../../../shaders/common.wgsl")),
    ("surface.wgsl", include_str!("../../../shaders/surface.wgsl")),
    ("traverse.wgsl", include_str!("../../../shaders/traverse.wgsl")),
    ("shade.wgsl", include_str!("../../../shaders/shade.wgsl")),
    ("raycast.wgsl", include_str!("../../../shaders/raycast.wgsl")),
];

/// The fragment module's own parts.
pub const FRAGMENT_PARTS: [(&str, &str); 2] = [
    ("tile_uniform.wgsl", include_str!("../../../shaders/tile_uniform.wgsl")),
    ("splat.wgsl", include_str!("../../../shaders/splat.wgsl")),
];

/// Hull ray casting, terrain meshes and splats with a conservative depth
/// promise.
pub const EARLY_DEPTH_PART: (&str, &str) = ("early_depth.wgsl", include_str!("../../../shaders/early_depth.wgsl"));

/// Counting every ray's work (`render/work.rs`), and its stand-in that
/// counts nothing: a module holds one of them.
pub const WORK_PARTS: [(&str, &str); 2] = [
    ("work_count.wgsl", include_str!("../../../shaders/work_count.wgsl")),
    ("work_none.wgsl", include_str!("../../../shaders/work_none.wgsl")),
];

/// The compute module's own part.
pub const COMPUTE_PART: (&str, &str) = ("compute.wgsl", include_str!("../../../shaders/compute.wgsl"));

/// The window's module: a rendered frame copied to the screen
/// (`sylva view`).
pub const PRESENT: (&str, &str) = ("present.wgsl", include_str!("../../../shaders/present.wgsl"));

/// The fragment module's source, with [`EARLY_DEPTH_PART`] if
/// `early_depth`, counting its rays' work if `counted`.
pub fn raycast_source(early_depth: bool, counted: bool) -> String {
    let extra = early_depth.then_some(&EARLY_DEPTH_PART);
    join(SHARED_PARTS.iter().chain(&FRAGMENT_PARTS).chain(extra).chain([work_part(counted)]))
}

/// The compute module's source, counting its rays' work if `counted`.
pub fn compute_source(counted: bool) -> String {
    join(SHARED_PARTS.iter().chain([&COMPUTE_PART, work_part(counted)]))
}

fn work_part(counted: bool) -> &'static (&'static str, &'static str) {
    &WORK_PARTS[usize::from(!counted)]
}

fn join<'a>(parts: impl Iterator<Item = &'a (&'a str, &'a str)>) -> String {
    parts.map(|(_, s)| *s).collect::<Vec<_>>().join("\n")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn validated(source: &str) -> naga::Module {
        let module = match naga::front::wgsl::parse_str(source) {
            Ok(m) => m,
            Err(e) => panic!("{}", e.emit_to_string(source)),
        };
        let mut validator =
            naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all());
        if let Err(e) = validator.validate(&module) {
            panic!("{}", e.emit_to_string(source));
        }
        module
    }

    /// Every module parses and validates with naga, no GPU needed: the
    /// fragment module with and without the early-depth entry point, and
    /// the compute module, and the window's.
    #[test]
    fn shaders_validate() {
        for (early_depth, counted) in [(false, false), (true, false), (false, true), (true, true)] {
            let module = validated(&raycast_source(early_depth, counted));
            for name in ["fs_ray_hull", "fs_plain_early", "fs_splat_early"] {
                assert_eq!(module.entry_points.iter().any(|e| e.name == name), early_depth, "{name}");
            }
            assert_eq!(module.global_variables.iter().any(|(_, v)| v.name.as_deref() == Some("work")), counted);
        }
        for counted in [false, true] {
            let module = validated(&compute_source(counted));
            assert!(module.entry_points.iter().any(|e| e.name == "cs_rays"));
        }
        let module = validated(PRESENT.1);
        assert_eq!(module.entry_points.len(), 2);
    }
}
