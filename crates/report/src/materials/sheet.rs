//! The contact sheet of `clevrtex materials sheet`: the cache of rendered cells and their
//! stitching into one image.

use std::path::PathBuf;

/// The cell cache: `explicit`, else `$XDG_CACHE_HOME/clevrtex/sheet` or
/// `~/.cache/clevrtex/sheet` (the temporary folder when neither is set).
pub fn cache_dir(explicit: Option<PathBuf>) -> PathBuf {
    if let Some(p) = explicit {
        return p;
    }
    let base = std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))
        .unwrap_or_else(std::env::temp_dir);
    base.join("clevrtex").join("sheet")
}

/// Hash of the embedded bridge scripts: a change to any of them invalidates every cached
/// cell.
fn scripts_hash() -> u64 {
    let parts: Vec<&[u8]> = clevrtex_render::bridge::files()
        .iter()
        .flat_map(|(name, text)| [name.as_bytes(), text.as_bytes()])
        .collect();
    clevrtex_materials::content_hash(&parts)
}

/// The file name of a cached cell: the material's name and content hash, the bridge scripts'
/// hash and the render settings.
pub fn cell_file(name: &str, hash: &str, size: u32, samples: u32) -> String {
    format!(
        "{name}-{}-{:016x}-{}x{}.png",
        hash,
        scripts_hash(),
        size,
        samples
    )
}

/// Stitch equally sized cell images into a grid, `cols` wide, on a dark background.
pub fn stitch(cells: &[PathBuf], cols: usize) -> Result<image::RgbImage, image::ImageError> {
    let imgs = cells
        .iter()
        .map(|p| image::open(p).map(|i| i.to_rgb8()))
        .collect::<Result<Vec<_>, _>>()?;
    let (w, h) = imgs.first().map_or((1, 1), |i| i.dimensions());
    let cols = cols.max(1).min(imgs.len().max(1));
    let rows = imgs.len().div_ceil(cols).max(1);
    let mut out =
        image::RgbImage::from_pixel(w * cols as u32, h * rows as u32, image::Rgb([16, 16, 16]));
    for (i, img) in imgs.iter().enumerate() {
        let (x, y) = ((i % cols) as u32 * w, (i / cols) as u32 * h);
        image::imageops::replace(&mut out, img, x.into(), y.into());
    }
    Ok(out)
}

/// The contact sheet of `names` made: cells of `size` at `samples` found in `cache` or
/// rendered into it (with the options `options` gives, asked only when a cell is missing),
/// stitched `cols` to a row and written to `out`; `say` is told what is cached and rendered.
pub fn make(
    cat: &clevrtex_materials::Catalogue,
    names: &[&str],
    options: &dyn Fn() -> anyhow::Result<clevrtex_render::material_renders::RenderOptions>,
    (size, samples, cols): (u32, u32, usize),
    cache: &std::path::Path,
    out: &std::path::Path,
    say: &mut dyn FnMut(String),
) -> anyhow::Result<()> {
    use anyhow::{bail, Context};
    let key = |name: &str| {
        let m = cat.get(name).expect("selected from the catalogue");
        cell_file(name, &m.hash, size, samples)
    };
    let missing: Vec<&str> = names
        .iter()
        .copied()
        .filter(|n| !cache.join(key(n)).is_file())
        .collect();
    say(format!(
        "sheet: {} materials, {} cached, {} to render",
        names.len(),
        names.len() - missing.len(),
        missing.len()
    ));
    if !missing.is_empty() {
        let mode = clevrtex_render::MaterialMode::Sheet;
        let settings = super::batches::settings(mode, size, samples, 0.37);
        let failed = clevrtex_render::material_renders::render_into_cache(
            cat,
            &missing,
            &options()?,
            &settings,
            cache,
            &key,
        )?;
        if !failed.is_empty() {
            bail!(
                "{} material(s) failed to build:\n{}\nhint: run `clevrtex materials check --names <name>` for the traceback",
                failed.len(),
                failed.join("\n")
            );
        }
    }
    let cells: Vec<PathBuf> = names.iter().map(|n| cache.join(key(n))).collect();
    let img = stitch(&cells, cols).context("cannot assemble the sheet")?;
    // The preview sheet's writer: PNG through the one atomic writer.
    crate::preview::save(&img, out)?;
    say(format!("wrote {}", out.display()));
    Ok(())
}
