//! The project's one content hash: material cache keys, the sheet's cell cache, the bench's
//! reference cache and the dataset manifests all use [`content_hash`]. It lives in this crate
//! because it is the lowest of the workspace: every other crate depends on it.

use std::io::Read;
use std::path::Path;

use xxhash_rust::xxh3::{xxh3_64, Xxh3};

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

/// [`content_hash`] of parts given by their own xxh3-64 hashes (`part_hashes[i]` =
/// `content_hash(&[part_i])`): the same value, for parts too large to hold in memory.
pub fn content_hash_of_parts(part_hashes: &[u64]) -> u64 {
    match part_hashes {
        [one] => *one,
        _ => {
            let bytes: Vec<u8> = part_hashes.iter().flat_map(|h| h.to_le_bytes()).collect();
            xxh3_64(&bytes)
        }
    }
}

/// xxh3-64 of a file's bytes (`content_hash(&[bytes])`), read in 1 MiB pieces: a texture map
/// of gigabytes costs no more memory than a small one.
pub fn file_hash(path: &Path) -> std::io::Result<u64> {
    let mut f = open_regular(path)?;
    let mut h = Xxh3::new();
    let mut buf = vec![0u8; 1 << 20];
    loop {
        let n = f.read(&mut buf)?;
        if n == 0 {
            return Ok(h.digest());
        }
        h.update(&buf[..n]);
    }
}

/// `O_NONBLOCK` (Linux's value; the BSDs' elsewhere).
#[cfg(target_os = "linux")]
const O_NONBLOCK: i32 = 0o4000;
#[cfg(not(target_os = "linux"))]
const O_NONBLOCK: i32 = 0x0004;

/// Open `path` to read it, only if it is a regular file (links followed): the open never
/// blocks (a FIFO named `x.blend` or `x.json` in `--materials` hung `materials list`,
/// `sample` and `generate` for good), and anything but a regular file is refused.
pub fn open_regular(path: &Path) -> std::io::Result<std::fs::File> {
    use std::os::unix::fs::OpenOptionsExt;
    let f = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(O_NONBLOCK)
        .open(path)?;
    if !f.metadata()?.is_file() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "not a regular file (a FIFO, socket, device or folder); not read",
        ));
    }
    Ok(f)
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
        let parts = [xxh3_64(b"scene"), xxh3_64(b"mat")];
        assert_eq!(content_hash_of_parts(&parts), a);
        assert_eq!(
            content_hash_of_parts(&parts[..1]),
            content_hash(&[b"scene"])
        );
    }

    #[test]
    fn a_file_hashes_as_its_bytes() {
        let dir = std::env::temp_dir().join(format!("clevrtex-hash-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let bytes: Vec<u8> = (0..3_000_000u32).map(|i| (i % 251) as u8).collect();
        std::fs::write(dir.join("f"), &bytes).unwrap();
        assert_eq!(file_hash(&dir.join("f")).unwrap(), content_hash(&[&bytes]));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
