//! `clevrtex materials measure`: three figures of a rendered dataset that tell procedural
//! materials from the photographs they stand in for (issue 23; `docs/materials.md`,
//! "Measuring a dataset"):
//!
//! - **albedo spread**: per region (each object id, and the background 0) of the albedo pass
//!   at native size, over the pixels whose 5x5 neighbourhood is one id (regions under 400
//!   such pixels skipped): sRGB to CIELAB (D65), `sqrt(var L + var a + var b)`;
//! - **interior/boundary gradient ratio**: the RGB image centre-cropped and resized as the
//!   evaluator does (128x128, Pillow's bilinear; the mask nearest); luminance
//!   `0.299 R + 0.587 G + 0.114 B` (0..255); gradient magnitude by central differences;
//!   boundary pixels have more than one id in their 3x3 neighbourhood, interior pixels one id
//!   in their 7x7; the ratio is the mean gradient inside over the mean on boundaries (per
//!   region: the region's interior mean over the image's boundary mean);
//! - **scale ratio** (meant for `camo`): on the albedo, per region as above (regions with
//!   std L < 0.5 skipped), `D(r)` = mean squared difference of L between kept pixels of the
//!   region `r` apart (horizontal and vertical pairs); `q = D(1) / D(4)`; per image, the
//!   backdrop's `q` over the median `q` of the objects.
//!
//! A dataset is untrusted input: files are read through `clevrtex_dataset::dataset` (links
//! only inside the dataset, regular files only, a size cap), a PNG's header size is checked
//! before anything is decoded, and every problem is an error naming the file.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context};
use clevrtex_dataset::dataset;
use clevrtex_dataset::layout;
use clevrtex_scene::Pass;
use rayon::prelude::*;

pub use super::regions::{
    albedo_spread, gradient_ratio, gradient_ratio_at, kept, median, scale_ratio, Gradient, Scale,
    MIN_KEPT, MIN_STD_L,
};

/// The largest image measured (width and height), checked in the PNG header: the largest
/// any clevrtex image has.
pub const MAX_SIDE: u32 = clevrtex_scene::scene_file::MAX_IMAGE_SIDE;
/// The largest metadata file read.
const MAX_METADATA_BYTES: u64 = 16 << 20;

/// What one sample gave, with its regions' materials.
#[derive(Debug, Clone)]
pub struct SampleFigures {
    pub variant: String,
    pub stem: String,
    /// Material of region id (0: the backdrop's `ground_material`).
    pub materials: BTreeMap<u32, String>,
    pub spread: BTreeMap<u32, f64>,
    pub gradient: Option<Gradient>,
    pub scale: Scale,
}

/// One PNG of a sample, decoded after its header's size was checked.
struct Png {
    width: usize,
    height: usize,
    channels: usize,
    data: Vec<u16>,
}

/// The (width, height) of a PNG's IHDR, if it is one.
fn png_size(bytes: &[u8]) -> Option<(u32, u32)> {
    if bytes.len() < 24 || &bytes[..8] != b"\x89PNG\r\n\x1a\n" || &bytes[12..16] != b"IHDR" {
        return None;
    }
    let be = |o: usize| u32::from_be_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]);
    Some((be(16), be(20)))
}

/// With `pass`, the PNG's mode is checked against it first (`dataset::png_mode_problem`).
fn read_png(root: &Path, path: &Path, pass: Option<Pass>) -> anyhow::Result<Png> {
    let bytes = dataset::read(root, path, dataset::MAX_FILE_BYTES)
        .map_err(|why| anyhow!("`{}` {why}", path.display()))?;
    let Some((w, h)) = png_size(&bytes) else {
        bail!("`{}` is not a PNG", path.display());
    };
    if let Some(problem) = pass.and_then(|p| dataset::png_mode_problem(&bytes, p)) {
        bail!("`{}` {problem}", path.display());
    }
    if w == 0 || h == 0 || w > MAX_SIDE || h > MAX_SIDE {
        bail!(
            "`{}` claims {w}x{h} pixels (at most {MAX_SIDE}x{MAX_SIDE} are measured)",
            path.display()
        );
    }
    let p = clevrtex_render::post::decode_png_bytes(&bytes, path)
        .map_err(|e| anyhow!("{}", e.to_string().lines().next().unwrap_or("bad PNG")))
        .with_context(|| format!("cannot decode `{}`", path.display()))?;
    if p.bits != 8 {
        bail!(
            "`{}` is a {}-bit PNG, expected 8-bit",
            path.display(),
            p.bits
        );
    }
    Ok(Png {
        width: p.width as usize,
        height: p.height as usize,
        channels: p.channels,
        data: p.data,
    })
}

fn rgb8(root: &Path, path: &Path) -> anyhow::Result<(usize, usize, Vec<u8>)> {
    let p = read_png(root, path, None)?;
    let px = p.width * p.height;
    let data: Vec<u8> = match p.channels {
        3 | 4 => p
            .data
            .chunks_exact(p.channels)
            .flat_map(|c| [c[0] as u8, c[1] as u8, c[2] as u8])
            .collect(),
        n => bail!("`{}` has {n} channels, expected RGB", path.display()),
    };
    if data.len() != px * 3 {
        bail!("`{}` is truncated", path.display());
    }
    Ok((p.width, p.height, data))
}

/// Measure the sample `stem` in `dir` (under the dataset root `root`).
pub fn measure_sample(
    root: &Path,
    dir: &Path,
    variant: &str,
    stem: &str,
) -> anyhow::Result<SampleFigures> {
    let meta_path = dir.join(layout::metadata_file(stem));
    let bytes = dataset::read(root, &meta_path, MAX_METADATA_BYTES)
        .map_err(|why| anyhow!("`{}` {why}", meta_path.display()))?;
    let meta: serde_json::Value = serde_json::from_slice(&bytes)
        .with_context(|| format!("`{}` is not valid metadata", meta_path.display()))?;
    let Some(objects) = meta["objects"].as_array() else {
        bail!("`{}` has no `objects` list", meta_path.display());
    };
    let mut materials = BTreeMap::new();
    materials.insert(
        0,
        meta["ground_material"].as_str().unwrap_or("?").to_string(),
    );
    for (i, o) in objects.iter().enumerate().take(255) {
        let m = o["material"].as_str().unwrap_or("?").to_string();
        materials.insert(i as u32 + 1, m);
    }
    let mask_path = dir.join(layout::pass_file(stem, Pass::Mask));
    let mask = read_png(root, &mask_path, Some(Pass::Mask))?;
    let (w, h) = (mask.width, mask.height);
    let ids: Vec<u32> = mask.data.iter().map(|&v| u32::from(v)).collect();
    if ids.len() != w * h {
        bail!("`{}` is truncated", mask_path.display());
    }
    let same_size = |path: &Path, pw: usize, ph: usize| {
        if (pw, ph) == (w, h) {
            Ok(())
        } else {
            Err(anyhow!(
                "`{}` is {pw}x{ph}, its mask {w}x{h}",
                path.display()
            ))
        }
    };
    let rgb_path = dir.join(layout::pass_file(stem, Pass::Rgb));
    let gradient = if rgb_path.exists() {
        let (rw, rh, rgb) = rgb8(root, &rgb_path)?;
        same_size(&rgb_path, rw, rh)?;
        gradient_ratio(&rgb, &ids, w, h)
    } else {
        None
    };
    let albedo_path = dir.join(layout::pass_file(stem, Pass::Albedo));
    let (spread, scale) = if albedo_path.exists() {
        let (aw, ah, albedo) = rgb8(root, &albedo_path)?;
        same_size(&albedo_path, aw, ah)?;
        (
            albedo_spread(&albedo, &ids, w, h),
            scale_ratio(&albedo, &ids, w, h),
        )
    } else {
        (
            BTreeMap::new(),
            Scale {
                q: BTreeMap::new(),
                ratio: None,
            },
        )
    };
    Ok(SampleFigures {
        variant: variant.to_string(),
        stem: stem.to_string(),
        materials,
        spread,
        gradient,
        scale,
    })
}

/// One sample found: (variant, stem, folder).
pub type Found = (String, String, PathBuf);

/// The dataset's canonical root and its samples (found by the one read side of a dataset,
/// `clevrtex_dataset::dataset::Dataset::open`): the `--out` of `generate` or one
/// `clevrtex_<variant>` folder.
pub fn find_samples(dir: &Path) -> anyhow::Result<(PathBuf, Vec<Found>)> {
    let hint =
        "hint: pass the `--out` folder of `clevrtex generate` or one `clevrtex_<variant>` folder";
    if !dir.is_dir() {
        bail!("dataset folder `{}` does not exist\n{hint}", dir.display());
    }
    let ds = clevrtex_dataset::dataset::Dataset::open(dir).map_err(|e| match e {
        clevrtex_dataset::dataset::DatasetError::Unreadable { cause, .. } => {
            anyhow::Error::new(cause).context(format!("cannot read `{}`", dir.display()))
        }
        other => other.into(),
    })?;
    let mut out = Vec::new();
    for vd in &ds.variants {
        if let Some((d, e)) = vd.unreadable.first() {
            return Err(anyhow::anyhow!("{e}").context(format!("cannot read `{}`", d.display())));
        }
        for s in vd.samples.iter().filter(|s| s.has_metadata()) {
            out.push((s.variant.clone(), s.stem.clone(), s.dir.clone()));
        }
    }
    out.sort();
    if out.is_empty() {
        bail!(
            "no samples (`CLEVRTEX_<variant>_<index>.json`) under `{}`\n{hint}",
            dir.display()
        );
    }
    Ok((ds.root, out))
}

/// Measure every sample under `dir`, in parallel.
pub fn measure_dataset(dir: &Path) -> anyhow::Result<Vec<SampleFigures>> {
    let (root, samples) = find_samples(dir)?;
    samples
        .par_iter()
        .map(|(variant, stem, sub)| measure_sample(&root, sub, variant, stem))
        .collect()
}

/// The figures gathered per key (a variant or a material).
#[derive(Debug, Clone, Default)]
pub struct Summary {
    pub images: usize,
    pub object_spread: Vec<f64>,
    pub background_spread: Vec<f64>,
    /// Per image (variants) or per region (materials).
    pub gradient: Vec<f64>,
    /// Per image (variants) or the region's `q` (materials).
    pub scale: Vec<f64>,
}

/// Per variant and per material summaries of measured samples.
pub fn summarise(
    samples: &[SampleFigures],
) -> (BTreeMap<String, Summary>, BTreeMap<String, Summary>) {
    let mut variants: BTreeMap<String, Summary> = BTreeMap::new();
    let mut materials: BTreeMap<String, Summary> = BTreeMap::new();
    for s in samples {
        let v = variants.entry(s.variant.clone()).or_default();
        v.images += 1;
        let material = |id: &u32| s.materials.get(id).cloned().unwrap_or_else(|| "?".into());
        for (id, &sp) in &s.spread {
            let m = materials.entry(material(id)).or_default();
            if *id == 0 {
                v.background_spread.push(sp);
                m.background_spread.push(sp);
            } else {
                v.object_spread.push(sp);
                m.object_spread.push(sp);
            }
        }
        if let Some(g) = &s.gradient {
            v.gradient.extend(g.ratio);
            for (id, &r) in &g.regions {
                materials.entry(material(id)).or_default().gradient.push(r);
            }
        }
        v.scale.extend(s.scale.ratio);
        for (id, &q) in &s.scale.q {
            materials.entry(material(id)).or_default().scale.push(q);
        }
    }
    (variants, materials)
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn bad_files_are_errors_naming_the_file() {
        let d = tempfile::tempdir().unwrap();
        let sub = d.path().join("clevrtex_full/0");
        std::fs::create_dir_all(&sub).unwrap();
        let stem = "CLEVRTEX_full_000000";
        std::fs::write(sub.join(format!("{stem}.json")), b"{not json").unwrap();
        let e = format!("{:#}", measure_dataset(d.path()).unwrap_err());
        assert!(
            e.contains(&format!("{stem}.json")) && e.contains("not valid metadata"),
            "{e}"
        );
        std::fs::write(
            sub.join(format!("{stem}.json")),
            br#"{"objects": [], "ground_material": "x"}"#,
        )
        .unwrap();
        // A PNG header claiming 100000 x 100000 pixels: refused before any allocation.
        let mut huge = b"\x89PNG\r\n\x1a\n\0\0\0\x0dIHDR".to_vec();
        huge.extend(100_000u32.to_be_bytes());
        huge.extend(100_000u32.to_be_bytes());
        huge.extend([8, 3, 0, 0, 0, 0, 0, 0, 0]);
        std::fs::write(sub.join(format!("{stem}_flat.png")), &huge).unwrap();
        let e = format!("{:#}", measure_dataset(d.path()).unwrap_err());
        assert!(
            e.contains("_flat.png") && e.contains("100000x100000"),
            "{e}"
        );
        std::fs::write(sub.join(format!("{stem}_flat.png")), b"garbage").unwrap();
        let e = format!("{:#}", measure_dataset(d.path()).unwrap_err());
        assert!(e.contains("_flat.png") && e.contains("not a PNG"), "{e}");
        let e = format!("{:#}", measure_dataset(&d.path().join("nope")).unwrap_err());
        assert!(e.contains("does not exist"), "{e}");
    }
}
