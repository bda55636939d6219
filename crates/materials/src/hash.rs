//! The project's one content hash: material cache keys, the sheet's cell cache, the bench's
//! reference cache and the dataset manifests all use [`content_hash`]. It lives in this crate
//! because it is the lowest of the workspace: every other crate depends on it.

use xxhash_rust::xxh3::xxh3_64;

/// xxh3-64 of `parts`, stable across releases and machines (a cache key, not for security).
///
/// One part: the xxh3-64 of its bytes, exactly what `xxhsum -H3` prints for a file. Several
/// parts: the xxh3-64 of their hashes in order (little-endian), so moving bytes from one part
/// to the next changes the result (`["ab", "c"]` and `["a", "bc"]` differ).
pub fn content_hash(parts: &[&[u8]]) -> u64 {
    match parts {
        [one] => xxh3_64(one),
        _ => {
            let hashes: Vec<u8> = parts
                .iter()
                .flat_map(|p| xxh3_64(p).to_le_bytes())
                .collect();
            xxh3_64(&hashes)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_part_is_plain_xxh3_and_parts_keep_their_boundaries() {
        // Reference value of xxh3-64 of "abc" (xxhsum -H3).
        assert_eq!(content_hash(&[b"abc"]), 0x78af_5f94_892f_3950);
        let a = content_hash(&[b"scene", b"mat"]);
        assert_eq!(a, content_hash(&[b"scene", b"mat"]));
        assert_ne!(a, content_hash(&[b"scen", b"emat"]));
        assert_ne!(a, content_hash(&[b"scene", b"mat2"]));
        assert_ne!(a, content_hash(&[b"scenemat"]));
    }
}
