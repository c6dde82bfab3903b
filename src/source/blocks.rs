//! The bounded block cache shared by every source, and the reader that
//! assembles windows from cached blocks.
//!
//! The cache is weighted by bytes and evicts least-recently-used blocks beyond
//! its budget. Concurrent requests for one missing block compute it once (the
//! cache's own single-flight insertion), waiting for each other a bounded
//! time (`LOAD_WAIT`). A cache may give its blocks a time
//! to live, for regions fed by upstream servers: an expired block is read
//! again from its source, and kept while its source fails — read stale, and
//! counted, so that what is made of it can say so.

use super::{PixelSource, SourceError};
use crate::raster::{Raster, Window};
use quick_cache::Weighter;
use quick_cache::sync::{Cache, GuardResult};
use rayon::prelude::*;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

type Block = Arc<Vec<Raster<f32>>>;

/// Longest a read waits for another load of the same block before loading
/// it too. Loads run rayon work, and a rayon thread waiting inside one runs
/// other jobs meanwhile, which may want the block it is loading itself (or
/// one held by a thread that waits on it): an unbounded wait can deadlock
/// the pool, a bounded one costs at worst a block loaded twice.
const LOAD_WAIT: Duration = Duration::from_millis(250);

/// A block and when it was read.
#[derive(Clone)]
struct Stamped {
    block: Block,
    read_at: Instant,
}

#[derive(Clone)]
struct ByteWeight;

impl Weighter<(u64, usize, usize), Stamped> for ByteWeight {
    fn weight(&self, _key: &(u64, usize, usize), stamped: &Stamped) -> u64 {
        stamped.block.iter().map(|r| (r.data().len() * 4) as u64).sum::<u64>().max(1)
    }
}

/// Decoded and derived blocks of every source, bounded by bytes.
pub struct BlockCache {
    blocks: Cache<(u64, usize, usize), Stamped, ByteWeight>,
    next_id: AtomicU64,
    computed: AtomicU64,
    stale_reads: AtomicU64,
    ttl: Option<Duration>,
}

impl BlockCache {
    /// A cache holding at most `budget_bytes` of pixels.
    pub fn new(budget_bytes: u64) -> Arc<BlockCache> {
        BlockCache::expiring(budget_bytes, None)
    }

    /// A cache whose blocks are read again once older than `ttl` (none:
    /// kept until evicted).
    pub fn expiring(budget_bytes: u64, ttl: Option<Duration>) -> Arc<BlockCache> {
        // One 256² single-band block is 256 KiB: size the table for that.
        let estimated = (budget_bytes / (256 * 1024)).clamp(16, 1 << 20) as usize;
        Arc::new(BlockCache {
            blocks: Cache::with_weighter(estimated, budget_bytes.max(1), ByteWeight),
            next_id: AtomicU64::new(1),
            computed: AtomicU64::new(0),
            stale_reads: AtomicU64::new(0),
            ttl,
        })
    }

    /// Bytes currently held.
    pub fn bytes(&self) -> u64 {
        self.blocks.weight()
    }

    /// Blocks computed (cache misses) since the cache was made.
    pub fn blocks_computed(&self) -> u64 {
        self.computed.load(Ordering::Relaxed)
    }

    /// Expired blocks read because their source failed, since the cache
    /// was made: a product made while it grew may hold stale data.
    pub fn stale_reads(&self) -> u64 {
        self.stale_reads.load(Ordering::Relaxed)
    }

    fn fresh_id(&self) -> u64 {
        self.next_id.fetch_add(1, Ordering::Relaxed)
    }
}

/// A [`PixelSource`] behind the cache: reads any window, block by block.
#[derive(Clone)]
pub struct Blocks {
    source: Arc<dyn PixelSource>,
    cache: Arc<BlockCache>,
    id: u64,
}

impl Blocks {
    /// Puts `source` behind `cache`.
    pub fn new(source: Arc<dyn PixelSource>, cache: &Arc<BlockCache>) -> Blocks {
        Blocks { id: cache.fresh_id(), source, cache: cache.clone() }
    }

    /// The underlying source.
    pub fn source(&self) -> &Arc<dyn PixelSource> {
        &self.source
    }

    /// Width and height in pixels.
    pub fn size(&self) -> (usize, usize) {
        self.source.size()
    }

    /// The pixels of `window`, one raster per band; pixels outside the source
    /// are NaN.
    pub fn read(&self, window: Window) -> Result<Vec<Raster<f32>>, SourceError> {
        self.read_bands(window, self.source.bands())
    }

    /// Like [`Blocks::read`], only the first `bands` bands.
    pub fn read_bands(&self, window: Window, bands: usize) -> Result<Vec<Raster<f32>>, SourceError> {
        let bands = bands.min(self.source.bands());
        let (w, h) = self.source.size();
        let Some(inside) = window.intersect(&Window::new(0, 0, w, h)) else {
            return Ok(vec![Raster::filled(window.width, window.height, f32::NAN); bands]);
        };
        let (bw, bh) = self.source.block_size();
        let (x0, y0) = (inside.x as usize, inside.y as usize);
        let (x1, y1) = (inside.x_end() as usize, inside.y_end() as usize);
        let (cols, rows) = (x0 / bw..x1.div_ceil(bw), y0 / bh..y1.div_ceil(bh));
        let indices: Vec<(usize, usize)> = rows.flat_map(|by| cols.clone().map(move |bx| (bx, by))).collect();
        // Blocks are independent: compute missing ones in parallel.
        let blocks: Vec<Block> = indices.par_iter().map(|&(bx, by)| self.block(bx, by)).collect::<Result<_, _>>()?;
        // Each band's inside rows, block row segments appended in order.
        let mosaic = |band: usize| -> Option<Raster<f32>> {
            let mut data = Vec::with_capacity(inside.area());
            for y in y0..y1 {
                let first = (y / bh - y0 / bh) * cols.len();
                for (bx, block) in cols.clone().zip(&blocks[first..first + cols.len()]) {
                    let (a, b) = (x0.max(bx * bw) - bx * bw, x1.min((bx + 1) * bw) - bx * bw);
                    let pixels = block.get(band).filter(|r| b <= r.width() && y % bh < r.height())?;
                    data.extend_from_slice(&pixels.row(y % bh)[a..b]);
                }
            }
            Raster::from_vec(inside.width, inside.height, data)
        };
        let local = Window::new(window.x - inside.x, window.y - inside.y, window.width, window.height);
        let short = || SourceError::Malformed {
            path: self.source.name().to_path_buf(),
            problem: "a block is smaller than the block size says".into(),
        };
        (0..bands)
            .map(|band| {
                let m = mosaic(band).ok_or_else(short)?;
                Ok(if inside == window { m } else { m.crop(local, f32::NAN) })
            })
            .collect()
    }

    /// One band of `window`.
    pub fn read_band(&self, window: Window, band: usize) -> Result<Raster<f32>, SourceError> {
        Ok(self.read_bands(window, band + 1)?.swap_remove(band))
    }

    fn block(&self, bx: usize, by: usize) -> Result<Block, SourceError> {
        let key = (self.id, bx, by);
        let cache = &self.cache;
        let load = || {
            cache.computed.fetch_add(1, Ordering::Relaxed);
            let block = self.source.read_block(bx, by).map(Arc::new)?;
            Ok::<_, SourceError>(Stamped { block, read_at: Instant::now() })
        };
        if let Some(ttl) = cache.ttl
            && let Some(old) = cache.blocks.get(&key).filter(|s| s.read_at.elapsed() > ttl)
        {
            return match load() {
                Ok(stamped) => {
                    cache.blocks.insert(key, stamped.clone());
                    Ok(stamped.block)
                }
                Err(e) => {
                    tracing::warn!(source = %self.source.name().display(), error = %e, "source failed; reading its expired block");
                    cache.stale_reads.fetch_add(1, Ordering::Relaxed);
                    Ok(old.block)
                }
            };
        }
        let stamped = match cache.blocks.get_value_or_guard(&key, Some(LOAD_WAIT)) {
            GuardResult::Value(stamped) => stamped,
            GuardResult::Guard(guard) => {
                let stamped = load()?;
                let _ = guard.insert(stamped.clone());
                stamped
            }
            GuardResult::Timeout => {
                let stamped = load()?;
                cache.blocks.insert(key, stamped.clone());
                stamped
            }
        };
        Ok(stamped.block)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use std::path::Path;
    use std::sync::atomic::AtomicUsize;

    /// A source whose pixel `(x, y)` is `x + 1000 y`, counting block reads.
    pub(crate) struct Counting {
        pub size: (usize, usize),
        pub block: (usize, usize),
        pub reads: AtomicUsize,
    }

    impl PixelSource for Counting {
        fn name(&self) -> &Path {
            Path::new("<counting>")
        }
        fn size(&self) -> (usize, usize) {
            self.size
        }
        fn bands(&self) -> usize {
            1
        }
        fn block_size(&self) -> (usize, usize) {
            self.block
        }
        fn read_block(&self, bx: usize, by: usize) -> Result<Vec<Raster<f32>>, SourceError> {
            self.reads.fetch_add(1, Ordering::Relaxed);
            let (x0, y0) = (bx * self.block.0, by * self.block.1);
            let w = self.block.0.min(self.size.0 - x0);
            let h = self.block.1.min(self.size.1 - y0);
            Ok(vec![Raster::from_fn(w, h, |x, y| ((x0 + x) + 1000 * (y0 + y)) as f32)])
        }
    }

    #[test]
    fn windows_assemble_from_blocks_and_blocks_are_read_once() {
        let src = Arc::new(Counting { size: (50, 40), block: (16, 16), reads: AtomicUsize::new(0) });
        let blocks = Blocks::new(src.clone(), &BlockCache::new(1 << 20));
        let win = blocks.read_band(Window::new(-2, 10, 30, 35), 0).unwrap();
        assert!(win.get(0, 0).is_nan() && win.get(1, 34).is_nan());
        assert_eq!(win.get(2, 0), 10_000.0);
        assert_eq!(win.get(29, 29), 27.0 + 39_000.0);
        assert!(win.get(29, 30).is_nan());
        let first = src.reads.load(Ordering::Relaxed);
        assert_eq!(first, 2 * 3);
        blocks.read(Window::new(0, 10, 10, 10)).unwrap();
        assert_eq!(src.reads.load(Ordering::Relaxed), first);
    }

    #[test]
    fn expired_blocks_are_read_again() {
        let src = Arc::new(Counting { size: (16, 16), block: (16, 16), reads: AtomicUsize::new(0) });
        let blocks = Blocks::new(src.clone(), &BlockCache::expiring(1 << 20, Some(Duration::from_millis(30))));
        blocks.read(Window::new(0, 0, 4, 4)).unwrap();
        blocks.read(Window::new(0, 0, 4, 4)).unwrap();
        assert_eq!(src.reads.load(Ordering::Relaxed), 1);
        std::thread::sleep(Duration::from_millis(40));
        blocks.read(Window::new(0, 0, 4, 4)).unwrap();
        assert_eq!(src.reads.load(Ordering::Relaxed), 2);
    }

    /// A source of 1.0 everywhere that fails while `down` is set.
    struct Flaky {
        down: std::sync::atomic::AtomicBool,
    }

    impl PixelSource for Flaky {
        fn name(&self) -> &Path {
            Path::new("<flaky>")
        }
        fn size(&self) -> (usize, usize) {
            (8, 8)
        }
        fn bands(&self) -> usize {
            1
        }
        fn block_size(&self) -> (usize, usize) {
            (8, 8)
        }
        fn read_block(&self, _: usize, _: usize) -> Result<Vec<Raster<f32>>, SourceError> {
            match self.down.load(Ordering::Relaxed) {
                true => Err(SourceError::Upstream { url: "<flaky>".into(), problem: "down".into() }),
                false => Ok(vec![Raster::filled(8, 8, 1.0)]),
            }
        }
    }

    #[test]
    fn an_expired_block_is_read_stale_while_its_source_fails_and_counted() {
        let src = Arc::new(Flaky { down: false.into() });
        let cache = BlockCache::expiring(1 << 20, Some(Duration::from_millis(20)));
        let blocks = Blocks::new(src.clone(), &cache);
        let read = || blocks.read_band(Window::new(0, 0, 2, 2), 0).map(|r| r.get(1, 1));
        assert_eq!((read().unwrap(), cache.stale_reads()), (1.0, 0));
        src.down.store(true, Ordering::Relaxed);
        assert_eq!((read().unwrap(), cache.stale_reads()), (1.0, 0), "fresh: the source is not asked");
        std::thread::sleep(Duration::from_millis(30));
        assert_eq!((read().unwrap(), cache.stale_reads()), (1.0, 1), "expired, the source down: stale");
        src.down.store(false, Ordering::Relaxed);
        assert_eq!((read().unwrap(), cache.stale_reads()), (1.0, 1), "read again once the source is back");
        assert_eq!((read().unwrap(), cache.stale_reads()), (1.0, 1));
        // A block never read has nothing to fall back on.
        src.down.store(true, Ordering::Relaxed);
        let other = Blocks::new(src, &cache);
        assert!(other.read(Window::new(0, 0, 2, 2)).is_err());
    }

    #[test]
    fn the_cache_stays_within_its_budget() {
        let src = Arc::new(Counting { size: (512, 512), block: (64, 64), reads: AtomicUsize::new(0) });
        let cache = BlockCache::new(4 * 64 * 64 * 4);
        let blocks = Blocks::new(src, &cache);
        blocks.read(Window::new(0, 0, 512, 512)).unwrap();
        assert!(cache.bytes() <= 4 * 64 * 64 * 4, "{}", cache.bytes());
    }

    /// Blocks whose loading reads (in parallel) from another cached source,
    /// like a pyramid level or a land cover over its map.
    struct Nested {
        inner: Blocks,
    }

    impl PixelSource for Nested {
        fn name(&self) -> &Path {
            Path::new("<nested>")
        }
        fn size(&self) -> (usize, usize) {
            self.inner.size()
        }
        fn bands(&self) -> usize {
            1
        }
        fn block_size(&self) -> (usize, usize) {
            (16, 16)
        }
        fn read_block(&self, bx: usize, by: usize) -> Result<Vec<Raster<f32>>, SourceError> {
            std::thread::sleep(Duration::from_millis(2));
            self.inner.read(Window::new(bx as i64 * 16, by as i64 * 16, 16, 16))
        }
    }

    #[test]
    fn concurrent_jobs_reading_nested_sources_never_deadlock_the_pool() {
        // Rayon threads waiting inside a block's load run other jobs, which
        // may want that very block: waits must not be unbounded.
        let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
        for round in 0..20 {
            let cache = BlockCache::new(1 << 24);
            let counting = Arc::new(Counting { size: (128, 128), block: (4, 4), reads: AtomicUsize::new(0) });
            let middle = Blocks::new(Arc::new(Nested { inner: Blocks::new(counting, &cache) }), &cache);
            let outer = Blocks::new(Arc::new(Nested { inner: middle }), &cache);
            let (tx, rx) = std::sync::mpsc::channel();
            let jobs = 24;
            for j in 0..jobs {
                let (outer, tx) = (outer.clone(), tx.clone());
                pool.spawn(move || {
                    let read = outer.read(Window::new((j % 4) as i64 * 8, (j / 4) as i64 * 8, 96, 96));
                    let _ = tx.send(read.map(|r| r[0].get(0, 0)));
                });
            }
            for j in 0..jobs {
                let got = rx.recv_timeout(Duration::from_secs(60));
                assert!(got.is_ok(), "round {round}: the pool deadlocked ({j} of {jobs} jobs done)");
                let corner = got.unwrap().unwrap();
                assert!((0..jobs).any(|k| corner == ((k % 4) * 8 + 1000 * ((k / 4) * 8)) as f32), "{corner}");
            }
        }
    }
}
