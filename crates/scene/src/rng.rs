//! The one random number generator of the sampler, and the few draws it needs.
//!
//! The draws are written out here instead of using `rand`'s distributions so that a scene
//! file depends only on the ChaCha stream, never on how a `rand` release maps bits to floats.

use rand::{RngCore, SeedableRng};

/// The sampler's RNG: ChaCha with 8 rounds (fast, and plenty for sampling layouts).
pub type SceneRng = rand_chacha::ChaCha8Rng;

/// What a stream is used for; part of the key so that different purposes never share draws.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Purpose {
    /// The object count: kept across visibility retries, so it ignores the attempt number.
    Count = 1,
    /// Camera, lights, shapes, sizes, placement and rotations; changes with the attempt.
    Layout = 2,
    /// Materials, their instance values and colours: their own stream, so that the same
    /// layouts come out whatever catalogue the materials are drawn from.
    Material = 3,
}

/// The layout stream every variant shared up to clevrtex 0.1 (`--layout-stream shared`): the
/// same seed gave every variant the same layouts. Any other stream name (by default the
/// variant's own) gives its own draws.
pub const SHARED_STREAM: &str = "shared";

/// The part of the key that names the layout stream: clevrtex 0.1's constant for
/// [`SHARED_STREAM`], else the content hash of the name and a version tag, so two names never
/// share draws (and never the shared stream's).
fn stream_tag(stream: &str) -> [u8; 16] {
    if stream == SHARED_STREAM {
        return *b"clevrtex-scene-1";
    }
    let mut tag = [0u8; 16];
    let hash = clevrtex_materials::content_hash(&[b"clevrtex-layout-stream", stream.as_bytes()]);
    tag[0..8].copy_from_slice(&hash.to_le_bytes());
    tag[8..16].copy_from_slice(b"stream-2");
    tag
}

/// The RNG for one image: the key is (run seed, attempt, purpose, layout stream), the ChaCha
/// stream is the image index, so image `index` gets the same draws whatever range, shard or
/// thread made it, and two layout streams (two variants, by default) unrelated ones.
pub(crate) fn scene_rng(
    seed: u64,
    stream: &str,
    attempt: u32,
    purpose: Purpose,
    index: u64,
) -> SceneRng {
    let mut key = [0u8; 32];
    key[0..8].copy_from_slice(&seed.to_le_bytes());
    key[8..12].copy_from_slice(&attempt.to_le_bytes());
    key[12..16].copy_from_slice(&(purpose as u32).to_le_bytes());
    key[16..32].copy_from_slice(&stream_tag(stream));
    let mut rng = SceneRng::from_seed(key);
    rng.set_stream(index);
    rng
}

/// Uniform in [0, 1) with 53 random bits.
pub(crate) fn unit(rng: &mut SceneRng) -> f64 {
    (rng.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// Uniform in [lo, hi).
pub(crate) fn uniform(rng: &mut SceneRng, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * unit(rng)
}

/// Uniform integer in [0, n), unbiased (rejection sampling). `n` must be positive.
pub(crate) fn below(rng: &mut SceneRng, n: usize) -> usize {
    debug_assert!(n > 0);
    let n = n as u64;
    // Largest multiple of n that fits; values at or above it are redrawn.
    let zone = u64::MAX - (u64::MAX % n);
    loop {
        let x = rng.next_u64();
        if x < zone {
            return (x % n) as usize;
        }
    }
}

/// A uniformly chosen element of a non-empty slice.
pub(crate) fn choose<'a, T>(rng: &mut SceneRng, items: &'a [T]) -> &'a T {
    &items[below(rng, items.len())]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_are_independent_of_each_other_and_reproducible() {
        let a: Vec<u64> = (0..4)
            .map(|_| scene_rng(7, "full", 0, Purpose::Layout, 3).next_u64())
            .collect();
        assert!(a.iter().all(|&x| x == a[0]));
        let b = scene_rng(7, "full", 0, Purpose::Layout, 4).next_u64();
        let c = scene_rng(7, "full", 1, Purpose::Layout, 3).next_u64();
        let d = scene_rng(7, "full", 0, Purpose::Count, 3).next_u64();
        assert_ne!(a[0], b);
        assert_ne!(a[0], c);
        assert_ne!(a[0], d);
        // Another stream, and the shared one, draw otherwise.
        let e = scene_rng(7, "camo", 0, Purpose::Layout, 3).next_u64();
        let f = scene_rng(7, SHARED_STREAM, 0, Purpose::Layout, 3).next_u64();
        assert!(a[0] != e && a[0] != f && e != f);
    }

    #[test]
    fn unit_and_below_stay_in_range() {
        let mut rng = scene_rng(1, "full", 0, Purpose::Layout, 0);
        for _ in 0..10_000 {
            let u = unit(&mut rng);
            assert!((0.0..1.0).contains(&u));
            assert!(below(&mut rng, 7) < 7);
        }
    }
}
