//! The table of WGSL sources under `shaders/`. WGSL has no includes, so the
//! ray-casting module is their concatenation in this order: shared
//! declarations first, entry points last.

/// `(file name, source)` in module order.
pub const RAYCAST_PARTS: [(&str, &str); 6] = [
    ("common.wgsl", include_str!("../../../shaders/common.wgsl")),
    ("surface.wgsl", include_str!("../../../shaders/surface.wgsl")),
    ("traverse.wgsl", include_str!("../../../shaders/traverse.wgsl")),
    ("shade.wgsl", include_str!("../../../shaders/shade.wgsl")),
    ("raycast.wgsl", include_str!("../../../shaders/raycast.wgsl")),
    ("splat.wgsl", include_str!("../../../shaders/splat.wgsl")),
];

/// The ray-casting module's source.
pub fn raycast_source() -> String {
    RAYCAST_PARTS.iter().map(|(_, s)| *s).collect::<Vec<_>>().join("\n")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every shader parses and validates with naga, no GPU needed.
    #[test]
    fn shaders_validate() {
        let source = raycast_source();
        let module = match naga::front::wgsl::parse_str(&source) {
            Ok(m) => m,
            Err(e) => panic!("{}", e.emit_to_string(&source)),
        };
        let mut validator =
            naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all());
        if let Err(e) = validator.validate(&module) {
            panic!("{}", e.emit_to_string(&source));
        }
    }
}
