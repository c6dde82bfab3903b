// Entry points: the hull's vertices, the ray-casting fragments that start
// on them (dissertation 6.4), and plain texture mapping of the terrain mesh
// where no ray is cast.

struct HullIn {
    @location(0) sample: vec2<f32>,
    @location(1) hull: vec2<f32>,
};

struct TerrainIn {
    @location(0) sample: vec2<f32>,
    @location(1) height: f32,
    @location(2) offset: vec3<f32>,
};

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) local: vec3<f32>,
};

// Per pixel: view-ray fetches, shadow-ray fetches, the bits of the
// distance along the view axis (m), and the draw whose rays it shows
// (tile.flags.y; 0 where no ray was cast).
struct FragmentOut {
    @location(0) colour: vec4<f32>,
    @location(1) data: vec4<u32>,
    @builtin(frag_depth) depth: f32,
};

struct PlainVertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) sample: vec2<f32>,
    // Distance along the view axis, metres.
    @location(1) distance: f32,
};

// Depth is written from the distance, as for ray-cast fragments: the
// rasterised depth of a reversed-Z projection keeps its precision only
// where clip space ends at 0 (not on GL, whose −1..1 range leaves far
// distances a few float steps, so the crack-filling mesh below a ray-cast
// tile could win the depth test against it).
struct PlainOut {
    @location(0) colour: vec4<f32>,
    @location(1) data: vec4<u32>,
    @builtin(frag_depth) depth: f32,
};

fn project(local: vec3<f32>) -> vec4<f32> {
    return frame.proj * (tile.model_view * vec4<f32>(local, 1.0));
}

@vertex
fn vs_hull(v: HullIn) -> VertexOut {
    let xy = (v.sample - vec2<f32>(tile.grid.z)) * tile.grid.xy;
    var f = 1.0;
    if !CANOPY_WHOLE {
        // The far fade of the nearest sample this vertex must bound (the
        // trees' near blend only lowers the canopy: left out, it bounds).
        let d = length(vec3<f32>(xy, v.hull.y) - tile.camera.xyz) - tile.camera.w;
        f = fade_far(max(d, 0.0));
    }
    let local = vec3<f32>(xy, v.hull.x + f * (v.hull.y - v.hull.x));
    return VertexOut(project(local), local);
}

// The terrain mesh at its true place (the flat frame's point plus the
// vertex's offset), lowered by tile.range.w under ray-cast tiles.
@vertex
fn vs_plain(v: TerrainIn) -> PlainVertexOut {
    let flat = vec3<f32>((v.sample - vec2<f32>(tile.grid.z)) * tile.grid.xy, v.height - tile.range.w);
    let view = tile.model_view * vec4<f32>(flat + v.offset, 1.0);
    return PlainVertexOut(frame.proj * view, v.sample, -view.z);
}

// Where a ray crosses the cast box's slabs, in sample space: the
// parameters at which it enters (.near) and leaves (.far) each of x, y, z.
struct Slabs {
    near: vec3<f32>,
    far: vec3<f32>,
};

fn slabs(o: vec3<f32>, d: vec3<f32>) -> Slabs {
    let n = tile.grid.w;
    let lo = vec3<f32>(-1.0, -1.0, tile.range.x);
    let hi = vec3<f32>(n, n, tile.range.y);
    let inv = 1.0 / d;
    let a = (lo - o) * inv;
    let b = (hi - o) * inv;
    return Slabs(min(a, b), max(a, b));
}

// The ray's parameter interval inside the cast box, in sample space.
fn cast_box(o: vec3<f32>, d: vec3<f32>) -> vec2<f32> {
    let s = slabs(o, d);
    return vec2<f32>(max(max(s.near.x, s.near.y), s.near.z), min(min(s.far.x, s.far.y), s.far.z));
}

// Whether the view ray along `dir` comes down through the cast box from
// its top to its bottom: it crossed every height of the tile over its
// footprint, so a ray that met no ground there passed a cell without data.
// Where a side is crossed within float error of the top or the bottom (the
// parameters are measured from the camera, far from a coarse tile), it is
// taken to be crossed: the filler stays.
fn falls_through(dir: vec3<f32>) -> bool {
    let s = slabs(to_samples(tile.camera.xyz), vec3<f32>(dir.xy / tile.grid.xy, dir.z));
    let margin = 1.0e-5 * abs(s.far.z);
    let enters_top = s.near.z >= max(s.near.x, s.near.y) + margin && s.near.z >= 0.0;
    let leaves_bottom = s.far.z + margin <= min(s.far.x, s.far.y);
    return dir.z < 0.0 && enters_top && leaves_bottom && s.near.z <= s.far.z;
}

fn to_samples(p: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(p.xy / tile.grid.xy + tile.grid.z, p.z);
}

// The unit direction, in the tile frame, of the ray through this pixel's
// centre: from the pixel, not from the interpolated hull position, so it is
// the reference's ray exactly (varyings over a 1,000 km triangle drift).
fn pixel_ray(pixel: vec2<f32>) -> vec3<f32> {
    let f = frame.viewport.w;
    let camera_dir = vec3<f32>((pixel.x - 0.5 * frame.viewport.x) / f, (0.5 * frame.viewport.y - pixel.y) / f, -1.0);
    let r = mat3x3<f32>(tile.model_view[0].xyz, tile.model_view[1].xyz, tile.model_view[2].xyz);
    return normalize(transpose(r) * camera_dir);
}

// A view ray in the tile frame: where its parameter is measured from, its
// unit direction, and its hit's parameter (NO_HIT: none in this tile).
struct Ray {
    origin: vec3<f32>,
    dir: vec3<f32>,
    t: f32,
};

// The ray along `dir` from the camera cast through the tile, starting
// `t_base` metres along it (where it meets the hull, backed off a little)
// and never before the near plane. Its parameter is measured from that
// start, for precision.
fn cast_ray(dir: vec3<f32>, t_base: f32) -> Ray {
    let ds = vec3<f32>(dir.xy / tile.grid.xy, dir.z);
    let forward = -vec3<f32>(tile.model_view[0].z, tile.model_view[1].z, tile.model_view[2].z);
    let t_near = frame.viewport.z / dot(dir, forward);
    let origin = tile.camera.xyz + dir * t_base;
    let os = to_samples(origin);
    let span = cast_box(os, ds);
    let t0 = max(max(span.x, 0.0), t_near - t_base);
    let t1 = span.y;
    var t = NO_HIT;
    if t0 <= t1 {
        if LINEAR {
            t = traverse_linear(os, ds, t0, t1, frame.mode.y);
        } else {
            t = traverse_exact(os, ds, t0, t1);
        }
    }
    return Ray(origin, dir, t);
}

// The distance along the view axis of the ray's hit, metres.
fn hit_distance(ray: Ray) -> f32 {
    let view = tile.model_view * vec4<f32>(ray.origin + ray.dir * ray.t, 1.0);
    return max(-view.z, 1.0e-30);
}

// The colour, per-pixel data and depth of the ray's hit.
fn shade_hit(ray: Ray) -> FragmentOut {
    let hs = to_samples(ray.origin + ray.dir * ray.t);
    let colour = shade(hs.xy, hs.z, ray.dir);
    let distance = hit_distance(ray);
    let data = vec4<u32>(view_fetches, shadow_fetches, bitcast<u32>(distance), tile.flags.y);
    return FragmentOut(vec4<f32>(colour, 1.0), data, frame.viewport.z / distance);
}

// The ray cast of one hull fragment: its hit's colour, data and depth, or
// discarded where the ray leaves the tile without a hit. Rays start where
// they cross the hull (backed off by 0.1 % for the rasteriser's rounding),
// or at the camera when it is inside the hull.
fn ray_fragment(in: VertexOut) -> FragmentOut {
    let dir = pixel_ray(in.clip.xy);
    var t_base = 0.0;
    if tile.flags.x != MODE_INSIDE {
        t_base = max(dot(in.local - tile.camera.xyz, dir) * 0.999, 0.0);
    }
    let ray = cast_ray(dir, t_base);
    let draw = tile.flags.y - 1u;
    let pixel = vec2<u32>(in.clip.xy);
    count_cast(draw, pixel, view_fetches, leaf_cells);
    if ray.t == NO_HIT {
        discard;
    }
    let out = shade_hit(ray);
    count_shadow(draw, pixel, shadow_fetches);
    return out;
}

@fragment
fn fs_ray(in: VertexOut) -> FragmentOut {
    return ray_fragment(in);
}

@fragment
fn fs_plain(in: PlainVertexOut) -> PlainOut {
    return plain_fragment(in);
}

// The terrain mesh's fragment: map colour, lit by the sun, or discarded on
// a cell without data and, under a ray-cast tile, away from its edge and
// where the ray came down through the tile's box without meeting ground.
fn plain_fragment(in: PlainVertexOut) -> PlainOut {
    let s = in.sample;
    // A crack filler only beside the tile's edge, where cracks open, and
    // never under a hole: a ray through a crack passes beside the box.
    let last = tile.grid.w - 1.0;
    if min(min(s.x, s.y), min(last - s.x, last - s.y)) > tile.texels.y {
        discard;
    }
    if tile.flags.x == MODE_HULL && falls_through(pixel_ray(in.clip.xy)) {
        discard;
    }
    let c = clamp(vec2<i32>(floor(s)), vec2<i32>(0), vec2<i32>(i32(tile.grid.w) - 2));
    let f = clamp(s - vec2<f32>(c), vec2<f32>(0.0), vec2<f32>(1.0));
    let c00 = colour_at(c.x, c.y);
    let c10 = colour_at(c.x + 1, c.y);
    let c01 = colour_at(c.x, c.y + 1);
    let c11 = colour_at(c.x + 1, c.y + 1);
    // A cell with a corner without data (surface class 255) holds no
    // ground, as for the ray caster.
    if max(max(c00.a, c10.a), max(c01.a, c11.a)) * 255.0 > 254.5 {
        discard;
    }
    let base = mix(mix(c00.rgb, c10.rgb, f.x), mix(c01.rgb, c11.rgb, f.x), f.y);
    var lit = base;
    if frame.mode.w == 1u {
        let g = vec4<f32>(texel(c.x, c.y).y, texel(c.x + 1, c.y).y, texel(c.x, c.y + 1).y, texel(c.x + 1, c.y + 1).y);
        let lambert = max(dot(patch_normal(g, f), tile.sun.xyz), 0.0);
        lit = base * (frame.sky.a + (1.0 - frame.sky.a) * lambert);
    }
    let distance = max(in.distance, 1.0e-30);
    let data = vec4<u32>(0u, 0u, bitcast<u32>(distance), 0u);
    return PlainOut(vec4<f32>(lit, 1.0), data, frame.viewport.z / distance);
}
