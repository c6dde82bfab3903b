//! Chunks of palette (indexed-colour) TIFFs. Land-cover rasters such as NLCD
//! tree canopy cover ship as 8-bit palette images whose indices *are* the
//! data (class codes, percentages); the `tiff` crate refuses to decode them
//! because it cannot expand a palette to colours. Sylva needs the indices, so
//! this reads the chunk's bytes and undoes the compression (none, LZW,
//! Deflate) and the horizontal predictor itself.

use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use tiff::decoder::{ChunkType, Decoder, DecodingResult};
use tiff::tags::Tag;

/// Largest compressed chunk read, bytes (a 4096² 8-bit tile is 16 MiB).
const MAX_CHUNK_BYTES: u64 = 64 << 20;

/// The palette indices of chunk `index`, cropped to its data size.
pub fn read_indices(
    dec: &mut Decoder<BufReader<File>>,
    index: u32,
    chunk: (usize, usize),
) -> Result<DecodingResult, String> {
    let bits = dec.find_tag_unsigned::<u16>(Tag::BitsPerSample).map_err(|e| e.to_string())?.unwrap_or(1);
    if bits != 8 {
        return Err(format!("{bits}-bit palette images are not supported (8-bit are)"));
    }
    let tiled = dec.get_chunk_type() == ChunkType::Tile;
    let (offsets_tag, counts_tag) =
        if tiled { (Tag::TileOffsets, Tag::TileByteCounts) } else { (Tag::StripOffsets, Tag::StripByteCounts) };
    let offset = *dec
        .get_tag_u64_vec(offsets_tag)
        .map_err(|e| e.to_string())?
        .get(index as usize)
        .ok_or("no offset for the chunk")?;
    let count = *dec
        .get_tag_u64_vec(counts_tag)
        .map_err(|e| e.to_string())?
        .get(index as usize)
        .ok_or("no byte count for the chunk")?;
    if count > MAX_CHUNK_BYTES {
        return Err(format!("chunk of {count} bytes exceeds the {MAX_CHUNK_BYTES}-byte limit"));
    }
    let compression = dec.find_tag_unsigned::<u16>(Tag::Compression).map_err(|e| e.to_string())?.unwrap_or(1);
    let predictor = dec.find_tag_unsigned::<u16>(Tag::Predictor).map_err(|e| e.to_string())?.unwrap_or(1);
    let (w, h) = dec.chunk_data_dimensions(index);
    // Tiles are stored at full size; strips at their data size.
    let (row_len, rows) = if tiled { chunk } else { (w as usize, h as usize) };
    let mut raw = vec![0u8; count as usize];
    let file = dec.inner();
    file.seek(SeekFrom::Start(offset)).map_err(|e| e.to_string())?;
    file.read_exact(&mut raw).map_err(|e| format!("truncated: {e}"))?;
    let mut bytes = decompress(raw, compression, row_len * rows)?;
    if bytes.len() < row_len * rows {
        return Err(format!("chunk holds {} bytes, expected {}", bytes.len(), row_len * rows));
    }
    if predictor == 2 {
        for row in bytes.chunks_mut(row_len) {
            for i in 1..row.len() {
                row[i] = row[i].wrapping_add(row[i - 1]);
            }
        }
    }
    let data = (0..h as usize).flat_map(|y| bytes[y * row_len..y * row_len + w as usize].iter().copied()).collect();
    Ok(DecodingResult::U8(data))
}

fn decompress(raw: Vec<u8>, compression: u16, expected: usize) -> Result<Vec<u8>, String> {
    match compression {
        1 => Ok(raw),
        5 => weezl::decode::Decoder::with_tiff_size_switch(weezl::BitOrder::Msb, 8)
            .decode(&raw)
            .map_err(|e| format!("LZW: {e}")),
        8 | 32946 => {
            let mut out = Vec::with_capacity(expected);
            flate2::read::ZlibDecoder::new(&raw[..])
                .take(expected as u64 * 2 + 1024)
                .read_to_end(&mut out)
                .map_err(|e| format!("Deflate: {e}"))?;
            Ok(out)
        }
        other => Err(format!("compression {other} is not supported for palette images (none, LZW and Deflate are)")),
    }
}
