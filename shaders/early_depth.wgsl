// Fragments that promise the GPU their depth is never nearer than the
// rasterised one (reversed Z: less or equal), so that it may reject those
// hidden behind nearer surfaces before they run. Compiled only where the
// device has `SHADER_EARLY_DEPTH_TEST` (render/shaders.rs).

// Ray casting from the hull's front faces: a ray
// enters the hull before it meets the surface the hull bounds, so its depth
// is never nearer than the hull's (reversed Z: less or equal). The GPU may
// then reject a fragment hidden behind nearer tiles before its ray is cast.
// The ray starts a hair before the hull (raycast.wgsl); a hit there takes
// the hull's depth, so the promise holds exactly.

@fragment @early_depth_test(less_equal)
fn fs_ray_hull(in: VertexOut) -> FragmentOut {
    var out = ray_fragment(in);
    out.depth = min(out.depth, in.clip.z);
    return out;
}

// The terrain mesh: its depth is the rasterised one computed from the
// distance (raycast.wgsl), equal but for rounding, which the clamp settles.
// Crack fillers under ray-cast tiles are hidden almost everywhere.
@fragment @early_depth_test(less_equal)
fn fs_plain_early(in: PlainVertexOut) -> PlainOut {
    var out = plain_fragment(in);
    out.depth = min(out.depth, in.clip.z);
    return out;
}

// Trees' splats: the quad lies in the plane of the sphere's nearest point
// (splat.wgsl), so a splat hidden behind the canopy or a nearer splat need
// not run.
@fragment @early_depth_test(less_equal)
fn fs_splat_early(in: SplatOut) -> FragmentOut {
    var out = splat_fragment(in);
    out.depth = min(out.depth, in.clip.z);
    return out;
}
