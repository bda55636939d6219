//! The pass table: every render pass and everything about it that is data.
//!
//! One entry per [`Pass`] in [`Pass::spec`]: its name (scene files, `--passes`, the bridge's
//! `PASSES` table in `blender_scripts/passes.py`), the EXR layers the bridge writes for it,
//! the file suffix of the published layout, the PNG it becomes and the encoding written into
//! every sample's metadata. The numbers of the encodings are constants here too, so the
//! encoders (`clevrtex_render::post`) and the metadata cannot disagree.
//!
//! Adding a pass: a variant of [`Pass`] and its entry in [`Pass::spec`], its entry in
//! `blender_scripts/passes.py` (a test checks both tables agree, names and EXR layers), its
//! encoder (`clevrtex_render::passes::encode`) and a test of it.

use serde::{Deserialize, Serialize};

/// Depth PNG: metres per unit (1 mm), so 16 bits cover 0 to 65.534 m.
pub const DEPTH_SCALE_M: f64 = 0.001;
/// Depth PNG value of pixels that hit nothing (the black world) or lie beyond the range.
pub const DEPTH_BACKGROUND: u16 = 65535;
/// Normal PNG value of pixels that hit nothing (the zero vector).
pub const NORMAL_BACKGROUND: [u16; 3] = [32768, 32768, 32768];
/// Shadow value where the unshadowed direct light is ~0 (unlit or back-facing): the
/// shadow ratio is undefined there, and we call it "not shadowed".
pub const SHADOW_UNDEFINED: u8 = 0;
/// Unshadowed direct-light luminance below which the shadow ratio counts as undefined.
pub const SHADOW_EPS: f32 = 1e-4;
/// ... and the fraction of the image's 99th-percentile unshadowed luminance below which it
/// does too: a surface that gets under 1% of the typical direct light (grazing or turned
/// away from every light) has no shadow worth the name, and its ratio of two tiny numbers
/// is all noise (it was most of the 256-sample reference's own error;
/// docs/notes/performance.md, "Shadow pass").
pub const SHADOW_REL_EPS: f32 = 0.01;

/// A render pass. The same names key the bridge's pass table (`blender_scripts/passes.py`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Pass {
    /// Colour-managed RGB image.
    Rgb,
    /// Instance ids from the object-index pass.
    Mask,
    /// Metric depth.
    Depth,
    /// Surface normals.
    Normal,
    /// The material's base colour (metals: their colour).
    Albedo,
    /// Computed shadow amount.
    Shadow,
}

/// Where the bridge puts a pass's data (the keys of the `files` of its reply).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    /// The colour-managed `rgb.png`, copied as it is.
    RgbPng,
    /// Layers of the multilayer `passes.exr` of the final render.
    PassesExr,
    /// The same layers of the shadow pass's own render, `shadow.exr`: direct light only,
    /// every surface a white diffuse BSDF, lights white, the light without object shadows in
    /// red and with them in green (`blender_scripts/builder.py`, `OneRenderShadow`).
    ShadowExr,
}

/// The colour layout of a published PNG.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PngKind {
    /// 8-bit palette (the instance mask).
    Palette8,
    /// 8-bit greyscale.
    Gray8,
    /// 8-bit RGB.
    Rgb8,
    /// 16-bit greyscale.
    Gray16,
    /// 16-bit RGB.
    Rgb16,
}

/// The value a pass's PNG holds where the camera sees nothing.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(untagged)]
pub enum Background {
    /// One grey value.
    Gray(u16),
    /// One RGB value.
    Rgb([u16; 3]),
}

/// How a pass is encoded, as written under `passes.<name>` into every metadata file.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Encoding {
    /// File format.
    pub format: &'static str,
    /// Bits per channel.
    pub bits: u8,
    /// What the channels hold.
    pub channels: &'static str,
    /// Coordinate space of vectors.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub space: Option<&'static str>,
    /// How to turn values back into quantities.
    pub encoding: &'static str,
    /// Quantity per unit.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scale: Option<f64>,
    /// Value where the camera sees nothing.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub background: Option<Background>,
    /// Value where the quantity is undefined.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub undefined: Option<u8>,
    /// When the quantity is undefined.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub undefined_when: Option<&'static str>,
}

/// How `clevrtex export` stores a pass in a WebDataset sample. Data that is not a colour
/// (ids, metres, vectors, fractions) is a NumPy array: a colour decoder
/// (`webdataset`'s `.decode("rgb")`, Hugging Face's `Image`) cannot mistake it for a picture.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WebdatasetForm {
    /// The PNG file as it is (a colour image).
    Png,
    /// A NumPy `.npy` array (C order, little-endian), decoded from the PNG with the pass's
    /// encoding: `descr` the NumPy dtype (`|u1`, `<f4`), `channels` 1 for `(H, W)`, 3 for
    /// `(H, W, 3)`.
    Npy {
        /// NumPy dtype string.
        descr: &'static str,
        /// Values per pixel.
        channels: u8,
    },
}

/// Everything about one pass that is data (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PassSpec {
    /// The pass.
    pub pass: Pass,
    /// Its name in scene files, on the command line and in the bridge's table.
    pub name: &'static str,
    /// Where its data comes from.
    pub source: Source,
    /// EXR layers read, as (layer, channel letters): `("Normal", "XYZ")` is the channels
    /// `ViewLayer.Normal.X`, `.Y` and `.Z`. Empty for passes that are not EXR data.
    pub exr_layers: &'static [(&'static str, &'static str)],
    /// File name suffix after the stem: `<stem><suffix>.png`.
    pub file_suffix: &'static str,
    /// The metadata key naming the pass's file (`<pass>_filename`; `image_filename` for rgb).
    pub metadata_key: &'static str,
    /// The pass's key (extension) in a WebDataset sample (`clevrtex export`).
    pub webdataset_key: &'static str,
    /// How `clevrtex export` stores it under that key.
    pub webdataset_form: WebdatasetForm,
    /// What a reader gets from that key: dtype, shape and units (the docs and the dataset
    /// card print it).
    pub webdataset_doc: &'static str,
    /// The PNG written.
    pub png: PngKind,
    /// The encoding written into the metadata.
    pub encoding: Encoding,
}

const fn encoding(bits: u8, channels: &'static str, encoding: &'static str) -> Encoding {
    Encoding {
        format: "png",
        bits,
        channels,
        space: None,
        encoding,
        scale: None,
        background: None,
        undefined: None,
        undefined_when: None,
    }
}

/// The table, in [`Pass::ALL`] order.
const SPECS: [PassSpec; 6] = [
    PassSpec {
        pass: Pass::Rgb,
        name: "rgb",
        source: Source::RgbPng,
        exr_layers: &[],
        file_suffix: "",
        metadata_key: "image_filename",
        webdataset_key: "png",
        webdataset_form: WebdatasetForm::Png,
        webdataset_doc: "the 8-bit sRGB PNG, (H, W, 3)",
        png: PngKind::Rgb8,
        encoding: encoding(
            8,
            "RGB",
            "colour-managed render (view transform and look of `render`), sRGB",
        ),
    },
    PassSpec {
        pass: Pass::Mask,
        name: "mask",
        source: Source::PassesExr,
        exr_layers: &[("IndexOB", "X")],
        file_suffix: "_flat",
        metadata_key: "mask_filename",
        webdataset_key: "mask.npy",
        webdataset_form: WebdatasetForm::Npy {
            descr: "|u1",
            channels: 1,
        },
        webdataset_doc: "uint8 (H, W) object ids: 0 background, i = objects[i-1] of the metadata",
        png: PngKind::Palette8,
        encoding: encoding(
            8,
            "palette index",
            "instance id: 0 = background, i = objects[i-1]; exact object-index pass, never anti-aliased",
        ),
    },
    PassSpec {
        pass: Pass::Depth,
        name: "depth",
        source: Source::PassesExr,
        exr_layers: &[("Depth", "Z")],
        file_suffix: "_depth_0001",
        metadata_key: "depth_filename",
        webdataset_key: "depth.npy",
        webdataset_form: WebdatasetForm::Npy {
            descr: "<f4",
            channels: 1,
        },
        webdataset_doc: "float32 (H, W) planar depth in metres (along the camera's view axis); background +inf",
        png: PngKind::Gray16,
        encoding: Encoding {
            scale: Some(DEPTH_SCALE_M),
            background: Some(Background::Gray(DEPTH_BACKGROUND)),
            ..encoding(
                16,
                "gray",
                "planar depth (distance along the camera's view axis, metres) = value * scale",
            )
        },
    },
    PassSpec {
        pass: Pass::Normal,
        name: "normal",
        source: Source::PassesExr,
        exr_layers: &[("Normal", "XYZ")],
        file_suffix: "_normal_0001",
        metadata_key: "normal_filename",
        webdataset_key: "normal.npy",
        webdataset_form: WebdatasetForm::Npy {
            descr: "<f4",
            channels: 3,
        },
        webdataset_doc: "float32 (H, W, 3) world-space unit normals (x, y, z); background (0, 0, 0)",
        png: PngKind::Rgb16,
        encoding: Encoding {
            space: Some("world"),
            background: Some(Background::Rgb(NORMAL_BACKGROUND)),
            ..encoding(16, "RGB = XYZ", "n = value / 65535 * 2 - 1")
        },
    },
    PassSpec {
        pass: Pass::Albedo,
        name: "albedo",
        source: Source::PassesExr,
        exr_layers: &[("BaseCol", "RGB")],
        file_suffix: "_albedo_0001",
        metadata_key: "albedo_filename",
        webdataset_key: "albedo.png",
        webdataset_form: WebdatasetForm::Png,
        webdataset_doc: "the 8-bit PNG, (H, W, 3): the material's base colour, linear values encoded with the sRGB transfer curve",
        png: PngKind::Rgb8,
        encoding: encoding(
            8,
            "RGB",
            "the material's base colour (metals: their colour; a colour AOV), linear values encoded with the sRGB transfer curve",
        ),
    },
    PassSpec {
        pass: Pass::Shadow,
        name: "shadow",
        source: Source::ShadowExr,
        exr_layers: &[("DiffDir", "RGB")],
        file_suffix: "_shadow_0001",
        metadata_key: "shadow_filename",
        webdataset_key: "shadow.npy",
        webdataset_form: WebdatasetForm::Npy {
            descr: "<f4",
            channels: 1,
        },
        webdataset_doc: "float32 (H, W) shadow amount in [0, 1] (1 - shadowed / unshadowed direct light); 0 where undefined",
        png: PngKind::Gray8,
        encoding: Encoding {
            undefined: Some(SHADOW_UNDEFINED),
            // `SHADOW_EPS` and `SHADOW_REL_EPS` written out (a test checks they agree).
            undefined_when: Some(
                "unshadowed direct light luminance < max(0.0001, 0.01 x its 99th percentile over the image)",
            ),
            ..encoding(
                8,
                "gray",
                "shadow = value / 255 = 1 - direct light / the same with objects casting no shadows, both on white diffuse surfaces (luminance)",
            )
        },
    },
];

impl Pass {
    /// Every pass, in canonical order.
    pub const ALL: [Pass; 6] = [
        Pass::Rgb,
        Pass::Mask,
        Pass::Depth,
        Pass::Normal,
        Pass::Albedo,
        Pass::Shadow,
    ];

    /// The pass's entry in the pass table.
    pub fn spec(self) -> &'static PassSpec {
        &SPECS[self as usize]
    }

    /// The pass's name as used on the command line and in files.
    pub fn name(self) -> &'static str {
        self.spec().name
    }

    /// The pass called `name`, if any.
    pub fn from_name(name: &str) -> Option<Pass> {
        Pass::ALL.into_iter().find(|p| p.name() == name)
    }

    /// The metadata key naming the pass's file (`<pass>_filename`; `image_filename` for rgb).
    pub fn metadata_key(self) -> &'static str {
        self.spec().metadata_key
    }
}

impl PassSpec {
    /// The full EXR channel names this pass reads, layer by layer (`ViewLayer.<layer>.<c>`).
    pub fn exr_channels(&self) -> Vec<Vec<String>> {
        self.exr_layers
            .iter()
            .map(|(layer, cs)| {
                cs.chars()
                    .map(|c| format!("ViewLayer.{layer}.{c}"))
                    .collect()
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_is_in_canonical_order() {
        for (i, p) in Pass::ALL.into_iter().enumerate() {
            assert_eq!(SPECS[i].pass, p);
            assert_eq!(Pass::from_name(p.name()), Some(p));
        }
    }

    #[test]
    fn written_out_constants_agree() {
        assert_eq!(
            Pass::Shadow.spec().encoding.undefined_when,
            Some(
                format!(
                    "unshadowed direct light luminance < max({SHADOW_EPS}, {SHADOW_REL_EPS} x its \
                     99th percentile over the image)"
                )
                .as_str()
            )
        );
        assert_eq!(
            Pass::Normal.spec().exr_channels(),
            vec![vec![
                "ViewLayer.Normal.X".to_string(),
                "ViewLayer.Normal.Y".into(),
                "ViewLayer.Normal.Z".into()
            ]]
        );
    }
}
