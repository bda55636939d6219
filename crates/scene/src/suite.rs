//! Benchmark suites: the published sets of variants and sizes that `generate --suite` makes
//! into one folder, and the plan of one (each variant's total fixed up front, its seed and
//! layout stream), scaled by `--scale` and sharded as a whole.
//!
//! The `clevrtex` suite is the published ClevrTex benchmark (Karazija, Laina, Rupprecht,
//! NeurIPS 2021 Datasets and Benchmarks): ClevrTex (`full`) 50,000 images, PlainBG (`pbg`),
//! VarBG (`vbg`), GrassBG (`grassbg`) and CAMO (`camo`) 20,000 each, OOD (`outd`) 10,000, test
//! only (its config's split rule). Splits come from each variant's config.

use serde::{Deserialize, Serialize};

use crate::bounds::INDEX_END;
use crate::shard::Shard;

/// A suite: its name and its variants with their published sizes, in the order they are made.
#[derive(Debug, Clone, Copy)]
pub struct Suite {
    /// `--suite NAME`.
    pub name: &'static str,
    /// One line saying what it is.
    pub description: &'static str,
    /// `(variant, images)` in order.
    pub variants: &'static [(&'static str, u64)],
}

/// Every suite `--suite` knows.
pub const SUITES: [Suite; 1] = [Suite {
    name: "clevrtex",
    description: "the published ClevrTex benchmark: full 50,000, pbg, vbg, grassbg and camo 20,000 each, outd 10,000 (test only)",
    variants: &[
        ("full", 50_000),
        ("pbg", 20_000),
        ("vbg", 20_000),
        ("grassbg", 20_000),
        ("camo", 20_000),
        ("outd", 10_000),
    ],
}];

/// Whether the public loader (`CLEVRTEX` of karazijal/clevrtex-generation's
/// `clevrtex_eval.py`) knows `variant`: the `clevrtex` suite's variants. For any other
/// (`clevr`, a config's own name) it raises `Unknown variant`.
pub fn public_loader_knows(variant: &str) -> bool {
    SUITES[0].variants.iter().any(|(v, _)| *v == variant)
}

/// The suite named `name`, or a message naming the known ones.
pub fn find(name: &str) -> Result<&'static Suite, String> {
    SUITES.iter().find(|s| s.name == name).ok_or_else(|| {
        format!(
            "unknown suite `{}`\nhint: pass one of: {}",
            crate::text::printable(name),
            SUITES.map(|s| s.name).join(", ")
        )
    })
}

/// One variant of a planned suite.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlannedVariant {
    /// Variant name.
    pub variant: String,
    /// Its images: the published size times the scale, rounded (fixed up front: the `--total`
    /// of each of its runs, so its splits are the public loader's).
    pub total: u64,
    /// Its run seed.
    pub seed: u64,
    /// Its layout stream (its own name: variants' layouts unrelated).
    pub layout_stream: String,
    /// Position of its first image in the whole suite (the images of the variants before it):
    /// `--shard K/N` takes the suite's images with `position % N == K`.
    pub offset: u64,
}

/// A suite planned at a scale and seed: what `generate --suite` makes and records
/// (`SUITE.json` in the folder), and what `verify` checks the folder against.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SuitePlan {
    /// Suite name.
    pub suite: String,
    /// `--scale`.
    pub scale: f64,
    /// `--seed`.
    pub seed: u64,
    /// The variants, in order.
    pub variants: Vec<PlannedVariant>,
}

impl Suite {
    /// The plan at `scale` (each variant's published size times `scale`, rounded) and
    /// `seed` (every variant's; their layout streams differ). Refused: a scale that is not a
    /// positive number, that empties a variant or that takes one past the index cap.
    pub fn plan(&self, scale: f64, seed: u64) -> Result<SuitePlan, String> {
        if !(scale.is_finite() && scale > 0.0) {
            return Err(format!(
                "`--scale {scale}` is not a positive number\nhint: pass e.g. `--scale 0.001` for a small try, `--scale 1` (the default) for the published sizes"
            ));
        }
        let mut variants = Vec::new();
        let mut offset = 0;
        for &(variant, images) in self.variants {
            let exact = images as f64 * scale;
            let total = exact.round();
            if total < 1.0 {
                let least = 1.0 / self.variants.iter().map(|v| v.1).min().unwrap_or(1) as f64;
                return Err(format!(
                    "`--scale {scale}` makes variant `{variant}` of suite `{}` empty ({images} x {scale} = {exact} images)\nhint: pass a scale of at least {least} so that every variant keeps an image",
                    self.name
                ));
            }
            if total >= INDEX_END as f64 {
                return Err(format!(
                    "`--scale {scale}` makes variant `{variant}` of suite `{}` {total} images, over the cap of {} images per variant\nhint: pass a smaller scale",
                    self.name,
                    INDEX_END - 1
                ));
            }
            let total = total as u64;
            variants.push(PlannedVariant {
                variant: variant.to_string(),
                total,
                seed,
                layout_stream: variant.to_string(),
                offset,
            });
            offset += total;
        }
        Ok(SuitePlan {
            suite: self.name.to_string(),
            scale,
            seed,
            variants,
        })
    }
}

impl SuitePlan {
    /// Images of the whole suite.
    pub fn images(&self) -> u64 {
        self.variants.iter().map(|v| v.total).sum()
    }

    /// The share of variant `v`'s indices `0..total` that shard `shard` of the whole suite
    /// makes: the suite's images are numbered variant after variant and shard `K/N` takes
    /// those at positions `p % N == K`, which within a variant starting at `offset` are the
    /// indices `i` with `i % N == (K - offset) mod N`: one shard of the variant's own range.
    pub fn variant_shard(&self, v: &PlannedVariant, shard: Shard) -> Shard {
        Shard {
            k: (shard.k + shard.n - v.offset % shard.n) % shard.n,
            n: shard.n,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_published_suite_and_its_scaled_plans() {
        let s = find("clevrtex").unwrap();
        let full = s.plan(1.0, 0).unwrap();
        assert_eq!(full.images(), 50_000 + 4 * 20_000 + 10_000);
        let small = s.plan(0.0005, 3).unwrap();
        let totals: Vec<(&str, u64, u64)> = small
            .variants
            .iter()
            .map(|v| (v.variant.as_str(), v.total, v.offset))
            .collect();
        assert_eq!(
            totals,
            [
                ("full", 25, 0),
                ("pbg", 10, 25),
                ("vbg", 10, 35),
                ("grassbg", 10, 45),
                ("camo", 10, 55),
                ("outd", 5, 65)
            ]
        );
        assert!(small
            .variants
            .iter()
            .all(|v| v.seed == 3 && v.layout_stream == v.variant));
        let e = find("clevr").unwrap_err();
        assert!(
            e.contains("unknown suite `clevr`") && e.contains("clevrtex"),
            "{e}"
        );
        // `full` keeps 50,000 x 0.00001 = 0.5 -> 1 image; `pbg` (0.2) is the first emptied.
        // The hint: 1 / 10,000 (`outd`'s size), where every variant has an image before
        // rounding (a half image rounds up, but 0.5 is not exact in floating point).
        let e = s.plan(0.00001, 0).unwrap_err();
        assert!(
            e.contains("`pbg`") && e.contains("empty") && e.contains("at least 0.0001"),
            "{e}"
        );
        assert!(s.plan(0.0001, 0).is_ok());
        let e = s.plan(5000.0, 0).unwrap_err();
        assert!(e.contains("over the cap"), "{e}");
        assert!(s.plan(f64::NAN, 0).is_err() && s.plan(-1.0, 0).is_err());
    }

    #[test]
    fn shards_of_the_suite_split_the_whole_suite() {
        let plan = find("clevrtex").unwrap().plan(0.0005, 0).unwrap();
        for n in 1..5 {
            let mut positions: Vec<u64> = Vec::new();
            let mut per_shard = vec![0u64; n as usize];
            for k in 0..n {
                for v in &plan.variants {
                    let s = plan.variant_shard(v, Shard { k, n });
                    for i in s.iter(0, v.total) {
                        assert_eq!((v.offset + i) % n, k);
                        positions.push(v.offset + i);
                        per_shard[k as usize] += 1;
                    }
                }
            }
            positions.sort();
            assert_eq!(positions, (0..plan.images()).collect::<Vec<_>>());
            // The whole suite split evenly, not each variant.
            let (lo, hi) = (
                per_shard.iter().min().unwrap(),
                per_shard.iter().max().unwrap(),
            );
            assert!(hi - lo <= 1, "{per_shard:?}");
        }
    }
}
