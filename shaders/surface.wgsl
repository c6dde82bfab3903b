// The surface the rays meet (src/client/raycast.rs): per cell the bilinear
// patch of its corners' ground + f * canopy, f fading the canopy with the
// corner's distance from the camera (out far away, and in from under the
// trees drawn as splats near the camera); and the exact ray-patch
// intersection.

fn smoothstep01(lo: f32, hi: f32, x: f32) -> f32 {
    let t = clamp((x - lo) / (hi - lo), 0.0, 1.0);
    return t * t * (3.0 - 2.0 * t);
}

// Canopy factor of the far fade at `distance` metres from the camera: it
// never grows with distance, so the nearest distance bounds it.
fn fade_far(distance: f32) -> f32 {
    let px = frame.fade.x * frame.fade.w / max(distance, 1.0e-9);
    return smoothstep01(frame.fade.y, frame.fade.z, px);
}

// Canopy factor at `distance` metres from the camera: the far fade times
// the share the trees' splats leave to the canopy (raycast::Fade::factor).
fn fade_factor(distance: f32) -> f32 {
    var near = 1.0;
    if frame.trees.x > 0.0 {
        let band = max(frame.trees.y, 1.0e-6);
        let splat = 1.0 - smoothstep01(frame.trees.x - 0.5 * band, frame.trees.x + 0.5 * band, distance);
        near = 1.0 - drawn_at(distance) * splat;
    }
    return fade_far(distance) * near;
}

// The share of trees drawn at `distance` metres (raycast::TreeBlend::drawn_at).
fn drawn_at(distance: f32) -> f32 {
    let x = clamp(distance / frame.trees.z, 0.0, 15.0);
    let k = min(u32(x), 14u);
    let t = x - f32(k);
    let a = frame.tree_drawn[k / 4u][k % 4u];
    let b = frame.tree_drawn[(k + 1u) / 4u][(k + 1u) % 4u];
    return mix(a, b, t);
}

fn sample_local(s: vec2<f32>, z: f32) -> vec3<f32> {
    return vec3<f32>((s - vec2<f32>(tile.grid.z)) * tile.grid.xy, z);
}

// Corner heights [h00, h10, h01, h11] of the cell whose south-west sample
// is (ci, cj), with the canopy faded; any nodata corner gives NODATA.
fn cell_heights(ci: i32, cj: i32, counter: ptr<private, u32>) -> vec4<f32> {
    if all(vec2<i32>(ci, cj) == memo_cell) {
        return memo_heights;
    }
    memo_cell = vec2<i32>(ci, cj);
    memo_heights = fetch_cell_heights(ci, cj, counter);
    return memo_heights;
}

fn fetch_cell_heights(ci: i32, cj: i32, counter: ptr<private, u32>) -> vec4<f32> {
    let size = f32(tile.index.y);
    let b = tile.index.x;
    let uv = (vec2<f32>(vec2<i32>(ci + b, cj + b)) + 1.0) / size;
    let c = cem_corners(uv, counter);
    if min(min(c.x, c.y), min(c.z, c.w)) <= NODATA_BELOW {
        return vec4<f32>(NODATA_BELOW * 10.0);
    }
    if CANOPY_WHOLE {
        return c;
    }
    // The ground under the canopy only where the canopy fades.
    let g = ground_corners(uv, counter);
    let cam = tile.camera.xyz;
    let s = vec2<f32>(f32(ci), f32(cj));
    let f = vec4<f32>(
        fade_factor(length(sample_local(s, g.x) - cam)),
        fade_factor(length(sample_local(s + vec2<f32>(1.0, 0.0), g.y) - cam)),
        fade_factor(length(sample_local(s + vec2<f32>(0.0, 1.0), g.z) - cam)),
        fade_factor(length(sample_local(s + vec2<f32>(1.0, 1.0), g.w) - cam)),
    );
    return g + f * (c - g);
}

// The cell's corners at `uv` of the CEM (ground_corners: of the ground), in
// the order h00, h10, h01, h11, blended with the coarser surface's when the
// tile morphs (its nodata is the tile's own, so nodata stays nodata; a tile
// without a morph layer drawn by a morphing pipeline reads its own). Two
// functions: a gather's channel must be a constant.
fn cem_corners(uv: vec2<f32>, counter: ptr<private, u32>) -> vec4<f32> {
    let own = textureGather(0, texels, gather_sampler, uv, tile.index.z);
    if !MORPHING || tile.flags.w == 0u {
        *counter += 1u;
        return corner_order(own);
    }
    *counter += 2u;
    return corner_order(mix(textureGather(0, morph_from, gather_sampler, uv, morph_layer()), own, tile.morph.x));
}

fn ground_corners(uv: vec2<f32>, counter: ptr<private, u32>) -> vec4<f32> {
    let own = textureGather(1, texels, gather_sampler, uv, tile.index.z);
    if !MORPHING || tile.flags.w == 0u {
        *counter += 1u;
        return corner_order(own);
    }
    *counter += 2u;
    return corner_order(mix(textureGather(1, morph_from, gather_sampler, uv, morph_layer()), own, tile.morph.x));
}

// A gather's texels, (i, j+1), (i+1, j+1), (i+1, j), (i, j), as h00, h10,
// h01, h11.
fn corner_order(v: vec4<f32>) -> vec4<f32> {
    return vec4<f32>(v.w, v.z, v.x, v.y);
}

fn has_data(h: vec4<f32>) -> bool {
    return h.x > NODATA_BELOW;
}

fn bilinear(h: vec4<f32>, f: vec2<f32>) -> f32 {
    let south = h.x + (h.y - h.x) * f.x;
    let north = h.z + (h.w - h.z) * f.x;
    return south + (north - south) * f.y;
}

// Surface height at fractional sample `s`, or NODATA where the cell is
// outside the texels or has no data.
fn height_at(s: vec2<f32>, counter: ptr<private, u32>) -> f32 {
    let c = vec2<i32>(floor(s));
    let b = tile.index.x;
    let last = tile.index.y - b - 2;
    if c.x < -b || c.y < -b || c.x > last || c.y > last {
        return NODATA_BELOW * 10.0;
    }
    let h = cell_heights(c.x, c.y, counter);
    if !has_data(h) {
        return NODATA_BELOW * 10.0;
    }
    return bilinear(h, s - vec2<f32>(c));
}

// The first tau in [0, len] where the ray at cell fraction `f`, height `z0`,
// moving `d` (samples and metres per metre), is at or below the patch `h`;
// NO_HIT if none. The roots of reference::patch_hit, without its separate
// linear case (one branch less for every lane of a software rasteriser).
fn patch_hit(h: vec4<f32>, f: vec2<f32>, d: vec3<f32>, z0: f32, len: f32) -> f32 {
    let e = h.x - h.y - h.z + h.w;
    let hx = h.y - h.x;
    let hy = h.z - h.x;
    let c = bilinear(h, f) - z0;
    if c >= 0.0 {
        return 0.0;
    }
    let b = hx * d.x + hy * d.y + e * (f.x * d.y + f.y * d.x) - d.z;
    let a = e * d.x * d.y;
    var root = NO_HIT;
    // The numerically stable pair of roots; c / q is also the root of the
    // linear case (a = 0), where q / a is none.
    let disc = b * b - 4.0 * a * c;
    if disc >= 0.0 {
        let q = -0.5 * (b + select(-1.0, 1.0, b >= 0.0) * sqrt(disc));
        let r1 = select(1.0e30, q / a, a != 0.0);
        let r2 = select(1.0e30, c / q, q != 0.0);
        let lo = min(r1, r2);
        let hi = max(r1, r2);
        if lo >= 0.0 && lo <= len {
            root = lo;
        } else if hi >= 0.0 && hi <= len {
            root = hi;
        }
    }
    if root >= 0.0 && root <= len {
        return root;
    }
    // Rounding may hide a root that the end point shows.
    let g_end = (a * len + b) * len + c;
    if g_end >= 0.0 {
        return len * -c / (g_end - c);
    }
    return NO_HIT;
}
