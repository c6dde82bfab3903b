//! Canopy proxy files: the atlas GeoTIFF of a Wang tile set that `sylva
//! canopy` writes (float32 heights in metres, the layout in its
//! ImageDescription), read into a [`TileSet`].
//!
//! Invariant: the atlas size is checked against the layout before any pixel
//! is decoded, and against [`MAX_TEXELS`], so a hostile file cannot make us
//! allocate.

use super::SourceError;
use crate::canopy::{Layout, TileSet};
use std::io::BufReader;
use std::path::Path;
use tiff::decoder::{Decoder, DecodingResult};
use tiff::tags::Tag;

/// Most texels an atlas may have (256 MiB of `f32`).
pub const MAX_TEXELS: usize = 1 << 26;

/// Reads a proxy atlas.
pub fn open(path: &Path) -> Result<TileSet, SourceError> {
    let bad = |problem: String| SourceError::Malformed { path: path.into(), problem };
    let file = std::fs::File::open(path).map_err(|source| SourceError::Open { path: path.into(), source })?;
    let mut dec = Decoder::new(BufReader::new(file)).map_err(|e| bad(format!("not a readable TIFF: {e}")))?;
    let text = dec
        .get_tag_ascii_string(Tag::ImageDescription)
        .map_err(|_| bad("no ImageDescription: not a canopy proxy made by `sylva canopy`".into()))?;
    let layout = Layout::parse_tag(&text).map_err(bad)?;
    let (w, h) = dec.dimensions().map_err(|e| bad(e.to_string()))?;
    let size = (w as usize, h as usize);
    if size != layout.atlas_size() || size.0 * size.1 > MAX_TEXELS {
        let (ew, eh) = layout.atlas_size();
        return Err(bad(format!("the atlas is {w}×{h}, its layout needs {ew}×{eh} (at most {MAX_TEXELS} texels)")));
    }
    let data = match dec.read_image().map_err(|e| bad(format!("cannot decode: {e}")))? {
        DecodingResult::F32(v) => v,
        _ => return Err(bad("heights must be float32".into())),
    };
    let atlas =
        crate::raster::Raster::from_vec(size.0, size.1, data).ok_or_else(|| bad("truncated image data".into()))?;
    TileSet::from_atlas(layout, &atlas).map_err(bad)
}
