// Ray casting from the hull's front faces with a promise to the GPU: a ray
// enters the hull before it meets the surface the hull bounds, so its depth
// is never nearer than the hull's (reversed Z: less or equal). The GPU may
// then reject a fragment hidden behind nearer tiles before its ray is cast.
// The ray starts a hair before the hull (raycast.wgsl); a hit there takes
// the hull's depth, so the promise holds exactly.
// Compiled only where the device has `SHADER_EARLY_DEPTH_TEST`
// (render/shaders.rs).

@fragment @early_depth_test(less_equal)
fn fs_ray_hull(in: VertexOut) -> FragmentOut {
    var out = ray_fragment(in);
    out.depth = min(out.depth, in.clip.z);
    return out;
}
