//! What every ray cast of a frame did, per draw: the rays cast, their
//! traversal's fetches, the leaf cells they read and their shadow rays'
//! fetches, counted on the GPU (`count_cast`, `count_shadow` in
//! `shaders/work_count.wgsl`) for every ray, shown or not. The pixels' own
//! counts ([`super::Rendered::fetches`]) keep the ray a pixel shows only:
//! a hull fragment whose ray leaves the tile without a hit is discarded, and
//! one a nearer tile overwrites is lost, yet both cast their rays: along
//! the rmnp valley at 640 × 480 a frame casts 2.1–4.4 rays for each pixel
//! that shows one, and its view rays fetch 1.2–4.8 times what its pixels
//! count (`docs/benchmarks.md`, "Every ray counted").
//! [`super::Renderer::count_work`] turns the counting on (for frames read
//! back in full; its atomics cost lavapipe 8–35 % of a frame): `sylva fly`
//! does in held flights under a frame budget (the held renders, uncounted,
//! give the times), and `bench lod --flights` fits the frames' times to
//! this work in hindsight. On a GPU a fragment shader that writes storage
//! may lose its early depth test, so there the counted frames may cast
//! hidden rays that the uncounted ones are spared (not measured).
//!
//! The counters of a draw are spread over 32 places (`SPREAD`), one per pixel
//! of an 8 × 4 block, so that the invocations of one GPU wave do not
//! queue on one address; reading them back sums the places. Each counter
//! is 64 bits, two words whose low word carries into the high one (at 4K
//! a place holds about 260,000 pixels of a draw, thousands of fetches
//! each: more than a word holds).

/// Places per draw (`WORK_SPREAD`).
const SPREAD: u64 = 32;
/// Counters per place: rays, view-ray fetches, leaf cells, shadow-ray
/// fetches (the order of `count_cast` and `count_shadow`).
const COUNTERS: u64 = 4;
/// Words per counter: low, high.
const WORDS: u64 = 2;
/// Bytes of one draw's counters.
const DRAW_BYTES: u64 = SPREAD * COUNTERS * WORDS * 4;

/// The work of one draw's ray casts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DrawWork {
    /// Rays cast: hull fragments that ran, or a compute pass's casts
    /// through the tile.
    pub rays: u64,
    /// Texture fetches of their traversals (the hit cell's shading left
    /// out).
    pub view_fetches: u64,
    /// Leaf cells the exact traversal visited, their corners read or
    /// memoised (0 for the linear march): dearer than a step over the
    /// maximum mipmap.
    pub leaf_cells: u64,
    /// Fetches of the shadow rays, cast from the hits.
    pub shadow_fetches: u64,
}

impl DrawWork {
    /// The work of both.
    pub fn plus(&self, o: &DrawWork) -> DrawWork {
        DrawWork {
            rays: self.rays + o.rays,
            view_fetches: self.view_fetches + o.view_fetches,
            leaf_cells: self.leaf_cells + o.leaf_cells,
            shadow_fetches: self.shadow_fetches + o.shadow_fetches,
        }
    }
}

/// The frame's counters on the GPU, room for `draws` draws.
pub struct WorkCounters {
    buffer: wgpu::Buffer,
    readback: wgpu::Buffer,
}

impl WorkCounters {
    /// Counters for at most `draws` draws a frame (the tile cache's slots).
    pub fn new(device: &wgpu::Device, draws: u32) -> WorkCounters {
        let size = DRAW_BYTES * u64::from(draws.max(1));
        let buffer = |label, usage| {
            device.create_buffer(&wgpu::BufferDescriptor { label: Some(label), size, usage, mapped_at_creation: false })
        };
        WorkCounters {
            buffer: buffer(
                "work",
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
            ),
            readback: buffer("work readback", wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ),
        }
    }

    /// The buffer the shaders count in (group 0, binding 6).
    pub fn binding(&self) -> wgpu::BindingResource<'_> {
        self.buffer.as_entire_binding()
    }

    /// Zeroes the counters before a frame.
    pub fn clear(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.clear_buffer(&self.buffer, 0, None);
    }

    /// The last frame's work of its first `draws` draws.
    pub fn read(&self, device: &wgpu::Device, queue: &wgpu::Queue, draws: usize) -> Vec<DrawWork> {
        let bytes = (DRAW_BYTES * draws as u64).min(self.buffer.size());
        if bytes == 0 {
            return Vec::new();
        }
        let mut encoder = device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(&self.buffer, 0, &self.readback, 0, bytes);
        queue.submit([encoder.finish()]);
        let counts: Vec<u32> = bytemuck::cast_slice(&super::targets::map_read(device, &self.readback)).to_vec();
        counts.chunks_exact(DRAW_BYTES as usize / 4).take(draws).map(sum_places).collect()
    }
}

/// A draw's work from its places' counters.
fn sum_places(words: &[u32]) -> DrawWork {
    let counts: Vec<u64> =
        words.chunks_exact(WORDS as usize).map(|w| u64::from(w[0]) | u64::from(w[1]) << 32).collect();
    let total = |k: usize| counts.iter().skip(k).step_by(COUNTERS as usize).sum();
    DrawWork { rays: total(0), view_fetches: total(1), leaf_cells: total(2), shadow_fetches: total(3) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_draws_places_are_summed_counter_by_counter() {
        let mut words = vec![0u32; (SPREAD * COUNTERS * WORDS) as usize];
        for (k, pair) in words.chunks_exact_mut(2).enumerate() {
            // Place p holds p + 1 rays, 10 (p + 1) fetches, ..., and
            // p + 1 times 2³² shadow fetches more.
            let (place, counter) = (k as u32 / 4, k as u32 % 4);
            pair[0] = (place + 1) * [1, 10, 100, 1000][counter as usize];
            pair[1] = if counter == 3 { place + 1 } else { 0 };
        }
        let sum = (1..=SPREAD).sum::<u64>();
        let work = sum_places(&words);
        let shadow_fetches = 1000 * sum + (sum << 32);
        assert_eq!(work, DrawWork { rays: sum, view_fetches: 10 * sum, leaf_cells: 100 * sum, shadow_fetches });
    }
}
