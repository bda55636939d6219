//! The checks of a user material's files before any image is rendered ([`bytes_problem`],
//! by [`Expect`]): a `.blend` ([`MAX_BLEND_BYTES`], its header), every image a `.blend` node
//! group reads (files and packed images), every `image` layer of a JSON material and every
//! map of a PBR folder: a format the material may read, at most [`MAX_TEXTURE_BYTES`] and
//! [`MAX_TEXTURE_SIDE`] pixels a side, decodable to the end. Blender renders a texture it
//! cannot read as pink without failing, so these run first, in Rust, on files from
//! elsewhere; the caller reads each file once from inside the material folder and hands
//! Blender a private copy of exactly the bytes checked (`render/src/user_materials/copies.rs`,
//! docs/security.md).

use std::path::Path;

/// Largest `.blend` file a user material may be (the public generator's are 1-3 MB; the
/// textures are separate files).
pub const MAX_BLEND_BYTES: u64 = 256 << 20;
/// Largest image file a user material may read.
pub const MAX_TEXTURE_BYTES: u64 = 256 << 20;
/// Largest side, in pixels, of any image a user material loads: the textures of a `.blend`
/// node group and the maps of a PBR folder ([`crate::pbr`]) alike. The
/// one cap, chosen from memory: an N x N map decoded as 8-bit RGBA is 4N^2 bytes, in every
/// Blender worker (and once more here while [`bytes_problem`] decodes it). 8192 is 256 MiB a
/// map, about 1 GiB for a PBR material's four maps (colour, normal, roughness,
/// displacement) per worker; 16,384 would be 1 GiB a map and 4 GiB a material per worker,
/// several materials and workers over. The field's libraries fit: the ClevrTex v2 materials
/// are 3K, Poly Haven ships 1K to 8K (some 16K) and ambientCG 1K to 8K; of a PBR folder
/// with several resolutions the largest within the cap is used.
pub const MAX_TEXTURE_SIDE: u32 = 8192;

/// Why an image of `w` x `h` pixels may not be loaded, if it may not: a side of 0 or over
/// [`MAX_TEXTURE_SIDE`]. The message follows the image's name ("`x.png` is ...").
pub fn side_problem(w: u32, h: u32) -> Option<String> {
    (w == 0 || h == 0 || w.max(h) > MAX_TEXTURE_SIDE).then(|| {
        format!("is {w}x{h} pixels; a side may be 1 to {MAX_TEXTURE_SIDE} (the cap on a loaded texture)")
    })
}

/// What a file a user material reads must be ([`bytes_problem`]): every file of a user
/// material reaches Blender as one of these, checked by this one function before a run, on
/// the very bytes Blender is then given (`render/src/user_materials/copies.rs`, docs/security.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Expect {
    /// A `.blend` file: at most [`MAX_BLEND_BYTES`], Blender's header (or gzip, zstd).
    Blend,
    /// An image a `.blend` node group reads (a file or packed into the `.blend`) or a JSON
    /// material's `image` layer: a PNG, JPEG or TIFF.
    Texture,
    /// A map of a PBR folder: a PNG, JPEG or OpenEXR of at least `channels` channels.
    PbrMap {
        /// Fewest channels (3 for colour, normal and packed ARM maps).
        channels: u8,
    },
}

impl Expect {
    /// Largest file of this kind.
    pub fn max_bytes(self) -> u64 {
        match self {
            Expect::Blend => MAX_BLEND_BYTES,
            Expect::Texture | Expect::PbrMap { .. } => MAX_TEXTURE_BYTES,
        }
    }

    /// The hint of a refusal of a file of this kind.
    pub fn hint(self) -> &'static str {
        match self {
            Expect::Blend => {
                "save it again from Blender (File > Save), or remove it from the material folder"
            }
            Expect::Texture => {
                "save the texture again as PNG, JPEG or TIFF, or use a smaller resolution"
            }
            Expect::PbrMap { .. } => {
                "download the map again (PNG, JPEG or OpenEXR), or remove it from the folder"
            }
        }
    }
}

/// Why `bytes`, the whole of a file of a user material, cannot be what `expect` says, if
/// they cannot: the message follows the file's name (" is not a PNG, ..."). An image must be
/// of a format `expect` allows, its header at most [`MAX_TEXTURE_SIDE`] pixels a side, and it
/// must decode to the end (a truncated or corrupt file, or a header that claims more pixels
/// than the file holds, fails here, not as pink or a failed image in Blender); decoded once,
/// with the allocation capped by the side cap.
pub fn bytes_problem(bytes: &[u8], expect: Expect) -> Option<String> {
    if let Expect::Blend = expect {
        return blend_header_problem(bytes).map(|p| format!("is {p}"));
    }
    if bytes.len() as u64 > expect.max_bytes() {
        return Some(format!(
            "is {} bytes, more than the {} allowed",
            bytes.len(),
            expect.max_bytes()
        ));
    }
    image_problem(bytes, expect)
}

/// What a build without image decoders says of every image (the feature `textures`).
#[cfg(not(feature = "textures"))]
pub(crate) const NO_DECODERS: &str = "cannot be checked: this build of clevrtex-materials has no image decoders (its feature `textures`)";

#[cfg(not(feature = "textures"))]
fn image_problem(_bytes: &[u8], _expect: Expect) -> Option<String> {
    Some(NO_DECODERS.into())
}

/// The image part of [`bytes_problem`]: format, JPEG end, header side, full decode, channels.
#[cfg(feature = "textures")]
fn image_problem(bytes: &[u8], expect: Expect) -> Option<String> {
    use image::ImageFormat as F;
    let (formats, names, channels): (&[F], &str, u8) = match expect {
        Expect::Blend => return None,
        Expect::Texture => (&[F::Png, F::Jpeg, F::Tiff], "a PNG, JPEG or TIFF file", 1),
        Expect::PbrMap { channels } => (
            &[F::Png, F::Jpeg, F::OpenExr],
            "a PNG, JPEG or OpenEXR file",
            channels,
        ),
    };
    let reader = |bytes| {
        image::ImageReader::new(std::io::Cursor::new(bytes))
            .with_guessed_format()
            .expect("reading from memory")
    };
    let r = reader(bytes);
    let Some(format) = r.format().filter(|f| formats.contains(f)) else {
        return Some(format!(
            "is not {names} (the formats this material may read)"
        ));
    };
    // The JPEG decoder fills a truncated file's missing pixels in without an error, as
    // Blender does (grey, silently): a whole JPEG has its end-of-image marker after its
    // first scan (entropy-coded data never holds FF D9: an FF there is stuffed or a restart).
    if format == F::Jpeg {
        let scan = bytes.windows(2).position(|w| w == [0xff, 0xda]);
        let end = bytes.windows(2).rposition(|w| w == [0xff, 0xd9]);
        if !matches!((scan, end), (Some(s), Some(e)) if e > s) {
            return Some(
                "is truncated: a JPEG without its end-of-image marker after its pixel data; does not decode to the end"
                    .into(),
            );
        }
    }
    let (w, h) = match r.into_dimensions() {
        Ok(d) => d,
        Err(e) => {
            return Some(format!(
                "has an unreadable header: {}",
                e.to_string().trim_end()
            ))
        }
    };
    if let Some(problem) = side_problem(w, h) {
        return Some(problem);
    }
    let mut r = reader(bytes);
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_TEXTURE_SIDE);
    limits.max_image_height = Some(MAX_TEXTURE_SIDE);
    // 16 bytes a pixel: 32-bit float RGBA (OpenEXR), the widest pixel of the formats.
    limits.max_alloc = Some(u64::from(MAX_TEXTURE_SIDE).pow(2) * 16);
    r.limits(limits);
    let decoded = match r.decode() {
        Ok(d) => d,
        Err(e) => return Some(format!("does not decode: {}", e.to_string().trim_end())),
    };
    let have = decoded.color().channel_count();
    (have < channels)
        .then(|| format!("has {have} channel(s); this map needs {channels} or more (RGB)"))
}

/// Why `head`, the start of a file, is not a `.blend` file's, if it is not: neither Blender's
/// `BLENDER` nor gzip or zstd compression (which Blender uses for compressed files).
pub(crate) fn blend_header_problem(head: &[u8]) -> Option<String> {
    let ok = head.starts_with(b"BLENDER")
        || head.starts_with(&[0x1f, 0x8b])
        || head.starts_with(&[0x28, 0xb5, 0x2f, 0xfd]);
    (!ok).then(|| {
        "not a Blender file (no `BLENDER` header, not gzip or zstd compressed)".to_string()
    })
}

/// Check a `.blend` file's size (at most [`MAX_BLEND_BYTES`]) without reading it.
pub(crate) fn blend_size_problem(path: &Path) -> Option<String> {
    match std::fs::metadata(path) {
        Err(e) => Some(format!("cannot read the `.blend` file: {e}")),
        Ok(m) if !m.is_file() => Some(
            "the `.blend` file is not a regular file (a FIFO, socket or device); not read"
                .to_string(),
        ),
        Ok(m) if m.len() > MAX_BLEND_BYTES => Some(format!(
            "the `.blend` file is {} bytes, more than the {MAX_BLEND_BYTES} allowed",
            m.len()
        )),
        Ok(_) => None,
    }
}
