//! The contact sheet of `clevrtex materials sheet`: rendered cells stitched into one image.

use std::path::PathBuf;

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
