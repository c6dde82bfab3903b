//! The envelope every cached payload is stored in: the payload followed by a
//! 16-byte trailer — magic, payload length, CRC-32 — so that a truncated or
//! corrupt entry is detected on read, never served. Both backends use it.

/// Marks the end of a cache entry.
const MAGIC: &[u8; 4] = b"SYLV";
/// Magic, payload length (u64), CRC-32 (u32).
pub const TRAILER: usize = 16;

/// The trailer of `payload`.
pub fn trailer(payload: &[u8]) -> [u8; TRAILER] {
    let mut t = [0u8; TRAILER];
    t[..4].copy_from_slice(MAGIC);
    t[4..12].copy_from_slice(&(payload.len() as u64).to_le_bytes());
    t[12..].copy_from_slice(&crc32fast::hash(payload).to_le_bytes());
    t
}

/// The payload of an entry if its trailer checks out.
pub fn open(mut data: Vec<u8>) -> Option<Vec<u8>> {
    let n = data.len().checked_sub(TRAILER)?;
    let t = &data[n..];
    let len = u64::from_le_bytes(t[4..12].try_into().ok()?);
    let crc = u32::from_le_bytes(t[12..].try_into().ok()?);
    if &t[..4] != MAGIC || len != n as u64 || crc != crc32fast::hash(&data[..n]) {
        return None;
    }
    data.truncate(n);
    Some(data)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sealed_payloads_open_and_damage_does_not() {
        let mut sealed = b"tile".to_vec();
        sealed.extend_from_slice(&trailer(b"tile"));
        assert_eq!(open(sealed.clone()).as_deref(), Some(&b"tile"[..]));
        assert_eq!(open(sealed[..sealed.len() - 1].to_vec()), None);
        let mut flipped = sealed.clone();
        flipped[0] ^= 1;
        assert_eq!(open(flipped), None);
        assert_eq!(open(b"junk".to_vec()), None);
    }
}
