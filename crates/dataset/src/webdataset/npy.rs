//! A pass's PNG decoded into its NumPy `.npy` array ([`pass_npy`], [`npy_header`]).

use clevrtex_scene::passes::WebdatasetForm;
use clevrtex_scene::Pass;

/// The `.npy` of a pass's PNG `bytes` (of the layout and encoding of the pass table:
/// [`clevrtex_scene::passes`]): the mask's ids as `uint8 (H, W)` (a palette's indices, or an
/// 8-bit grey image's values: the published ClevrTex's masks); depth, normal and shadow as
/// `float32` arrays of the one decode of every reader ([`crate::quantity::decode`]: metres
/// with background `+inf`, unit normals with background `(0, 0, 0)`, the shadow amount in
/// `[0, 1]`). `Err` says why not, one line.
pub fn pass_npy(pass: Pass, bytes: &[u8]) -> Result<Vec<u8>, String> {
    decoded_npy(pass, &crate::png::decode(bytes)?)
}

/// [`pass_npy`] of a PNG already decoded (and checked: [`crate::dataset::check_pass_png`]).
pub fn decoded_npy(pass: Pass, png: &crate::png::DecodedPng) -> Result<Vec<u8>, String> {
    let WebdatasetForm::Npy { descr, channels } = pass.spec().webdataset_form else {
        return Err(format!(
            "the {} pass is not stored as an array",
            pass.name()
        ));
    };
    let (w, h) = (png.width as usize, png.height as usize);
    let mut out = npy_header(
        descr,
        &[h, w, usize::from(channels)][..if channels == 1 { 2 } else { 3 }],
    );
    if pass == Pass::Mask {
        if png.bits != 8 || png.channels != 1 {
            return Err(format!(
                "is a {}-bit {}-channel PNG, not the 8-bit 1-channel mask pass",
                png.bits, png.channels
            ));
        }
        out.extend(png.data.iter().map(|&v| v as u8));
        return Ok(out);
    }
    let q = crate::quantity::decode(pass, png)?;
    for v in q.data {
        out.extend(v.to_le_bytes());
    }
    Ok(out)
}

/// The header of a NumPy `.npy` file (format version 1.0) of C-order `shape` and dtype
/// `descr`, padded with spaces so the data starts at a multiple of 64 bytes (NumPy's
/// `numpy.lib.format`). Nothing in it depends on the machine: the same array, the same bytes.
pub fn npy_header(descr: &str, shape: &[usize]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(ToString::to_string).collect();
    let shape = match dims.len() {
        1 => format!("({},)", dims[0]),
        _ => format!("({})", dims.join(", ")),
    };
    let mut dict = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}");
    // magic (6) + version (2) + length (2) + dict + '\n', to a multiple of 64.
    let pad = (64 - (10 + dict.len() + 1) % 64) % 64;
    dict.push_str(&" ".repeat(pad));
    dict.push('\n');
    let mut out = Vec::with_capacity(10 + dict.len());
    out.extend(b"\x93NUMPY\x01\x00");
    out.extend((dict.len() as u16).to_le_bytes());
    out.extend(dict.as_bytes());
    out
}
