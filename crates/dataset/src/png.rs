//! A dataset's PNGs read back: the size from the header ([`size`]) and the samples without
//! any conversion ([`decode`]), for `verify` and `export` (and `clevrtex-render`'s checks of
//! what Blender wrote, `clevrtex_render::post::decode_png`).

/// Width and height from a PNG's header, when `bytes` starts like a PNG (`verify`, and the
/// RGB image Blender writes, checked against the size asked for).
pub fn size(bytes: &[u8]) -> Option<(u32, u32)> {
    if bytes.len() < 24 || &bytes[..8] != b"\x89PNG\r\n\x1a\n" || &bytes[12..16] != b"IHDR" {
        return None;
    }
    let w = u32::from_be_bytes(bytes[16..20].try_into().ok()?);
    let h = u32::from_be_bytes(bytes[20..24].try_into().ok()?);
    Some((w, h))
}

/// A decoded PNG: samples as `u16` (8-bit files keep their 0-255 values), row-major,
/// interleaved channels; palette files give their indices (one channel).
#[derive(Debug, Clone)]
pub struct DecodedPng {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Bits per sample (8 or 16).
    pub bits: u8,
    /// Channels per pixel (1 for grey and palette, 3 for RGB, 4 for RGBA).
    pub channels: usize,
    /// Whether the file is a palette PNG.
    pub palette: bool,
    /// The samples.
    pub data: Vec<u16>,
}

/// Decode a PNG from `bytes`, without any conversion (palette indices stay indices, 16-bit
/// stays 16-bit); its declared size is bounded before anything is allocated for it. `Err`
/// says what is wrong, in one line (callers name the file).
pub fn decode(bytes: &[u8]) -> Result<DecodedPng, String> {
    let bad = |problem: String| problem;
    let mut dec = png::Decoder::new(std::io::Cursor::new(bytes));
    dec.set_transformations(png::Transformations::IDENTITY);
    let mut reader = dec
        .read_info()
        .map_err(|e| bad(format!("not a PNG: {e}")))?;
    // The size from the header, bounded before anything is allocated for it: a PNG read
    // back from a dataset is not trusted, and a few hundred bytes can declare 200000x200000.
    let (w, h) = (reader.info().width, reader.info().height);
    let max = clevrtex_scene::scene_file::MAX_IMAGE_SIDE;
    if w > max || h > max {
        return Err(bad(format!(
            "declares {w}x{h} pixels, more than the {max}x{max} any clevrtex image has"
        )));
    }
    let size = reader
        .output_buffer_size()
        .ok_or_else(|| bad("image too large".into()))?;
    let mut buf = vec![0; size];
    let info = reader
        .next_frame(&mut buf)
        .map_err(|e| bad(format!("cannot decode PNG: {e}")))?;
    buf.truncate(info.buffer_size());
    let bits = match info.bit_depth {
        png::BitDepth::Eight => 8,
        png::BitDepth::Sixteen => 16,
        other => return Err(bad(format!("unsupported bit depth {other:?}"))),
    };
    let data = if bits == 16 {
        buf.chunks_exact(2)
            .map(|c| u16::from_be_bytes([c[0], c[1]]))
            .collect()
    } else {
        buf.iter().map(|&b| b as u16).collect()
    };
    Ok(DecodedPng {
        width: info.width,
        height: info.height,
        bits,
        channels: info.color_type.samples(),
        palette: info.color_type == png::ColorType::Indexed,
        data,
    })
}

/// An 8-bit RGB PNG of `width x height` interleaved `rgb` (the export's cropped images).
pub fn encode_rgb8(width: u32, height: u32, rgb: &[u8]) -> Result<Vec<u8>, png::EncodingError> {
    let mut bytes = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut bytes, width, height);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut w = enc.write_header()?;
        w.write_image_data(rgb)?;
        w.finish()?;
    }
    Ok(bytes)
}
