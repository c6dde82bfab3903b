// Shows a rendered frame in a window: one triangle covering the surface,
// each pixel reading the renderer's colour target at the same position
// (the frame is rendered at the window's size). The colour target holds
// sRGB-encoded bytes: they pass unchanged to a plain surface, and are
// decoded to linear for an sRGB surface, which encodes them again.

// 1 when the surface format is sRGB.
override SRGB_TARGET: f32 = 0.0;

@group(0) @binding(0) var frame_colour: texture_2d<f32>;

@vertex
fn vs_present(@builtin(vertex_index) k: u32) -> @builtin(position) vec4<f32> {
    let uv = vec2<f32>(f32((k << 1u) & 2u), f32(k & 2u));
    return vec4<f32>(uv * 2.0 - 1.0, 0.0, 1.0);
}

fn srgb_to_linear(c: vec3<f32>) -> vec3<f32> {
    let low = c / 12.92;
    let high = pow((c + 0.055) / 1.055, vec3<f32>(2.4));
    return select(high, low, c <= vec3<f32>(0.04045));
}

@fragment
fn fs_present(@builtin(position) at: vec4<f32>) -> @location(0) vec4<f32> {
    let size = vec2<i32>(textureDimensions(frame_colour));
    let texel = min(vec2<i32>(at.xy), size - 1);
    let c = textureLoad(frame_colour, texel, 0).rgb;
    return vec4<f32>(select(c, srgb_to_linear(c), SRGB_TARGET > 0.5), 1.0);
}
