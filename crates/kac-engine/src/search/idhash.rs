//! The hashing of shape ids in the index's maps.

use super::*;

/// Hashing for shape ids, which are SHA-256 digests already: their four 8-byte words folded with a key drawn once
/// per process, then mixed (murmur3's finalizer), instead of SipHash, which the scans of a tag's shapes and the
/// loading of millions of ids spend most of their time in otherwise. The key keeps ids chosen to collide (whose
/// contents someone searched for) from being chosen once for every server.
#[derive(Clone, Copy)]
pub(crate) struct IdHasher(u64);

impl Default for IdHasher {
    fn default() -> Self {
        static KEY: std::sync::OnceLock<u64> = std::sync::OnceLock::new();
        IdHasher(*KEY.get_or_init(|| {
            use std::hash::{BuildHasher, Hasher};
            std::collections::hash_map::RandomState::new().build_hasher().finish()
        }))
    }
}

impl std::hash::Hasher for IdHasher {
    fn write(&mut self, bytes: &[u8]) {
        let mut x = self.0;
        for c in bytes.chunks(8) {
            let mut b = [0u8; 8];
            b[..c.len()].copy_from_slice(c);
            x = (x ^ u64::from_le_bytes(b)).wrapping_mul(0x9E37_79B9_7F4A_7C15).rotate_left(31);
        }
        self.0 = x;
    }
    fn write_usize(&mut self, n: usize) {
        self.0 ^= n as u64;
    }
    fn finish(&self) -> u64 {
        let mut h = self.0;
        h ^= h >> 33;
        h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
        h ^= h >> 33;
        h = h.wrapping_mul(0xc4ce_b9fe_1a85_ec53);
        h ^ (h >> 33)
    }
}

pub(crate) type Ids = std::hash::BuildHasherDefault<IdHasher>;
pub(crate) type IdMap<V> = HashMap<ShapeId, V, Ids>;
pub(crate) type IdSet = std::collections::HashSet<ShapeId, Ids>;
