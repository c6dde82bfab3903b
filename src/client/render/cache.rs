//! The GPU tile cache: fixed-size slots in texture arrays — texels (CEM,
//! ground, safety zones), colour + surface class, and the maximum mipmap
//! packed in an atlas — plus each resident tile's hull mesh. The number of
//! slots follows from the memory budget; a full cache evicts the least
//! recently drawn tile that the current frame does not use. With
//! geomorphing, a pool of layers holds the coarser surfaces that morphing
//! tiles blend with (a third of a slot each, one layer per two slots).
//!
//! Invariant: bytes resident ≤ the budget (slots and layers are allocated
//! up front; a budget of a single slot allocates a second layer, unused, that
//! wgpu's GL backend needs to see an array).

use super::super::hull::{self, HullVertex, QUAD_SAMPLES};
use super::super::terrain::TerrainVertex;
use super::super::tile::TileData;
use super::gpu::{AllocError, allocate};
use wgpu::util::DeviceExt;

/// Texture arrays hold at most this many layers on every adapter.
const MAX_SLOTS: u32 = 256;

/// A resident tile.
struct Resident {
    serial: u64,
    last_frame: u64,
    hull: Mesh,
    /// Side of the uploaded hull's largest quad, samples.
    hull_quad_samples: f32,
    terrain: Mesh,
}

/// A mesh on the GPU.
pub struct Mesh {
    /// Vertices.
    pub vertices: wgpu::Buffer,
    /// Triangles.
    pub indices: wgpu::Buffer,
    /// Number of indices.
    pub index_count: u32,
    /// Indices of the grid alone, without skirts.
    pub grid_count: u32,
}

impl Mesh {
    fn new(device: &wgpu::Device, vertices: &[u8], indices: &[u32], grid_count: usize) -> Mesh {
        let buffer = |label, contents, usage| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(label), contents, usage })
        };
        Mesh {
            vertices: buffer("tile vertices", vertices, wgpu::BufferUsages::VERTEX),
            indices: buffer("tile indices", bytemuck::cast_slice(indices), wgpu::BufferUsages::INDEX),
            index_count: indices.len() as u32,
            grid_count: grid_count as u32,
        }
    }

    fn bytes(&self) -> usize {
        (self.vertices.size() + self.indices.size()) as usize
    }
}

/// `n` layers, or one fewer where `n` is a multiple of six: wgpu's GL
/// backend takes a square texture with such a layer count for a cube-map
/// array, and the tiles read from it then show the wrong texels.
fn array_layers(n: u32) -> u32 {
    if n.is_multiple_of(6) { n - 1 } else { n }
}

/// Bytes of a tile's two meshes with `samples` per side at most: the hull
/// over the cast range's `samples + 1` cells (quads of [`QUAD_SAMPLES`]; a
/// coarser hull is smaller) and the terrain over its `samples - 1`, each a
/// top grid with a ring of skirt vertices. Slots are counted with them, so
/// that what is resident stays within the budget.
fn mesh_bytes(samples: u32) -> usize {
    let mesh = |cells: usize, vertex_bytes: usize, closed: bool| {
        let k = cells.div_ceil(QUAD_SAMPLES).max(1);
        let ring = hull::ring(k);
        let top = (k + 1) * (k + 1);
        let indices = hull::indices(k, &ring, top as u32, closed).len();
        ((top + ring.len()) * vertex_bytes).next_multiple_of(4) + indices * 4
    };
    let n = samples as usize;
    mesh(n + 1, std::mem::size_of::<HullVertex>(), true)
        + mesh(n.saturating_sub(1), std::mem::size_of::<TerrainVertex>(), false)
}

/// The cache is smaller than one frame's tiles.
#[derive(Debug, thiserror::Error)]
#[error("the GPU tile cache has {slots} slots and this frame needs more; give it a larger budget (--gpu-budget-mib)")]
pub struct CacheFull {
    /// Slots in the cache.
    pub slots: u32,
}

/// Tile textures on the GPU.
pub struct TileCache {
    /// Texels: CEM, ground, 4- and 32-sample zones.
    pub texels: wgpu::Texture,
    /// Colour (rgb) and surface class (alpha).
    pub colours: wgpu::Texture,
    /// The maximum mipmap atlas.
    pub mip: wgpu::Texture,
    /// Atlas rectangle of each mipmap level: x, y, width, height.
    pub mip_rects: Vec<[u32; 4]>,
    size: u32,
    /// The coarser surfaces of morphing tiles: CEM and ground per texel.
    pub morph_from: wgpu::Texture,
    slots: Vec<Option<Resident>>,
    slot_bytes: usize,
    /// Per morph layer: the serial of the tile it holds, when last drawn.
    morph_layers: Vec<Option<(u64, u64)>>,
    hull_factor: usize,
}

impl TileCache {
    /// A cache for tiles of `samples` per side with `halo`, within
    /// `budget_bytes` (at least one slot), with a pool of morph layers if
    /// `geomorph`; an error if the GPU has not the memory.
    pub fn new(
        device: &wgpu::Device,
        samples: u32,
        halo: u32,
        budget_bytes: usize,
        geomorph: bool,
    ) -> Result<TileCache, AllocError> {
        let size = samples + 2 * halo;
        let mip_rects = atlas(samples + 1);
        let atlas_w = mip_rects.iter().map(|r| r[0] + r[2]).max().unwrap_or(1);
        let atlas_h = mip_rects.iter().map(|r| r[1] + r[3]).max().unwrap_or(1);
        let slot_bytes = (size * size * (16 + 4) + atlas_w * atlas_h * 4) as usize;
        let share = if geomorph { morph_bytes(size) / 2 } else { 0 };
        let count = array_layers(
            u32::try_from(budget_bytes / (slot_bytes + mesh_bytes(samples) + share))
                .unwrap_or(u32::MAX)
                .clamp(1, MAX_SLOTS.min(device.limits().max_texture_array_layers)),
        );
        let layers = if geomorph { array_layers((count / 2).max(1)) } else { 0 };
        // At least two layers: wgpu's GL backend takes a one-layer texture for
        // a plain 2-D one, which the shaders' 2-D array bindings cannot read
        // (with one slot in the budget, the second layer stays unused).
        let array = |label, (w, h, count): (u32, u32, u32), format| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d { width: w, height: h, depth_or_array_layers: count.max(2) },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                view_formats: &[],
            })
        };
        // Without geomorphing the pool is one texel, for the bind group.
        let pool = if geomorph { (size, size, layers) } else { (1, 1, 1) };
        let mib = (count as usize * slot_bytes + layers as usize * morph_bytes(size)) >> 20;
        let what = format!("a GPU tile cache of {count} tiles ({mib} MiB; --gpu-budget-mib sets it)");
        let [texels, colours, mip, morph_from] = allocate(device, what, || {
            [
                array("tile texels", (size, size, count), wgpu::TextureFormat::Rgba32Float),
                array("tile colours", (size, size, count), wgpu::TextureFormat::Rgba8Unorm),
                array("tile max mipmaps", (atlas_w, atlas_h, count), wgpu::TextureFormat::R32Float),
                array("morph surfaces", pool, wgpu::TextureFormat::Rg32Float),
            ]
        })?;
        Ok(TileCache {
            texels,
            colours,
            mip,
            morph_from,
            mip_rects,
            size,
            slots: (0..count).map(|_| None).collect(),
            slot_bytes,
            morph_layers: vec![None; layers as usize],
            hull_factor: 1,
        })
    }

    /// Uploads hulls with quads `factor` times as large as the tiles'
    /// ([`crate::client::hull::Hull::coarsened`]) from now on.
    pub fn set_hull_factor(&mut self, factor: usize) {
        self.hull_factor = factor.max(1);
    }

    /// Number of slots.
    pub fn capacity(&self) -> u32 {
        self.slots.len() as u32
    }

    /// Bytes of texture memory per slot.
    pub fn slot_bytes(&self) -> usize {
        self.slot_bytes
    }

    /// Bytes of tiles resident now (textures, meshes and morph layers).
    pub fn resident_bytes(&self) -> usize {
        let tiles: usize =
            self.slots.iter().flatten().map(|r| self.slot_bytes + r.hull.bytes() + r.terrain.bytes()).sum();
        tiles + self.morph_layers.iter().flatten().count() * morph_bytes(self.size)
    }

    /// The morph layer holding the coarser surface of `tile` (uploading
    /// it if it is not there), marked used in `frame`; none for a tile
    /// that does not morph, or when every layer is used in `frame` (the
    /// tile is then drawn with its own heights).
    pub fn morph_layer(&mut self, queue: &wgpu::Queue, tile: &TileData, frame: u64) -> Option<u32> {
        let from = tile.morph_from.as_ref()?;
        let held = self.morph_layers.iter().position(|l| l.is_some_and(|(serial, _)| serial == tile.serial));
        let k = match held {
            Some(k) => k,
            None => {
                let k = least_recent(self.morph_layers.iter().map(|l| l.map(|(_, used)| used)), frame)?;
                let size = self.size;
                write_layer(queue, &self.morph_from, k as u32, [0, 0, size, size], bytemuck::cast_slice(from), 8);
                k
            }
        };
        self.morph_layers[k] = Some((tile.serial, frame));
        Some(k as u32)
    }

    /// The slot of a resident tile (by [`TileData::serial`]), marking it
    /// used in `frame`.
    pub fn lookup(&mut self, serial: u64, frame: u64) -> Option<u32> {
        let k = self.slots.iter().position(|s| s.as_ref().is_some_and(|r| r.serial == serial))?;
        if let Some(r) = self.slots[k].as_mut() {
            r.last_frame = frame;
        }
        Some(k as u32)
    }

    /// The hull and terrain meshes of the tile in `slot`.
    pub fn meshes(&self, slot: u32) -> Option<(&Mesh, &Mesh)> {
        let r = self.slots.get(slot as usize)?.as_ref()?;
        Some((&r.hull, &r.terrain))
    }

    /// Side of the largest quad of the hull uploaded for the tile in
    /// `slot`, samples.
    pub fn hull_quad_samples(&self, slot: u32) -> Option<f32> {
        Some(self.slots.get(slot as usize)?.as_ref()?.hull_quad_samples)
    }

    /// Makes `tile` resident (if it is not), evicting the least recently
    /// drawn tile not used in `frame`; returns its slot.
    pub fn insert(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        tile: &TileData,
        frame: u64,
    ) -> Result<u32, CacheFull> {
        if let Some(slot) = self.lookup(tile.serial, frame) {
            return Ok(slot);
        }
        let slot = self.victim(frame).ok_or(CacheFull { slots: self.capacity() })?;
        self.write(queue, tile, slot);
        let t = &tile.terrain;
        let coarse;
        let uploaded = if self.hull_factor > 1 {
            coarse = tile.hull.coarsened(self.hull_factor);
            &coarse
        } else {
            &tile.hull
        };
        let hull = Mesh::new(
            device,
            bytemuck::cast_slice::<HullVertex, u8>(&uploaded.vertices),
            &uploaded.indices,
            uploaded.indices.len(),
        );
        let terrain =
            Mesh::new(device, bytemuck::cast_slice::<TerrainVertex, u8>(&t.vertices), &t.indices, t.grid_indices);
        let hull_quad_samples = uploaded.quad_samples();
        let resident = Resident { serial: tile.serial, last_frame: frame, hull, hull_quad_samples, terrain };
        self.slots[slot as usize] = Some(resident);
        Ok(slot)
    }

    fn victim(&self, frame: u64) -> Option<u32> {
        least_recent(self.slots.iter().map(|s| s.as_ref().map(|r| r.last_frame)), frame).map(|k| k as u32)
    }

    fn write(&self, queue: &wgpu::Queue, tile: &TileData, slot: u32) {
        let size = self.size;
        let colours: Vec<[u8; 4]> =
            tile.colour.iter().zip(&tile.surface).map(|(c, &s)| [c[0], c[1], c[2], s]).collect();
        write_layer(queue, &self.texels, slot, [0, 0, size, size], bytemuck::cast_slice(&tile.texels), 16);
        write_layer(queue, &self.colours, slot, [0, 0, size, size], bytemuck::cast_slice(&colours), 4);
        let levels = self.mip_rects.iter().enumerate().take(tile.mip.levels());
        for (level, rect) in levels.filter(|(_, r)| r[2] > 0) {
            write_layer(queue, &self.mip, slot, *rect, bytemuck::cast_slice(tile.mip.level(level).data()), 4);
        }
    }
}

/// Bytes of one morph layer: two `f32` per texel.
fn morph_bytes(size: u32) -> usize {
    (size * size * 8) as usize
}

/// A free entry, else the least recently used one not used in `frame`,
/// from each entry's last use (none: free).
fn least_recent(last_used: impl Iterator<Item = Option<u64>>, frame: u64) -> Option<usize> {
    let mut oldest: Option<(usize, u64)> = None;
    for (k, used) in last_used.enumerate() {
        match used {
            None => return Some(k),
            Some(used) if used < frame && oldest.is_none_or(|(_, o)| used < o) => oldest = Some((k, used)),
            Some(_) => {}
        }
    }
    oldest.map(|(k, _)| k)
}

fn write_layer(
    queue: &wgpu::Queue,
    texture: &wgpu::Texture,
    slot: u32,
    rect: [u32; 4],
    bytes: &[u8],
    texel_bytes: u32,
) {
    queue.write_texture(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: 0,
            origin: wgpu::Origin3d { x: rect[0], y: rect[1], z: slot },
            aspect: wgpu::TextureAspect::All,
        },
        bytes,
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(rect[2] * texel_bytes),
            rows_per_image: Some(rect[3]),
        },
        wgpu::Extent3d { width: rect[2], height: rect[3], depth_or_array_layers: 1 },
    );
}

/// Where the levels of a maximum mipmap over `cells²` cells go in one
/// atlas: levels 1 and up stacked in a column (each `ceil(previous / 2)`
/// wide, as `MaxMipmap` builds them). Level 0 gets an empty rectangle and is
/// not uploaded: the traversal bounds a leaf by the corners it reads anyway
/// (traverse.wgsl), which saves the largest level's memory in every slot.
pub fn atlas(cells: u32) -> Vec<[u32; 4]> {
    let mut rects = vec![[0, 0, 0, 0]];
    let (mut side, mut y) = (cells, 0);
    while side > 1 {
        side = side.div_ceil(2);
        rects.push([0, y, side, side]);
        y += side;
    }
    rects
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_array_is_taken_for_cube_maps() {
        assert_eq!((1..=40).map(array_layers).filter(|n| n % 6 == 0).count(), 0);
        assert_eq!([1, 5, 6, 7, 36, 37].map(array_layers), [1, 5, 5, 7, 35, 37]);
    }

    #[test]
    fn the_atlas_holds_every_level_without_overlap() {
        let rects = atlas(514);
        assert_eq!(rects.len(), 11);
        assert_eq!(rects.last().map(|r| (r[2], r[3])), Some((1, 1)));
        assert_eq!(rects[0][2] * rects[0][3], 0, "level 0 is not uploaded");
        assert_eq!(rects[1][2..], [257, 257]);
        for (a, ra) in rects.iter().enumerate() {
            for rb in rects.iter().skip(a + 1) {
                let apart = ra[0] + ra[2] <= rb[0]
                    || rb[0] + rb[2] <= ra[0]
                    || ra[1] + ra[3] <= rb[1]
                    || rb[1] + rb[3] <= ra[1];
                assert!(apart, "{ra:?} overlaps {rb:?}");
            }
        }
        assert!(rects.len() <= super::super::uniforms::MAX_MIP_LEVELS);
    }
}
