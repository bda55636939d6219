//! The typed, bounded view of a sample's metadata ([`MetadataView`], [`check_metadata`]: errors
//! name the file and the key) and the mode of a pass PNG from its header
//! ([`png_mode_problem`]).

use serde_json::Value;

use crate::layout;
use clevrtex_scene::scene_file::MAX_IMAGE_SIDE;
use clevrtex_scene::Pass;

/// Why the PNG `bytes` of a sample's `pass` are not of the mode every reader takes for it,
/// from the header alone (before any decoder allocates), or `None` when they are, or when
/// they are no PNG at all (the decoder then says so). The mask must be 8-bit object ids, one
/// channel: a palette index as clevrtex and the public ClevrTex write it, or greyscale (an RGB
/// `_flat.png` would be read as three ids a pixel, a 16-bit one as ids past 255); the other
/// passes must have their pass-table mode ([`clevrtex_scene::passes::PngKind`]). Used by `verify`,
/// `preview`, `report`, `materials measure`, `eval`'s ground truth and the Python `Dataset`.
pub fn png_mode_problem(bytes: &[u8], pass: Pass) -> Option<String> {
    use clevrtex_scene::passes::PngKind;
    if bytes.len() < 26 || &bytes[..8] != b"\x89PNG\r\n\x1a\n" || &bytes[12..16] != b"IHDR" {
        return None;
    }
    let (depth, colour) = (bytes[24], bytes[25]);
    let mode = |depth: u8, colour: u8| {
        let c = match colour {
            0 => "greyscale",
            2 => "RGB",
            3 => "palette",
            4 => "greyscale-alpha",
            6 => "RGBA",
            _ => "unknown-colour",
        };
        format!("{depth}-bit {c}")
    };
    let ok = match pass.spec().png {
        PngKind::Palette8 | PngKind::Gray8 if pass == Pass::Mask => {
            depth == 8 && (colour == 0 || colour == 3)
        }
        PngKind::Palette8 => (depth, colour) == (8, 3),
        PngKind::Gray8 => (depth, colour) == (8, 0),
        PngKind::Rgb8 => (depth, colour) == (8, 2),
        PngKind::Gray16 => (depth, colour) == (16, 0),
        PngKind::Rgb16 => (depth, colour) == (16, 2),
    };
    if ok {
        return None;
    }
    let want = match pass.spec().png {
        _ if pass == Pass::Mask => "8-bit palette or greyscale object ids".to_string(),
        PngKind::Palette8 => mode(8, 3),
        PngKind::Gray8 => mode(8, 0),
        PngKind::Rgb8 => mode(8, 2),
        PngKind::Gray16 => mode(16, 0),
        PngKind::Rgb16 => mode(16, 2),
    };
    Some(format!(
        "is a {} PNG, but a {} pass must be {want}",
        mode(depth, colour),
        pass.name()
    ))
}

/// The checks every reader that packs or measures a pass applies to its PNG `bytes` (the file
/// `name`, for messages) before using its pixels: the header's size against the metadata's
/// `size` (before anything is decoded, so a header declaring 100000x100000 is never
/// allocated), the mode ([`png_mode_problem`]), the decode itself (the side cap of
/// [`crate::png::decode`], CRCs, truncation), the decoded size again, and for the mask no id
/// past the metadata's `num_objects`. `size` is `None` for the downloaded ClevrTex (its
/// metadata records none): the caller then compares the passes with each other. Used by
/// `verify` and `export`. `Err` is one line naming the file.
pub fn check_pass_png(
    name: &str,
    bytes: &[u8],
    pass: Pass,
    size: Option<(u32, u32)>,
    num_objects: usize,
) -> Result<crate::png::DecodedPng, String> {
    if let (Some((w, h)), Some((pw, ph))) = (size, crate::png::size(bytes)) {
        if (pw, ph) != (w, h) {
            return Err(format!("`{name}` is {pw}x{ph} (the metadata says {w}x{h})"));
        }
    }
    if let Some(problem) = png_mode_problem(bytes, pass) {
        return Err(format!("`{name}` {problem}"));
    }
    let png = crate::png::decode(bytes).map_err(|problem| format!("`{name}`: {problem}"))?;
    if let Some((w, h)) = size {
        if (png.width, png.height) != (w, h) {
            return Err(format!(
                "`{name}` is {}x{} (the metadata says {w}x{h})",
                png.width, png.height
            ));
        }
    }
    if pass == Pass::Mask {
        if let Some(bad) = png
            .data
            .iter()
            .map(|&v| usize::from(v))
            .filter(|&v| v > num_objects)
            .min()
        {
            return Err(format!(
                "mask has id {bad} but the metadata has {num_objects} objects"
            ));
        }
    }
    Ok(png)
}

/// A value of a sample's metadata that is not what a reader needs: the file and the key.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("metadata `{file}` key `{key}` {what}")]
pub struct MetadataError {
    /// The metadata file, as the caller names it.
    pub file: String,
    /// The key (dotted, `objects[i].visible_pixels` for a list's entry).
    pub key: String,
    /// What is wrong (`is "x", not a whole number from 1 to 4096`).
    pub what: String,
}

/// A metadata value for a message: its JSON, cut at 80 characters.
pub fn short(v: &Value) -> String {
    let t = v.to_string();
    if t.chars().count() > 80 {
        format!("{}...", t.chars().take(80).collect::<String>())
    } else {
        t
    }
}

/// The values of a sample's metadata that size or index something, typed and bounded before
/// anything is sized by them: the image's size (at most [`MAX_IMAGE_SIDE`] a side), the
/// objects (at most 255, a list as long as `num_objects`), the visibility threshold and each
/// object's visible pixels (at most the image's pixels), the passes listed; and the run's
/// `config_hash` (a string when present) that `verify` compares with the manifest.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MetadataView {
    /// `render.width`.
    pub width: u32,
    /// `render.height`.
    pub height: u32,
    /// `num_objects`.
    pub num_objects: usize,
    /// `visibility_threshold_px` (0 when absent: the published data has none).
    pub visibility_threshold_px: u64,
    /// Each object's `visible_pixels`, when present.
    pub visible_pixels: Vec<Option<u64>>,
    /// `image_index`, when a whole number.
    pub image_index: Option<u64>,
    /// The passes the metadata's `passes` names (unknown names left out).
    pub passes: Vec<Pass>,
    /// `config_hash`: the config hash of the `generate` run that made the sample (absent:
    /// `None`, in older datasets, the published data and `render`'s samples).
    pub config_hash: Option<String>,
}

/// A whole number from the metadata at `key` (dotted), within `lo..=hi`.
pub fn meta_int(
    meta: &Value,
    file: &str,
    key: &str,
    lo: u64,
    hi: u64,
) -> Result<u64, MetadataError> {
    let v = key.split('.').fold(meta, |v, k| &v[k]);
    match v.as_u64() {
        Some(n) if (lo..=hi).contains(&n) => Ok(n),
        _ => Err(MetadataError {
            file: file.to_string(),
            key: key.to_string(),
            what: format!("is {v}, not a whole number from {lo} to {hi}"),
        }),
    }
}

impl MetadataView {
    /// The typed view of `meta` (a JSON object) of the file `file`; the error names the key.
    pub fn of(meta: &Value, file: &str) -> Result<MetadataView, MetadataError> {
        let err = |key: &str, what: String| MetadataError {
            file: file.to_string(),
            key: key.to_string(),
            what,
        };
        let side = u64::from(MAX_IMAGE_SIDE);
        let width = meta_int(meta, file, "render.width", 1, side)? as u32;
        let height = meta_int(meta, file, "render.height", 1, side)? as u32;
        let pixels = u64::from(width) * u64::from(height);
        let n = meta_int(meta, file, "num_objects", 0, 255)? as usize;
        // The split names a folder or shard in `export` and a report row: `../x` is refused by
        // every reader alike (`verify` passed it while `export` refused it).
        check_split(meta, file)?;
        let config_hash = match meta.get("config_hash") {
            None => None,
            Some(Value::String(h)) => Some(h.clone()),
            Some(v) => return Err(err("config_hash", format!("is {}, not a string", short(v)))),
        };
        let threshold = match meta.get("visibility_threshold_px") {
            None => 0,
            Some(_) => meta_int(meta, file, "visibility_threshold_px", 0, pixels)?,
        };
        let Some(objects) = meta["objects"].as_array() else {
            return Err(err(
                "objects",
                format!("is {}, not a list", short(&meta["objects"])),
            ));
        };
        if objects.len() != n {
            return Err(err(
                "objects",
                format!("has {} entries but `num_objects` is {n}", objects.len()),
            ));
        }
        let mut visible = Vec::with_capacity(n);
        for (i, o) in objects.iter().enumerate() {
            visible.push(match o.get("visible_pixels") {
                None => None,
                Some(v) => match v.as_u64() {
                    Some(p) if p <= pixels => Some(p),
                    _ => {
                        return Err(err(
                            &format!("objects[{i}].visible_pixels"),
                            format!(
                                "is {}, not a whole number from 0 to the image's {pixels} pixels",
                                short(v)
                            ),
                        ))
                    }
                },
            });
        }
        Ok(MetadataView {
            width,
            height,
            num_objects: n,
            visibility_threshold_px: threshold,
            visible_pixels: visible,
            image_index: meta["image_index"].as_u64(),
            passes: meta["passes"]
                .as_object()
                .map(|m| m.keys().filter_map(|k| Pass::from_name(k)).collect())
                .unwrap_or_default(),
            config_hash,
        })
    }
}

/// The check every reader that shows or measures a sample applies to its metadata (`preview`,
/// `report`): a JSON object; ours (with `render`) must give a whole [`MetadataView`]; the
/// downloaded ClevrTex's (no `render`) must type its keys that are there (`objects` a list,
/// `num_objects` 0 to 255 and equal to its length). The error names the file and key.
pub fn check_metadata(meta: &Value, file: &str) -> Result<(), MetadataError> {
    let err = |key: &str, what: String| MetadataError {
        file: file.to_string(),
        key: key.to_string(),
        what,
    };
    if !meta.is_object() {
        return Err(err(
            "(top level)",
            format!("is {}, not an object", short(meta)),
        ));
    }
    if meta.get("render").is_some() {
        return MetadataView::of(meta, file).map(|_| ());
    }
    let objects = match meta.get("objects") {
        None => None,
        Some(Value::Array(a)) => Some(a.len()),
        Some(v) => return Err(err("objects", format!("is {}, not a list", short(v)))),
    };
    check_split(meta, file)?;
    if meta.get("num_objects").is_some() {
        let n = meta_int(meta, file, "num_objects", 0, 255)? as usize;
        if objects.is_some_and(|len| len != n) {
            return Err(err(
                "objects",
                format!(
                    "has {} entries but `num_objects` is {n}",
                    objects.unwrap_or(0)
                ),
            ));
        }
    }
    Ok(())
}

/// [`check_metadata`] of a metadata file's `bytes` (the file `file`, for messages): JSON first
/// (serde_json's: no NaN, nesting bounded), then the checks every reader makes. For readers
/// that hand the bytes on (the Python `Dataset`): the CLI's rules, not a second copy of them.
pub fn check_metadata_bytes(bytes: &[u8], file: &str) -> Result<(), String> {
    let meta: Value = serde_json::from_slice(bytes)
        .map_err(|e| format!("`{file}` is not valid metadata: {e}"))?;
    check_metadata(&meta, file).map_err(|e| e.to_string())
}

/// The passes whose `*_filename` key ([`Pass::metadata_key`], the pass table's) the metadata `meta` of
/// `stem` sets, in pass-table order: each must name the layout's file (or be null, absent:
/// not written). File names come from the layout, never from the metadata.
pub fn listed_passes(meta: &Value, file: &str, stem: &str) -> Result<Vec<Pass>, MetadataError> {
    let mut out = Vec::new();
    for pass in Pass::ALL {
        let key = pass.metadata_key();
        let want = layout::pass_file(stem, pass);
        match &meta[key] {
            Value::Null => {}
            Value::String(name) if *name == want => out.push(pass),
            other => {
                return Err(MetadataError {
                    file: file.to_string(),
                    key: key.to_string(),
                    what: format!("is {other}, not the layout's `{want}` (or null)"),
                })
            }
        }
    }
    Ok(out)
}

/// The metadata's `split`, checked without knowing the variant: `test`, `val`, `train`, none,
/// or (the public generator records its variant there) a name a variant may have; anything
/// else (`../x`) is refused by every reader alike. [`recorded_split`] then reads it.
fn check_split(meta: &Value, file: &str) -> Result<(), MetadataError> {
    match &meta["split"] {
        Value::String(s) if clevrtex_scene::names::variant_name_problem(s).is_none() => Ok(()),
        split => recorded_split(split, "", file).map(|_| ()),
    }
}

/// The split a sample's metadata records in `split`: `Some` for `test`, `val` or `train`;
/// `None` where it records none: `split` absent, or the name of the sample's `variant` (the
/// public generator, karazijal/clevrtex-generation, writes the variant there, so the published
/// ClevrTex is split by position: [`crate::dataset::splits()`]). Anything else is an error naming the file and
/// the key.
pub fn recorded_split(
    split: &Value,
    variant: &str,
    file: &str,
) -> Result<Option<layout::Split>, MetadataError> {
    let err = |what: String| MetadataError {
        file: file.to_string(),
        key: "split".into(),
        what,
    };
    match split {
        Value::Null => Ok(None),
        Value::String(s) if s == variant => Ok(None),
        Value::String(s) => layout::Split::parse(s).map(Some).ok_or_else(|| {
            err(format!(
                "is `{}`, not test, val or train",
                clevrtex_scene::text::printable(s)
            ))
        }),
        other => Err(err(format!("is {}, not test, val or train", short(other)))),
    }
}
