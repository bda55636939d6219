//! The one decode of a pass's PNG into the quantity it encodes ([`decode`]): depth in metres,
//! the surface normal, the shadow amount, the albedo in 0..1. The WebDataset and Hugging Face
//! export (`webdataset::npy`) and the Python `Dataset` (`crates/python/src/items.rs`) both
//! decode through it, so the arrays they give are equal, bit for bit (crop and resize are
//! nearest for the data passes: they pick pixels of this decode). docs/output-format.md,
//! "Decoded passes", documents it.
//!
//! The normal: Cycles' normal pass is the mean of the normals of a pixel's samples, and a
//! sample that hits nothing counts as the zero vector; the PNG stores that mean (16 bits a
//! channel), so it is shorter than 1 where a pixel straddles an edge or a bumpy texture. The
//! decode returns its direction, a unit vector: what normal estimation compares (angles),
//! and the same wherever a model looks; the share of a pixel an object covers is the mask's
//! business. A pixel that hit nothing (the PNG's `NORMAL_BACKGROUND`) is `(0, 0, 0)`.

use clevrtex_scene::passes::{DEPTH_BACKGROUND, DEPTH_SCALE_M, NORMAL_BACKGROUND};
use clevrtex_scene::Pass;

use crate::png::DecodedPng;

/// A decoded pass: `channels` float32 values per pixel, row-major, channels interleaved
/// (`(H, W, C)`).
#[derive(Debug, Clone, PartialEq)]
pub struct Quantity {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Values per pixel: 1 (depth, shadow) or 3 (normal, albedo).
    pub channels: usize,
    /// The values.
    pub data: Vec<f32>,
}

/// Depth in metres of a depth PNG's value: `value * DEPTH_SCALE_M`, `+inf` for
/// `DEPTH_BACKGROUND` (nothing hit, or beyond the 65.534 m the PNG holds).
pub fn depth(v: u16) -> f32 {
    if v == DEPTH_BACKGROUND {
        f32::INFINITY
    } else {
        (f64::from(v) * DEPTH_SCALE_M) as f32
    }
}

/// The unit normal (world space, x y z) of a normal PNG's pixel: the direction of
/// `value / 65535 * 2 - 1`; `(0, 0, 0)` for `NORMAL_BACKGROUND` (nothing hit).
pub fn normal(px: [u16; 3]) -> [f32; 3] {
    if px == NORMAL_BACKGROUND {
        return [0.0; 3];
    }
    let v = px.map(|c| f64::from(c) / 65535.0 * 2.0 - 1.0);
    let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if len > 0.0 {
        v.map(|c| (c / len) as f32)
    } else {
        [0.0; 3]
    }
}

/// The shadow amount in `[0, 1]` of a shadow PNG's 8-bit value (`value / 255`).
pub fn shadow(v: u16) -> f32 {
    f32::from(v) / 255.0
}

/// An albedo channel in `[0, 1]` of an albedo PNG's 8-bit sRGB value (`value / 255`).
pub fn albedo(v: u8) -> f32 {
    f32::from(v) / 255.0
}

/// The bits and channels of `pass`'s PNG, as the pass table says, for the passes [`decode`]
/// decodes.
pub fn png_layout(pass: Pass) -> Option<(u8, usize)> {
    match pass {
        Pass::Depth => Some((16, 1)),
        Pass::Normal => Some((16, 3)),
        Pass::Shadow => Some((8, 1)),
        Pass::Albedo => Some((8, 3)),
        Pass::Rgb | Pass::Mask => None,
    }
}

/// The quantity of `pass` (depth, normal, shadow, albedo) from its decoded PNG. `Err` (one
/// line, the caller names the file) when the pass is not one of those or the PNG is not of
/// the pass table's bits and channels.
pub fn decode(pass: Pass, png: &DecodedPng) -> Result<Quantity, String> {
    let Some((bits, channels)) = png_layout(pass) else {
        return Err(format!(
            "the {} pass is not decoded to a quantity",
            pass.name()
        ));
    };
    if png.bits != bits || png.channels != channels || png.palette {
        return Err(format!(
            "is a {}-bit {}-channel PNG, not the {bits}-bit {channels}-channel {} pass",
            png.bits,
            png.channels,
            pass.name()
        ));
    }
    let data: Vec<f32> = match pass {
        Pass::Depth => png.data.iter().map(|&v| depth(v)).collect(),
        Pass::Shadow => png.data.iter().map(|&v| shadow(v)).collect(),
        Pass::Albedo => png.data.iter().map(|&v| albedo(v as u8)).collect(),
        Pass::Normal => png
            .data
            .chunks_exact(3)
            .flat_map(|p| normal([p[0], p[1], p[2]]))
            .collect(),
        Pass::Rgb | Pass::Mask => unreachable!("refused above"),
    };
    Ok(Quantity {
        width: png.width as usize,
        height: png.height as usize,
        channels,
        data,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normals_are_unit_vectors_and_the_background_is_zero() {
        assert_eq!(normal(NORMAL_BACKGROUND), [0.0; 3]);
        // A silhouette pixel: half the samples hit (0, 0, 1), half nothing: the mean (0, 0,
        // 0.5) is stored; its direction is returned.
        let half = (0.75f64 * 65535.0).round() as u16;
        let n = normal([32768, 32768, half]);
        let len = n.iter().map(|c| f64::from(*c).powi(2)).sum::<f64>().sqrt();
        assert!((len - 1.0).abs() < 1e-6, "{n:?}");
        assert!(n[2] > 0.9999, "{n:?}");
        assert_eq!(normal([65535, 32768, 32768])[0], 1.0);
    }

    #[test]
    fn depth_background_is_infinite_and_values_are_metres() {
        assert_eq!(depth(DEPTH_BACKGROUND), f32::INFINITY);
        assert_eq!(depth(1500), 1.5);
    }

    #[test]
    fn a_png_of_another_layout_is_refused() {
        let png = DecodedPng {
            width: 1,
            height: 1,
            bits: 8,
            channels: 1,
            palette: false,
            data: vec![3],
        };
        assert!(decode(Pass::Normal, &png)
            .unwrap_err()
            .contains("16-bit 3-channel"));
        assert!(decode(Pass::Mask, &png).is_err());
        assert_eq!(decode(Pass::Shadow, &png).unwrap().data, [3.0 / 255.0]);
    }
}
