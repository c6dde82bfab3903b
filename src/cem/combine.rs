//! Stage c: the canopy (proxy × cover) and the combined elevation map
//! (ground + canopy), "the tileable canopy proxy model is multiplied with the
//! vegetation cover map, and the resulting vegetation height added to the
//! local terrain height" (dissertation 6.3).

use crate::canopy::CanopyProxy;
use crate::grid::SampleGrid;
use crate::raster::Raster;

/// Vegetation height above ground: the proxy where the cover is positive,
/// times the cover.
pub fn canopy(proxy: &dyn CanopyProxy, grid: &SampleGrid, cover: &Raster<f32>) -> Raster<f32> {
    proxy.heights(grid, Some(cover)).zip_map(cover, |h, c| h * c.max(0.0))
}

/// Vegetation height with one proxy per forest type: Σₖ proxyₖ × coverₖ,
/// where `covers(k)` is type `k`'s cover on the grid (read only once each).
pub fn canopy_by_type(
    proxies: &[&dyn CanopyProxy],
    grid: &SampleGrid,
    covers: impl Fn(usize) -> Raster<f32>,
) -> Raster<f32> {
    let mut total = Raster::filled(grid.width(), grid.height(), 0.0f32);
    for (k, proxy) in proxies.iter().enumerate() {
        let cover = covers(k);
        if cover.data().iter().any(|&c| c > 0.0) {
            total = total.zip_map(&canopy(*proxy, grid, &cover), |a, b| a + b);
        }
    }
    total
}

/// Ground plus canopy; nodata ground stays nodata.
pub fn cem(ground: &Raster<f32>, canopy: &Raster<f32>) -> Raster<f32> {
    ground.zip_map(canopy, |g, c| g + c)
}
