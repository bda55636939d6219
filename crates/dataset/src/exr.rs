//! The kept EXRs of a dataset (`--keep-exr`) checked without trusting them ([`check_kept`],
//! for `verify`); `clevrtex-render` reads Blender's EXRs with the same cap on channels.

/// Most channels (over all layers) an EXR may declare: Blender's passes file has a few dozen.
pub const MAX_CHANNELS: usize = 256;

/// Most values (pixels times channels) [`check_kept`] decodes to find a damaged EXR: 128 MB of
/// `f32` (a 1024x1024 passes file of 30 channels), whatever the header claims; larger files
/// are checked from their header only.
pub const MAX_CHECKED_VALUES: usize = 1 << 25;

/// Check a kept EXR of a dataset (`verify`; the file is untrusted): its header parses, is not
/// deep, declares at most 256 channels and `size` (width, height) on every layer; when its
/// values fit [`MAX_CHECKED_VALUES`], every pixel decodes (a truncated or garbled file does
/// not). `Err` says what is wrong, in one line.
pub fn check_kept(bytes: &[u8], size: (usize, usize)) -> std::result::Result<(), String> {
    use exr::prelude::*;
    let meta = exr::meta::MetaData::read_from_buffered(std::io::Cursor::new(bytes), false)
        .map_err(|e| format!("is not a readable EXR: {e}"))?;
    let mut values = 0usize;
    let mut channels = 0usize;
    for header in &meta.headers {
        let (w, h) = (header.layer_size.width(), header.layer_size.height());
        if (w, h) != size {
            return Err(format!(
                "declares {w}x{h} pixels (the metadata says {}x{})",
                size.0, size.1
            ));
        }
        if header.deep {
            return Err("holds deep data, which Blender never writes".into());
        }
        channels += header.channels.list.len();
        values = values.saturating_add(w * h * header.channels.list.len());
    }
    if channels > MAX_CHANNELS {
        return Err(format!(
            "declares {channels} channels, more than the {MAX_CHANNELS} read"
        ));
    }
    if values <= MAX_CHECKED_VALUES {
        read()
            .no_deep_data()
            .largest_resolution_level()
            .all_channels()
            .all_layers()
            .all_attributes()
            .from_buffered(std::io::Cursor::new(bytes))
            .map_err(|e| format!("does not decode: {e}"))?;
    }
    Ok(())
}
