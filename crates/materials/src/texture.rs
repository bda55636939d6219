//! The checks of a user material's files before any image is rendered: the `.blend` itself
//! ([`MAX_BLEND_BYTES`]) and every image texture it reads ([`check_texture`]: inside the
//! material folder, a regular file, at most [`MAX_TEXTURE_BYTES`] and
//! [`MAX_TEXTURE_SIDE`] pixels a side, and decodable to the end). Blender renders a texture
//! it cannot read as pink without failing, so these run first, in Rust, on files from
//! elsewhere (docs/security.md).

use std::path::{Path, PathBuf};

use crate::{Error, ErrorKind};

/// Largest `.blend` file a user material may be (the public generator's are 1-3 MB; the
/// textures are separate files).
pub const MAX_BLEND_BYTES: u64 = 256 << 20;
/// Largest image file a user material may read.
pub const MAX_TEXTURE_BYTES: u64 = 256 << 20;
/// Largest side, in pixels, of any image a user material loads: the textures of a `.blend`
/// node group ([`check_texture`]) and the maps of a PBR folder ([`crate::pbr`]) alike. The
/// one cap, chosen from memory: an N x N map decoded as 8-bit RGBA is 4N^2 bytes, in every
/// Blender worker (and once more here while [`check_texture`] decodes it). 8192 is 256 MiB a
/// map, about 1 GiB for a PBR material's four maps (colour, normal, roughness,
/// displacement) per worker; 16,384 would be 1 GiB a map and 4 GiB a material per worker,
/// several materials and workers over. The field's libraries fit: the ClevrTex v2 materials
/// are 3K, Poly Haven ships 1K to 8K (some 16K) and ambientCG 1K to 8K; of a PBR folder
/// with several resolutions the largest within the cap is used.
pub const MAX_TEXTURE_SIDE: u32 = 8192;

/// Why an image of `w` x `h` pixels may not be loaded, if it may not: a side of 0 or over
/// [`MAX_TEXTURE_SIDE`]. The message follows the image's name ("`x.png` is ...").
pub(crate) fn side_problem(w: u32, h: u32) -> Option<String> {
    (w == 0 || h == 0 || w.max(h) > MAX_TEXTURE_SIDE).then(|| {
        format!("is {w}x{h} pixels; a side may be 1 to {MAX_TEXTURE_SIDE} (the cap on a loaded texture)")
    })
}

/// Where `reference` (an image path as a `.blend` stores it: `//textures/x.jpg` relative to
/// the `.blend`, or absolute) points, for a `.blend` at `blend`.
pub fn resolve_reference(blend: &Path, reference: &str) -> PathBuf {
    let dir = blend.parent().unwrap_or(Path::new("."));
    match reference.strip_prefix("//") {
        Some(rel) => dir.join(rel.replace('\\', "/")),
        None => PathBuf::from(reference),
    }
}

/// Check the texture `reference` of material `material` (from the `.blend` at `blend`, shown
/// as `shown`) against the folder `root`: it must resolve to a regular file inside `root`
/// (no link out), of at most [`MAX_TEXTURE_BYTES`], a PNG, JPEG or TIFF of at most
/// [`MAX_TEXTURE_SIDE`] pixels a side that decodes to the end. Returns the canonical path.
pub fn check_texture(
    material: &str,
    shown: &str,
    blend: &Path,
    root: &Path,
    reference: &str,
) -> Result<PathBuf, Error> {
    let path = resolve_reference(blend, reference);
    let err = |message: String, hint: &str| {
        Error::new(
            ErrorKind::BadValue,
            shown,
            "",
            format!("material `{material}`: {message}"),
            hint,
        )
    };
    let canon = path.canonicalize().map_err(|e| {
        err(
            format!(
                "texture `{reference}` (`{}`) cannot be read: {e}",
                path.display()
            ),
            "put the texture beside the `.blend` where it expects it (usually `textures/`), or \
             remove the material from the folder; Blender would render it pink",
        )
    })?;
    let root = root.canonicalize().unwrap_or_else(|_| root.to_path_buf());
    if !canon.starts_with(&root) {
        return Err(err(
            format!(
                "texture `{reference}` (`{}`) is outside the material folder `{}`",
                canon.display(),
                root.display()
            ),
            "copy the texture into the material folder and reference it relative to the \
             `.blend` (`//textures/...`)",
        ));
    }
    let meta = std::fs::metadata(&canon).map_err(|e| {
        err(
            format!("texture `{}` cannot be read: {e}", canon.display()),
            "check the file's permissions",
        )
    })?;
    if !meta.is_file() {
        return Err(err(
            format!("texture `{}` is not a regular file", canon.display()),
            "reference an image file",
        ));
    }
    if meta.len() > MAX_TEXTURE_BYTES {
        return Err(err(
            format!(
                "texture `{}` is {} bytes, more than the {} allowed",
                canon.display(),
                meta.len(),
                MAX_TEXTURE_BYTES
            ),
            "use a smaller resolution of the texture (3K or 4K)",
        ));
    }
    let bad = |problem: String| {
        err(
            format!("texture `{}` {problem}", canon.display()),
            "save the texture again as PNG, JPEG or TIFF, or use a smaller resolution",
        )
    };
    let reader = image::ImageReader::open(&canon)
        .and_then(|r| r.with_guessed_format())
        .map_err(|e| bad(format!("cannot be read: {}", e.to_string().trim_end())))?;
    match reader.format() {
        Some(image::ImageFormat::Png | image::ImageFormat::Jpeg | image::ImageFormat::Tiff) => {}
        _ => {
            return Err(bad(
                "is not a PNG, JPEG or TIFF file (the formats user materials may read)".into(),
            ))
        }
    }
    let (w, h) = reader.into_dimensions().map_err(|e| {
        bad(format!(
            "has an unreadable header: {}",
            e.to_string().trim_end()
        ))
    })?;
    if let Some(problem) = side_problem(w, h) {
        return Err(bad(problem));
    }
    // Decode to the end: a truncated or corrupt file fails here, not as pink in Blender.
    let mut reader = image::ImageReader::open(&canon)
        .and_then(|r| r.with_guessed_format())
        .map_err(|e| bad(format!("cannot be read: {}", e.to_string().trim_end())))?;
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_TEXTURE_SIDE);
    limits.max_image_height = Some(MAX_TEXTURE_SIDE);
    limits.max_alloc = Some(u64::from(MAX_TEXTURE_SIDE).pow(2) * 8);
    reader.limits(limits);
    reader
        .decode()
        .map_err(|e| bad(format!("does not decode: {}", e.to_string().trim_end())))?;
    Ok(canon)
}

/// Check a `.blend` file's size (at most [`MAX_BLEND_BYTES`]) without reading it.
pub(crate) fn blend_size_problem(path: &Path) -> Option<String> {
    match std::fs::metadata(path) {
        Err(e) => Some(format!("cannot read the `.blend` file: {e}")),
        Ok(m) if m.len() > MAX_BLEND_BYTES => Some(format!(
            "the `.blend` file is {} bytes, more than the {MAX_BLEND_BYTES} allowed",
            m.len()
        )),
        Ok(_) => None,
    }
}
