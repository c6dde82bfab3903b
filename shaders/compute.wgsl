// Ray casting in a compute pass instead of hull fragments (render/compute.rs,
// RayPass::Compute), for GPUs that shade fragments on a small part of the
// chip: a data-centre GPU such as the H200 runs fragment shaders on a few of
// its multiprocessors and compute shaders on all of them.
//
// One invocation per pixel. The screen is cut into bins of BIN_PX² pixels;
// each bin lists the ray-cast tiles whose box covers any of its pixels,
// nearest first (built on the CPU each frame). A pixel casts its ray
// through each listed tile whose box it sees, from where the ray enters the
// box, skipping tiles whose box starts beyond the nearest hit so far (and
// stopping at the first whose box lies wholly beyond it), and
// shades the nearest hit once: what the depth test picks among hull
// fragments, without their overdraw. A full-screen triangle (fs_fill) then
// writes the hits' depth, so that the terrain meshes and splats drawn after
// (if any) are hidden behind them.

// The tiles' blocks, TILE_STRIDE (256 bytes) apart, and the one this
// invocation casts through (common.wgsl reads `tile`). The padding is
// spelled out: GL's backend does not honour a member's @size.
struct TileSlot {
    block: Tile,
    pad: vec4<f32>,
};
@group(1) @binding(0) var<storage, read> tiles: array<TileSlot>;
var<private> tile: Tile;

// bins[0]: bins per row; bins[1 + b] .. bins[2 + b]: where bin b's draw
// indices lie in the same array.
@group(2) @binding(0) var<storage, read> bins: array<u32>;
@group(2) @binding(1) var colour_out: texture_storage_2d<rgba8unorm, write>;
@group(2) @binding(2) var data_out: texture_storage_2d<rgba32uint, write>;
@group(2) @binding(3) var ray_data: texture_2d<u32>;

const BIN_PX: u32 = 32u;
const FAR: f32 = 3.0e38;
// Relative slack of the test that a tile's box starts beyond the nearest
// hit: a hit on the box's face (a ray entering where the surface meets the
// face) is computed two ways that round apart.
const BOX_SLACK: f32 = 1.0e-4;

// Casts through tile `draw` from now on; the memo of corner heights
// (common.wgsl) belongs to the last tile.
fn use_tile(draw: u32) {
    tile = tiles[draw].block;
    memo_cell = vec2<i32>(-2147483647);
}

// Where the ray along `dir` enters the tile's box (metres from the camera;
// 0 when it starts inside), or -1 if it misses the box.
fn box_entry(dir: vec3<f32>) -> f32 {
    let span = cast_box(to_samples(tile.camera.xyz), vec3<f32>(dir.xy / tile.grid.xy, dir.z));
    if span.x > span.y || span.y < 0.0 {
        return -1.0;
    }
    return max(span.x, 0.0);
}

// The view-axis distance of the point `t` metres along `dir`.
fn axis_distance(dir: vec3<f32>, t: f32) -> f32 {
    return t * dot(dir, -vec3<f32>(tile.model_view[0].z, tile.model_view[1].z, tile.model_view[2].z));
}

@compute @workgroup_size(8, 8)
fn cs_rays(@builtin(global_invocation_id) id: vec3<u32>) {
    let p = id.xy;
    if p.x >= u32(frame.viewport.x) || p.y >= u32(frame.viewport.y) {
        return;
    }
    let pixel = vec2<f32>(p) + 0.5;
    // The cosine of the ray to the view axis: a point d metres along it
    // lies d * axis_cos along the axis.
    let f = frame.viewport.w;
    let axis_cos = 1.0 / length(vec3<f32>((pixel.x - 0.5 * frame.viewport.x) / f, (0.5 * frame.viewport.y - pixel.y) / f, 1.0));
    let bin = (p.y / BIN_PX) * bins[0] + p.x / BIN_PX;
    var best = FAR;
    var best_draw = 0u;
    var best_base = 0.0;
    var best_t = NO_HIT;
    for (var i = bins[1u + bin]; i < bins[2u + bin]; i++) {
        let draw = bins[i];
        // The list is nearest box first: once a box is wholly beyond the
        // nearest hit, so are the rest.
        if tiles[draw].block.near.x * axis_cos > best * (1.0 + BOX_SLACK) {
            break;
        }
        let screen = tiles[draw].block.screen;
        if any(p < screen.xy) || any(p >= screen.zw) {
            continue;
        }
        use_tile(draw);
        let dir = pixel_ray(pixel);
        let entry = box_entry(dir);
        if entry < 0.0 || axis_distance(dir, entry) > best * (1.0 + BOX_SLACK) {
            continue;
        }
        let before = vec2<u32>(view_fetches, leaf_cells);
        let ray = cast_ray(dir, entry * 0.999);
        // Counted by the draw's index among the frame's draws, as the pixel
        // data name it (`draw` is its place in the nearest-first order).
        count_cast(tile.flags.y - 1u, p, view_fetches - before.x, leaf_cells - before.y);
        if ray.t != NO_HIT {
            let d = hit_distance(ray);
            if d < best {
                best = d;
                best_draw = draw + 1u;
                best_base = entry * 0.999;
                best_t = ray.t;
            }
        }
    }
    if best_draw == 0u {
        textureStore(colour_out, p, vec4<f32>(frame.sky.rgb, 1.0));
        textureStore(data_out, p, vec4<u32>(0u));
        return;
    }
    use_tile(best_draw - 1u);
    let dir = pixel_ray(pixel);
    let out = shade_hit(Ray(tile.camera.xyz + dir * best_base, dir, best_t));
    count_shadow(tile.flags.y - 1u, p, shadow_fetches);
    textureStore(colour_out, p, out.colour);
    textureStore(data_out, p, out.data);
}

@vertex
fn vs_fill(@builtin(vertex_index) v: u32) -> @builtin(position) vec4<f32> {
    let xy = vec2<f32>(f32((v << 1u) & 2u), f32(v & 2u));
    return vec4<f32>(xy * 2.0 - 1.0, 0.0, 1.0);
}

@fragment
fn fs_fill(@builtin(position) clip: vec4<f32>) -> @builtin(frag_depth) f32 {
    let d = textureLoad(ray_data, vec2<i32>(clip.xy), 0);
    if d.w == 0u {
        discard;
    }
    return frame.viewport.z / bitcast<f32>(d.z);
}
