// Trees near the camera as point splats (issue 7; paper 000 §5): each splat
// is a camera-facing disc, drawn as an instanced quad in its tile's frame
// and shaded as a small sphere (src/client/trees.rs places them). A splat's
// opacity fades it out toward the edge of the tree range, where the
// ray-cast canopy fades in (surface.wgsl): a screen-door keeps depth writes
// exact without sorting. Lighting follows the canopy's: ambient plus the
// sun, shadowed by the terrain toward the sun: shade.wgsl's shadow() at the
// splat's centre, once per splat in a compute pass before the frame's
// render pass (cs_splat_light), which the quad's four vertices read.

struct SplatIn {
    // Centre, tile-local metres.
    @location(0) centre: vec3<f32>,
    // Radius, metres.
    @location(1) radius: f32,
    // sRGB colour; alpha: opacity.
    @location(2) colour: vec4<f32>,
    // Light reaching the centre through the terrain, in [0, 1]
    // (cs_splat_light, a second instance buffer).
    @location(3) light: f32,
};

struct SplatOut {
    @builtin(position) clip: vec4<f32>,
    // Position on the disc, −1..1 on both axes.
    @location(0) disc: vec2<f32>,
    @location(1) @interpolate(flat) colour: vec4<f32>,
    // Centre in camera space; radius.
    @location(2) @interpolate(flat) centre: vec4<f32>,
    // Light reaching the centre through the terrain, in [0, 1].
    @location(3) @interpolate(flat) light: f32,
};

// The quad covers the disc's pixels in the plane of the sphere's nearest
// point, a radius nearer than its centre (but not before the near plane):
// the depth a fragment writes (the sphere's, fs_splat) then lies at or
// behind the quad's, as fs_splat_early promises (and clamps to where the
// quad stops short).
@vertex
fn vs_splat(@builtin(vertex_index) v: u32, s: SplatIn) -> SplatOut {
    let disc = vec2<f32>(f32(v & 1u), f32(v >> 1u)) * 2.0 - 1.0;
    let centre = (tile.model_view * vec4<f32>(s.centre, 1.0)).xyz;
    let z = max(-centre.z, 1.0e-30);
    let front = max(z - s.radius, min(z, 1.001 * frame.viewport.z));
    let corner = vec3<f32>((centre.xy + disc * s.radius) * (front / z), -front);
    return SplatOut(frame.proj * vec4<f32>(corner, 1.0), disc, s.colour, vec4<f32>(centre, s.radius), s.light);
}

// The frame's splats as 32-bit words, SPLAT_WORDS each (the centre first:
// trees.rs's Splat), and the light each receives.
const SPLAT_WORDS: u32 = 5u;
@group(2) @binding(0) var<storage, read> splat_words: array<f32>;
@group(2) @binding(1) var<storage, read_write> splat_lights: array<f32>;

// The light of the tile's splats, one invocation per splat.
@compute @workgroup_size(64)
fn cs_splat_light(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= tile.splats.y {
        return;
    }
    let k = tile.splats.x + id.x;
    let w = k * SPLAT_WORDS;
    let at = to_samples(vec3<f32>(splat_words[w], splat_words[w + 1u], splat_words[w + 2u]));
    var light = 1.0;
    if frame.mode.w == 1u {
        light = shadow(at.xy, at.z, tile.sun.xyz);
    }
    splat_lights[k] = light;
}

// A hash of the pixel in [0, 1): the screen door's threshold.
fn pixel_hash(p: vec2<u32>) -> f32 {
    var h = p.x * 0x8da6b343u ^ p.y * 0xd8163841u;
    h = (h ^ (h >> 15u)) * 0x2c1b3c6du;
    h = h ^ (h >> 12u);
    return f32(h >> 8u) / 16777216.0;
}

@fragment
fn fs_splat(in: SplatOut) -> FragmentOut {
    return splat_fragment(in);
}

// A splat's fragment: a lit sphere's, behind a screen door; outside the disc
// or the door, discarded.
fn splat_fragment(in: SplatOut) -> FragmentOut {
    let r2 = dot(in.disc, in.disc);
    if r2 > 1.0 || pixel_hash(vec2<u32>(in.clip.xy)) >= in.colour.a {
        discard;
    }
    let bulge = sqrt(1.0 - r2);
    let normal = vec3<f32>(in.disc, bulge);
    let distance = max(-in.centre.z - bulge * in.centre.w, 1.0e-30);
    var colour = in.colour.rgb;
    if frame.mode.w == 1u {
        let r = mat3x3<f32>(tile.model_view[0].xyz, tile.model_view[1].xyz, tile.model_view[2].xyz);
        let lambert = max(dot(normal, r * tile.sun.xyz), 0.0);
        let ambient = frame.sky.a;
        colour = colour * frame.canopy_tint.rgb * (ambient + (1.0 - ambient) * in.light * (0.5 + 0.5 * lambert));
    }
    let data = vec4<u32>(0u, 0u, bitcast<u32>(distance), 0u);
    return FragmentOut(vec4<f32>(colour, 1.0), data, frame.viewport.z / distance);
}
