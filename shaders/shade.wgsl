// Shading by surface type and soft shadows accumulated toward the sun
// (dissertation 6.4, "Illumination Calculation", "Other Surface Types").
// Mirrors src/client/raycast.rs: shade() and shadow().

const CLASS_FOREST: u32 = 1u;
const CLASS_WATER: u32 = 2u;
// raycast::WATER_MIN_NORMAL_Z: the cosine of 15°.
const WATER_MIN_NORMAL_Z: f32 = 0.966;

// Light reaching the hit at sample `s`, height `z`, through the terrain
// toward the sun: samples at horizontal distances growing linearly step by
// step up to the halo; near occluders weigh more. The tile's quality sets n.
fn shadow(s: vec2<f32>, z: f32, sun: vec3<f32>) -> f32 {
    let per_m = sun.xy / tile.grid.xy;
    let horizontal = length(per_m);
    let n = tile.flags.z;
    if n == 0u || horizontal < 1.0e-9 {
        return 1.0;
    }
    let nf = f32(n);
    let s0 = 2.0 * tile.sun.w / (nf * (nf + 1.0));
    var occlusion = 0.0;
    for (var k = 1u; k <= n; k++) {
        let kf = f32(k);
        let t = s0 * kf * (kf + 1.0) / 2.0 / horizontal;
        let zq = z + sun.z * t;
        if zq > tile.texels.x {
            break;
        }
        let h = height_at(s + per_m * t, &shadow_fetches);
        if h > NODATA_BELOW {
            occlusion += frame.shadow.x / kf * clamp((h - zq) / frame.shadow.y, 0.0, 1.0);
        }
    }
    return clamp(1.0 - occlusion, 0.0, 1.0);
}

fn colour_at(i: i32, j: i32) -> vec4<f32> {
    let b = tile.index.x;
    let last = tile.index.y - 1;
    let c = clamp(vec2<i32>(i + b, j + b), vec2<i32>(0), vec2<i32>(last));
    return textureLoad(colours, c, tile.index.z, 0);
}

fn patch_normal(h: vec4<f32>, f: vec2<f32>) -> vec3<f32> {
    let dx = ((h.y - h.x) * (1.0 - f.y) + (h.w - h.z) * f.y) / tile.grid.x;
    let dy = ((h.z - h.x) * (1.0 - f.x) + (h.w - h.y) * f.x) / tile.grid.y;
    return normalize(vec3<f32>(-dx, -dy, 1.0));
}

fn water(base: vec3<f32>, dir: vec3<f32>, sun: vec3<f32>, sun_on: bool, light: f32) -> vec3<f32> {
    let cosine = clamp(-dir.z, 0.0, 1.0);
    let fresnel = 0.02 + 0.98 * pow(1.0 - cosine, 5.0);
    var glint = 0.0;
    if sun_on {
        glint = pow(max(dot(vec3<f32>(dir.xy, -dir.z), sun), 0.0), 64.0) * 0.8 * light;
    }
    return base * 0.8 * (1.0 - fresnel) + frame.sky.rgb * fresnel + glint;
}

// Colour of the surface at sample `s`, height `z`, seen along `dir`.
fn shade(s: vec2<f32>, z: f32, dir: vec3<f32>) -> vec3<f32> {
    let n1 = i32(tile.grid.w) - 1;
    let c = clamp(vec2<i32>(floor(s)), vec2<i32>(-1), vec2<i32>(n1));
    let f = s - vec2<f32>(c);
    let c00 = colour_at(c.x, c.y);
    let c10 = colour_at(c.x + 1, c.y);
    let c01 = colour_at(c.x, c.y + 1);
    let c11 = colour_at(c.x + 1, c.y + 1);
    let base = mix(mix(c00.rgb, c10.rgb, f.x), mix(c01.rgb, c11.rgb, f.x), f.y);
    let nearest = vec2<i32>(floor(s + 0.5));
    let surface = u32(round(colour_at(nearest.x, nearest.y).a * 255.0));
    var h = cell_heights(c.x, c.y, &view_fetches);
    if !has_data(h) {
        h = vec4<f32>(z);
    }
    let normal = patch_normal(h, f);
    // Water is flat: water classes on slopes are misclassified shadows.
    let flat_water = surface == CLASS_WATER && normal.z >= WATER_MIN_NORMAL_Z;
    if frame.mode.w != 1u {
        if flat_water {
            return water(base, dir, vec3<f32>(0.0), false, 1.0);
        }
        return base;
    }
    let sun = tile.sun.xyz;
    // From the surface, never from under it: a ray that entered the cast
    // range through a side below the surface (the crack between two flat
    // frames, metres deep near a pole) is lit as the surface above it.
    let light = shadow(s, max(z, bilinear(h, f)), sun);
    let lambert = max(dot(normal, sun), 0.0);
    let ambient = frame.sky.a;
    if surface == CLASS_FOREST {
        let l = ambient + (1.0 - ambient) * light * (0.6 + 0.4 * lambert);
        return base * frame.canopy_tint.rgb * l;
    }
    let lit = base * (ambient + (1.0 - ambient) * light * lambert);
    if flat_water {
        return water(lit, dir, sun, true, light);
    }
    return lit;
}
