//! `export --crop [--resize N]`: a sample's shard entries cropped and resized as the public
//! loader does (centre square of side `int(0.8 min(W, H))`, then `N x N`): the image and the
//! albedo Pillow-exact bilinear, the mask and the data passes (depth, normal, shadow) nearest,
//! with [`crate::resize`], the one implementation `eval` and the Python `Dataset` use.

use clevrtex_scene::passes::WebdatasetForm;

use super::{npy_header, SampleFile};
use crate::resize::{crop_box, crop_resize_bilinear_rgb, crop_resize_nearest};

/// The frame of a cropped and resized sample: the crop's corner `(x0, y0)` and the scale from
/// the crop's pixels to the output's.
#[derive(Debug, Clone, Copy)]
pub struct Frame {
    /// Left edge of the crop in the full image's pixels.
    pub x0: f64,
    /// Top edge of the crop.
    pub y0: f64,
    /// Output pixels per crop pixel.
    pub scale: f64,
}

/// The data of a `.npy` of ours ([`npy_header`]): its shape and where its data starts.
pub fn npy_shape(bytes: &[u8]) -> Option<(Vec<usize>, usize)> {
    let len = usize::from(u16::from_le_bytes(bytes.get(8..10)?.try_into().ok()?));
    let header = std::str::from_utf8(bytes.get(10..10 + len)?).ok()?;
    let inner = header.split("'shape': (").nth(1)?.split(')').next()?;
    let shape = inner
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse().ok())
        .collect::<Option<Vec<usize>>>()?;
    Some((shape, 10 + len))
}

/// Crop (and resize to `side`, else keep the crop's size) every entry of a sample (`files`
/// in the order of `entries`, as `sample_entries` made them). `Err` says why not, one line.
pub fn crop_resize(
    entries: &mut [(String, Vec<u8>)],
    files: &[SampleFile],
    side: Option<usize>,
) -> Result<Frame, String> {
    let mut frame = None;
    for ((key, bytes), f) in entries.iter_mut().zip(files) {
        let name = || f.path.display().to_string();
        if key == "json" {
            continue;
        }
        if let (Some(pass), true) = (f.pass, f.npy) {
            let WebdatasetForm::Npy { descr, channels } = pass.spec().webdataset_form else {
                continue;
            };
            let (shape, start) =
                npy_shape(bytes).ok_or_else(|| format!("`{}`: not an array", name()))?;
            let (h, w) = (shape[0], shape[1]);
            let (x0, y0, c) = crop_box(w, h);
            let out = side.unwrap_or(c);
            let index: Vec<u32> = (0..(w * h) as u32).collect();
            let map = crop_resize_nearest(&index, w, h, out)
                .ok_or_else(|| format!("`{}` is too small to crop", name()))?;
            let size = (bytes.len() - start) / (w * h);
            let data = &bytes[start..];
            let mut new = npy_header(
                descr,
                &[out, out, usize::from(channels)][..if channels == 1 { 2 } else { 3 }],
            );
            for &i in &map {
                new.extend_from_slice(&data[i as usize * size..][..size]);
            }
            *bytes = new;
            frame = Some((x0, y0, c, out));
        } else if key == "png" || key == "albedo.png" {
            let png = crate::png::decode(bytes).map_err(|w| format!("`{}` {w}", name()))?;
            if png.bits != 8 || png.channels < 3 {
                return Err(format!(
                    "`{}` is a {}-bit {}-channel PNG, not 8-bit RGB",
                    name(),
                    png.bits,
                    png.channels
                ));
            }
            let (w, h) = (png.width as usize, png.height as usize);
            let rgb: Vec<u8> = png
                .data
                .chunks_exact(png.channels)
                .flat_map(|p| [p[0] as u8, p[1] as u8, p[2] as u8])
                .collect();
            let (x0, y0, c) = crop_box(w, h);
            let out = side.unwrap_or(c);
            let res = crop_resize_bilinear_rgb(&rgb, w, h, out)
                .ok_or_else(|| format!("`{}` is too small to crop", name()))?;
            *bytes = crate::png::encode_rgb8(out as u32, out as u32, &res)
                .map_err(|e| format!("`{}`: cannot encode its crop: {e}", name()))?;
            frame = Some((x0, y0, c, out));
        } else {
            return Err(format!(
                "`{}` is in the published ClevrTex's encoding, which `--crop` does not crop\nhint: export without `--crop`",
                name()
            ));
        }
    }
    let (x0, y0, c, out) = frame.ok_or("the sample has no image to crop")?;
    Ok(Frame {
        x0: x0 as f64,
        y0: y0 as f64,
        scale: out as f64 / c as f64,
    })
}
