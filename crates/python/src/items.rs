//! One sample read as the Python `Dataset`'s item: the image and mask cropped and resized as
//! the public `CLEVRTEX` loader does, and the optional passes decoded to their quantities.

use std::path::Path;

use clevrtex_eval::read;
use clevrtex_eval::resize::{crop_box, crop_resize_bilinear_rgb, crop_resize_nearest};
use clevrtex_scene::Pass;
use pyo3::prelude::*;
use pyo3::types::PyBytes;

use crate::dataset::{canonical_root, dataset_png};
use crate::errors::value_error;

/// The largest `resize` side (the largest image a dataset has).
const MAX_SIDE: usize = clevrtex_scene::scene_file::MAX_IMAGE_SIDE as usize;

/// The RGB image and the mask of a sample, cropped and resized: `(rgb, labels, h, w, W, H)`
/// (`W`, `H`: the files' own size).
type Pair = (Vec<u8>, Vec<u32>, usize, usize, usize, usize);

fn load_pair(
    root: Option<&Path>,
    image: &str,
    mask: &str,
    crop: bool,
    side: Option<usize>,
) -> PyResult<Pair> {
    let img = read::png_rgb(&dataset_png(root, image)?)
        .map_err(|r| value_error(format!("cannot decode `{image}`: {r}")))?;
    let mask_bytes = dataset_png(root, mask)?;
    if let Some(problem) =
        clevrtex_dataset::dataset::png_mode_problem(&mask_bytes, clevrtex_scene::Pass::Mask)
    {
        return Err(value_error(format!("`{mask}` {problem}")));
    }
    let msk = read::png_labels(&mask_bytes)
        .map_err(|r| value_error(format!("cannot decode `{mask}`: {r}")))?;
    let (w, h) = (img.width, img.height);
    if (msk.width, msk.height) != (w, h) {
        return Err(value_error(format!(
            "`{image}` is {w}x{h} but its mask is {}x{}",
            msk.width, msk.height
        )));
    }
    match (crop, side) {
        (false, None) => Ok((img.rgb, msk.labels, h, w, w, h)),
        (true, side) => {
            let side = side.unwrap_or_else(|| crop_box(w, h).2);
            let rgb = crop_resize_bilinear_rgb(&img.rgb, w, h, side);
            let labels = crop_resize_nearest(&msk.labels, w, h, side);
            match (rgb, labels) {
                (Some(r), Some(l)) => Ok((r, l, side, side, w, h)),
                _ => Err(value_error(format!("`{image}` is too small to crop"))),
            }
        }
        (false, Some(_)) => Err(value_error(
            "resizing without the crop is not supported: pass crop=True or resize=None",
        )),
    }
}

fn check_side(side: Option<usize>) -> PyResult<()> {
    if let Some(s) = side.filter(|&s| s == 0 || s > MAX_SIDE) {
        return Err(value_error(format!(
            "`resize` side {s} is outside 1..{MAX_SIDE} (the benchmark's is 128)"
        )));
    }
    Ok(())
}

/// Read one sample as the public `CLEVRTEX` loader does: `(rgb, labels, height, width)` with
/// `rgb` 8-bit interleaved and `labels` little-endian u32; with `crop`, the centre square of
/// side `int(0.8 min(W, H))`; resized to `side` (Pillow-exact bilinear for the image, nearest
/// for the mask), or kept at the crop's size when `side` is `None`. With `root` (the dataset's
/// folder), each file is checked again against it when read: a link swapped in after the
/// `Dataset` was made that leads out of the dataset is not followed (ValueError).
#[pyfunction]
#[pyo3(signature = (image, mask, crop=true, side=Some(128), root=None))]
pub(crate) fn load_sample<'py>(
    py: Python<'py>,
    image: &str,
    mask: &str,
    crop: bool,
    side: Option<usize>,
    root: Option<&str>,
) -> PyResult<(Bound<'py, PyBytes>, Bound<'py, PyBytes>, usize, usize)> {
    check_side(side)?;
    let (rgb, labels, h, w, _, _) = py.allow_threads(|| {
        let root = canonical_root(root)?;
        load_pair(root.as_deref(), image, mask, crop, side)
    })?;
    let lb: Vec<u8> = labels.iter().flat_map(|v| v.to_le_bytes()).collect();
    Ok((PyBytes::new(py, &rgb), PyBytes::new(py, &lb), h, w))
}

/// One optional pass of a sample decoded to its quantity, `(C, H, W)` float32 planar
/// (docs/python.md): the one decode of every reader, `clevrtex_dataset::quantity` (depth
/// metres, background `+inf`; `normal` the unit vector in world space, background 0; `albedo`
/// and `shadow` in 0..1), so the arrays equal the WebDataset export's. Depth, normal and
/// shadow are data (one point per pixel): cropped and resized nearest, like the mask; albedo
/// is a colour: bilinear, like the image. The PNG's layout must be the pass table's and its
/// size the image's.
fn decode_pass(
    pass: Pass,
    p: &str,
    bytes: &[u8],
    (w, h): (usize, usize),
    crop: bool,
    side: Option<usize>,
) -> PyResult<(Vec<f32>, usize)> {
    use clevrtex_dataset::quantity;
    let img = clevrtex_dataset::png::decode(bytes)
        .map_err(|r| value_error(format!("cannot decode `{p}`: {r}")))?;
    let Some((bits, channels)) = quantity::png_layout(pass) else {
        return Err(value_error(format!(
            "internal: `{}` is not an optional pass",
            pass.name()
        )));
    };
    if (img.channels, img.bits, img.palette) != (channels, bits, false) {
        let kind = |c: usize, b: u8| format!("{b}-bit {}", if c == 1 { "grey" } else { "RGB" });
        return Err(value_error(format!(
            "`{p}` is a {} PNG, but the {} pass is {}",
            kind(img.channels, img.bits),
            pass.name(),
            kind(channels, bits)
        )));
    }
    if (img.width as usize, img.height as usize) != (w, h) {
        return Err(value_error(format!(
            "`{p}` is {}x{} but its image is {w}x{h}",
            img.width, img.height
        )));
    }
    let out_side = if crop {
        Some(side.unwrap_or_else(|| crop_box(w, h).2))
    } else {
        None
    };
    let n_out = out_side.map_or(w * h, |s| s * s);
    let small = || value_error(format!("`{p}` is too small to crop"));
    let planar = |values: &[f32], pixels: &mut dyn Iterator<Item = usize>| {
        let mut out = vec![0f32; channels * n_out];
        for (i, px) in pixels.enumerate() {
            for c in 0..channels {
                out[c * n_out + i] = values[px * channels + c];
            }
        }
        out
    };
    // Albedo: 8-bit RGB resized as the image is (Pillow's bilinear), then decoded.
    if pass == Pass::Albedo {
        let rgb: Vec<u8> = img.data.iter().map(|&v| v as u8).collect();
        let rgb = match out_side {
            Some(s) => crop_resize_bilinear_rgb(&rgb, w, h, s).ok_or_else(small)?,
            None => rgb,
        };
        let values: Vec<f32> = rgb.iter().map(|&v| quantity::albedo(v)).collect();
        return Ok((planar(&values, &mut (0..n_out)), 3));
    }
    // The others: decoded, then the pixels the nearest crop and resize picks.
    let q = quantity::decode(pass, &img).map_err(|r| value_error(format!("`{p}` {r}")))?;
    let out = match out_side {
        Some(s) => {
            let index: Vec<u32> = (0..(w * h) as u32).collect();
            let map = crop_resize_nearest(&index, w, h, s).ok_or_else(small)?;
            planar(&q.data, &mut map.iter().map(|&i| i as usize))
        }
        None => planar(&q.data, &mut (0..n_out)),
    };
    Ok((out, channels))
}

/// A decoded optional pass: its name, float32 bytes (native order) and channels.
type PassOut<'py> = (String, Bound<'py, PyBytes>, usize);

/// What [`load_item`] returns: `(rgb, labels, h, w, (W, H), passes)`, `(W, H)` the files' own
/// size.
type Item<'py> = (
    Bound<'py, PyBytes>,
    Bound<'py, PyBytes>,
    usize,
    usize,
    (usize, usize),
    Vec<PassOut<'py>>,
);

/// [`load_sample`] and the sample's optional passes `passes` (`(name, path)`: `depth`,
/// `normal`, `albedo`, `shadow`), each decoded by [`decode_pass`] to `(C, H, W)` float32 of
/// the image's output size: `(rgb, labels, h, w, (W, H), [(name, bytes, channels)])` (`W`, `H`:
/// the files' own size). Every file is
/// read by the dataset reader (checked against `root`, capped, never a FIFO); a missing file
/// is `FileNotFoundError` naming it.
#[pyfunction]
#[pyo3(signature = (image, mask, passes, crop=true, side=Some(128), root=None))]
pub(crate) fn load_item<'py>(
    py: Python<'py>,
    image: &str,
    mask: &str,
    passes: Vec<(String, String)>,
    crop: bool,
    side: Option<usize>,
    root: Option<&str>,
) -> PyResult<Item<'py>> {
    check_side(side)?;
    let mut wanted = Vec::with_capacity(passes.len());
    for (name, path) in &passes {
        match Pass::from_name(name) {
            Some(p @ (Pass::Depth | Pass::Normal | Pass::Albedo | Pass::Shadow)) => {
                wanted.push((p, path.as_str()))
            }
            _ => {
                return Err(value_error(format!(
                    "unknown pass `{name}`; known: depth, normal, albedo, shadow"
                )))
            }
        }
    }
    let (rgb, labels, h, w, size, decoded) = py.allow_threads(|| -> PyResult<_> {
        let root = canonical_root(root)?;
        let (rgb, labels, h, w, fw, fh) = load_pair(root.as_deref(), image, mask, crop, side)?;
        let mut decoded = Vec::with_capacity(wanted.len());
        for &(pass, p) in &wanted {
            let bytes = dataset_png(root.as_deref(), p)?;
            decoded.push((pass, decode_pass(pass, p, &bytes, (fw, fh), crop, side)?));
        }
        Ok((rgb, labels, h, w, (fw, fh), decoded))
    })?;
    let lb: Vec<u8> = labels.iter().flat_map(|v| v.to_le_bytes()).collect();
    let out = decoded
        .into_iter()
        .map(|(pass, (v, c))| {
            let bytes: Vec<u8> = v.iter().flat_map(|x| x.to_ne_bytes()).collect();
            (pass.name().to_string(), PyBytes::new(py, &bytes), c)
        })
        .collect();
    Ok((
        PyBytes::new(py, &rgb),
        PyBytes::new(py, &lb),
        h,
        w,
        size,
        out,
    ))
}
