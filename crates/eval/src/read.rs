//! Readers for PNG, `.npy` and `.npz` inputs. They take bytes, return a reason string on bad
//! input and never panic (they are fuzzed in `tests/fuzz.rs`).

use std::collections::BTreeMap;
use std::io::{Cursor, Read};

/// Largest decoded buffer a reader will allocate (1 GiB), so hostile headers cannot exhaust
/// memory.
pub const MAX_BYTES: usize = 1 << 30;

/// A decoded 2-D array of segment ids.
#[derive(Clone, Debug, PartialEq)]
pub struct LabelImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Row-major ids.
    pub labels: Vec<u32>,
}

/// A decoded 8-bit RGB image.
#[derive(Clone, Debug, PartialEq)]
pub struct RgbImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Interleaved RGB.
    pub rgb: Vec<u8>,
}

/// The decoder's message without the `Debug` dump of a chunk type it may hold
/// (`ChunkType { type: garb, critical: false, ... }` becomes `` `garb` ``).
fn png_reason(e: &png::DecodingError) -> String {
    let text = e.to_string();
    let mut out = String::with_capacity(text.len());
    let mut rest = text.as_str();
    while let Some(at) = rest.find("ChunkType { type: ") {
        out.push_str(&rest[..at]);
        let after = &rest[at + "ChunkType { type: ".len()..];
        let Some(end) = after.find('}') else {
            rest = &rest[at..];
            break;
        };
        let name = after[..end].split(',').next().unwrap_or_default().trim();
        out.push_str(&format!("chunk `{name}`"));
        rest = after[end + 1..]
            .strip_prefix(" chunk")
            .unwrap_or(&after[end + 1..]);
    }
    out.push_str(rest);
    out
}

fn png_reader(bytes: &[u8]) -> Result<png::Reader<Cursor<&[u8]>>, String> {
    let mut dec =
        png::Decoder::new_with_limits(Cursor::new(bytes), png::Limits { bytes: MAX_BYTES });
    dec.set_transformations(png::Transformations::IDENTITY);
    dec.read_info()
        .map_err(|e| format!("not a valid PNG ({})", png_reason(&e)))
}

fn png_frame(
    reader: &mut png::Reader<Cursor<&[u8]>>,
) -> Result<(Vec<u8>, png::OutputInfo), String> {
    let size = reader
        .output_buffer_size()
        .filter(|&s| s <= MAX_BYTES)
        .ok_or("image too large")?;
    let mut buf = vec![0u8; size];
    let info = reader
        .next_frame(&mut buf)
        .map_err(|e| format!("not a valid PNG ({})", png_reason(&e)))?;
    buf.truncate(info.buffer_size());
    Ok((buf, info))
}

/// Width and height a PNG declares in its header, read without decoding anything: check
/// them against what is expected before [`png_labels`] or [`png_rgb`] allocate for them.
pub fn png_size(bytes: &[u8]) -> Result<(usize, usize), String> {
    let reader = png_reader(bytes)?;
    let info = reader.info();
    Ok((info.width as usize, info.height as usize))
}

/// [`png_size`], refused when a side is over the 4096 pixels any clevrtex image has: for a
/// dataset's own PNGs (ground truth), whose size nothing else bounds before decoding.
pub fn png_size_of_dataset_image(bytes: &[u8]) -> Result<(usize, usize), String> {
    let (w, h) = png_size(bytes)?;
    let max = clevrtex_scene::scene_file::MAX_IMAGE_SIDE as usize;
    if w > max || h > max {
        return Err(format!(
            "declares {w}x{h} pixels, more than the {max}x{max} of any ClevrTex image"
        ));
    }
    Ok((w, h))
}

/// Read a PNG of segment ids: 1-16 bit greyscale, or palette (the raw index, never the
/// palette colour).
pub fn png_labels(bytes: &[u8]) -> Result<LabelImage, String> {
    use png::{BitDepth, ColorType};
    let mut reader = png_reader(bytes)?;
    let (buf, info) = png_frame(&mut reader)?;
    let (w, h) = (info.width as usize, info.height as usize);
    match info.color_type {
        ColorType::Grayscale | ColorType::Indexed => {}
        other => {
            return Err(format!(
                "a segment-id PNG must be greyscale or palette, this one is {other:?}"
            ))
        }
    }
    let mut labels = Vec::with_capacity(w * h);
    let line = info.line_size;
    for y in 0..h {
        let row = buf
            .get(y * line..(y + 1) * line)
            .ok_or("truncated image data")?;
        match info.bit_depth {
            BitDepth::Eight => labels.extend(row[..w].iter().map(|&v| v as u32)),
            BitDepth::Sixteen => labels.extend(
                row.chunks_exact(2)
                    .take(w)
                    .map(|c| u16::from_be_bytes([c[0], c[1]]) as u32),
            ),
            depth => {
                let bits = depth as usize;
                let mask = (1u32 << bits) - 1;
                for x in 0..w {
                    let bit = x * bits;
                    let byte = row[bit / 8] as u32;
                    labels.push((byte >> (8 - bits - bit % 8)) & mask);
                }
            }
        }
    }
    if labels.len() != w * h {
        return Err("truncated image data".into());
    }
    Ok(LabelImage {
        width: w,
        height: h,
        labels,
    })
}

/// A decoded greyscale or RGB PNG of 8 or 16 bits, its samples as they are (an optional
/// pass of a dataset: depth, normal, albedo, shadow).
#[derive(Clone, Debug, PartialEq)]
pub struct SampleImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// 1 (grey) or 3 (RGB).
    pub channels: usize,
    /// 8 or 16.
    pub bits: u8,
    /// Row-major, interleaved samples (8-bit ones widened, not scaled).
    pub samples: Vec<u16>,
}

/// Read an 8- or 16-bit greyscale or RGB PNG without converting its samples (a palette,
/// alpha or fewer bits is refused: no pass of the layout is written so).
pub fn png_samples(bytes: &[u8]) -> Result<SampleImage, String> {
    use png::{BitDepth, ColorType};
    let mut reader = png_reader(bytes)?;
    let (buf, info) = png_frame(&mut reader)?;
    let (w, h) = (info.width as usize, info.height as usize);
    let channels = match info.color_type {
        ColorType::Grayscale => 1,
        ColorType::Rgb => 3,
        other => return Err(format!("is a {other:?} PNG, not greyscale or RGB")),
    };
    let bits = match info.bit_depth {
        BitDepth::Eight => 8,
        BitDepth::Sixteen => 16,
        other => return Err(format!("has {} bits per sample, not 8 or 16", other as u8)),
    };
    let n = w
        .checked_mul(h)
        .and_then(|n| n.checked_mul(channels))
        .ok_or("image too large")?;
    let line = info.line_size;
    let mut samples = Vec::with_capacity(n);
    for y in 0..h {
        let row = buf
            .get(y * line..(y + 1) * line)
            .ok_or("truncated image data")?;
        if bits == 8 {
            samples.extend(row[..w * channels].iter().map(|&v| u16::from(v)));
        } else {
            samples.extend(
                row.chunks_exact(2)
                    .take(w * channels)
                    .map(|c| u16::from_be_bytes([c[0], c[1]])),
            );
        }
    }
    if samples.len() != n {
        return Err("truncated image data".into());
    }
    Ok(SampleImage {
        width: w,
        height: h,
        channels,
        bits,
        samples,
    })
}

/// Read a PNG as 8-bit RGB: palette and greyscale are expanded, alpha is dropped and 16-bit
/// samples keep their high byte.
pub fn png_rgb(bytes: &[u8]) -> Result<RgbImage, String> {
    use png::ColorType;
    let mut dec =
        png::Decoder::new_with_limits(Cursor::new(bytes), png::Limits { bytes: MAX_BYTES });
    dec.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut reader = dec
        .read_info()
        .map_err(|e| format!("not a valid PNG ({})", png_reason(&e)))?;
    let (buf, info) = png_frame(&mut reader)?;
    let (w, h) = (info.width as usize, info.height as usize);
    let channels = match info.color_type {
        ColorType::Grayscale => 1,
        ColorType::GrayscaleAlpha => 2,
        ColorType::Rgb => 3,
        ColorType::Rgba => 4,
        ColorType::Indexed => return Err("palette PNG could not be expanded".into()),
    };
    let n = w.checked_mul(h).ok_or("image too large")?;
    if buf.len() < n * channels {
        return Err("truncated image data".into());
    }
    let mut rgb = Vec::with_capacity(n * 3);
    match channels {
        3 => rgb.extend_from_slice(&buf[..n * 3]),
        4 => buf[..n * 4]
            .chunks_exact(4)
            .for_each(|p| rgb.extend_from_slice(&p[..3])),
        c => buf[..n * c]
            .chunks_exact(c)
            .for_each(|p| rgb.extend_from_slice(&[p[0], p[0], p[0]])),
    }
    Ok(RgbImage {
        width: w,
        height: h,
        rgb,
    })
}

/// Element data of a `.npy` array.
#[derive(Clone, Debug, PartialEq)]
pub enum NpyData {
    /// Any integer or boolean dtype.
    Int(Vec<i64>),
    /// `float32` (and `float16`, widened).
    F32(Vec<f32>),
    /// `float64`.
    F64(Vec<f64>),
}

/// A `.npy` array in C order.
#[derive(Clone, Debug, PartialEq)]
pub struct NpyArray {
    /// Dimensions.
    pub shape: Vec<usize>,
    /// Elements in C (row-major) order.
    pub data: NpyData,
    /// The dtype as written in the header, e.g. `<f4`.
    pub descr: String,
}

impl NpyArray {
    /// Whether the dtype is a floating-point one.
    pub fn is_float(&self) -> bool {
        !matches!(self.data, NpyData::Int(_))
    }
}

/// A Python literal in a `.npy` header.
#[derive(Debug, PartialEq)]
enum Lit {
    Str(String),
    Int(u64),
    Bool(bool),
    Tuple(Vec<Lit>),
    Dict(Vec<(Lit, Lit)>),
}

struct LitParser<'a> {
    s: &'a [u8],
    pos: usize,
    depth: usize,
}

impl LitParser<'_> {
    fn ws(&mut self) {
        while self.pos < self.s.len() && self.s[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
    }

    fn peek(&mut self) -> Option<u8> {
        self.ws();
        self.s.get(self.pos).copied()
    }

    fn expect(&mut self, c: u8) -> Result<(), String> {
        if self.peek() == Some(c) {
            self.pos += 1;
            Ok(())
        } else {
            Err(format!("bad header: expected `{}`", c as char))
        }
    }

    fn value(&mut self) -> Result<Lit, String> {
        self.depth += 1;
        if self.depth > 16 {
            return Err("bad header: nested too deeply".into());
        }
        let v = match self.peek().ok_or("bad header: unexpected end")? {
            b'{' => {
                self.pos += 1;
                let mut items = Vec::new();
                while self.peek() != Some(b'}') {
                    let k = self.value()?;
                    self.expect(b':')?;
                    let v = self.value()?;
                    items.push((k, v));
                    if self.peek() == Some(b',') {
                        self.pos += 1;
                    } else {
                        break;
                    }
                }
                self.expect(b'}')?;
                Lit::Dict(items)
            }
            open @ (b'(' | b'[') => {
                let close = if open == b'(' { b')' } else { b']' };
                self.pos += 1;
                let mut items = Vec::new();
                while self.peek() != Some(close) {
                    items.push(self.value()?);
                    if self.peek() == Some(b',') {
                        self.pos += 1;
                    } else {
                        break;
                    }
                }
                self.expect(close)?;
                Lit::Tuple(items)
            }
            q @ (b'\'' | b'"') => {
                self.pos += 1;
                let start = self.pos;
                while self.pos < self.s.len() && self.s[self.pos] != q {
                    self.pos += 1;
                }
                if self.pos >= self.s.len() {
                    return Err("bad header: unterminated string".into());
                }
                let text = String::from_utf8_lossy(&self.s[start..self.pos]).into_owned();
                self.pos += 1;
                Lit::Str(text)
            }
            c if c.is_ascii_digit() => {
                let start = self.pos;
                while self.pos < self.s.len() && self.s[self.pos].is_ascii_digit() {
                    self.pos += 1;
                }
                // Python 2 era files may write `3L`.
                if self.s.get(self.pos) == Some(&b'L') {
                    self.pos += 1;
                }
                let digits = std::str::from_utf8(&self.s[start..self.pos])
                    .unwrap_or("")
                    .trim_end_matches('L');
                Lit::Int(
                    digits
                        .parse()
                        .map_err(|_| "bad header: dimension too large")?,
                )
            }
            _ if self.s[self.pos..].starts_with(b"True") => {
                self.pos += 4;
                Lit::Bool(true)
            }
            _ if self.s[self.pos..].starts_with(b"False") => {
                self.pos += 5;
                Lit::Bool(false)
            }
            c => return Err(format!("bad header: unexpected `{}`", c.escape_ascii())),
        };
        self.depth -= 1;
        Ok(v)
    }
}

/// What a `.npy` header declares.
struct NpyHeader {
    descr: String,
    fortran: bool,
    shape: Vec<usize>,
    big: bool,
    kind: u8,
    size: usize,
    count: usize,
    /// Offset of the data after the header.
    data_start: usize,
}

impl NpyHeader {
    /// Bytes of the data the header declares.
    fn nbytes(&self) -> usize {
        self.count * self.size
    }
}

/// Parse the header of a `.npy` file: everything up to its data (the data need not be there).
fn npy_header(bytes: &[u8]) -> Result<NpyHeader, String> {
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err("not a `.npy` file (bad magic)".into());
    }
    let (hlen, start): (usize, usize) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 => {
            if bytes.len() < 12 {
                return Err("truncated header".into());
            }
            (
                u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
                12,
            )
        }
        v => return Err(format!("unsupported `.npy` format version {v}")),
    };
    let header = bytes
        .get(start..start.saturating_add(hlen))
        .ok_or("truncated header (or a header larger than 64 KiB)")?;
    let mut p = LitParser {
        s: header,
        pos: 0,
        depth: 0,
    };
    let Lit::Dict(items) = p.value()? else {
        return Err("bad header: not a dict".into());
    };
    let (mut descr, mut fortran, mut shape) = (None, false, None);
    for (k, v) in items {
        match (k, v) {
            (Lit::Str(k), Lit::Str(d)) if k == "descr" => descr = Some(d),
            (Lit::Str(k), Lit::Bool(b)) if k == "fortran_order" => fortran = b,
            (Lit::Str(k), Lit::Tuple(dims)) if k == "shape" => {
                let mut s = Vec::new();
                for d in dims {
                    match d {
                        Lit::Int(d) => {
                            s.push(usize::try_from(d).map_err(|_| "dimension too large")?)
                        }
                        _ => return Err("bad header: shape must hold integers".into()),
                    }
                }
                shape = Some(s);
            }
            (Lit::Str(k), _) if k == "descr" => {
                return Err("structured dtypes are not supported".into())
            }
            _ => {}
        }
    }
    let descr = descr.ok_or("bad header: no `descr`")?;
    let shape = shape.ok_or("bad header: no `shape`")?;
    let count = shape
        .iter()
        .try_fold(1usize, |a, &d| a.checked_mul(d))
        .ok_or("array too large")?;
    let d = descr.as_bytes();
    if d.len() < 3 {
        return Err(format!("unsupported dtype `{descr}`"));
    }
    let big = d[0] == b'>';
    let kind = d[1];
    let size: usize = std::str::from_utf8(&d[2..])
        .unwrap_or("")
        .parse()
        .map_err(|_| format!("unsupported dtype `{descr}`"))?;
    if !matches!(d[0], b'<' | b'>' | b'|' | b'=') {
        return Err(format!("unsupported dtype `{descr}`"));
    }
    let nbytes = count.checked_mul(size).ok_or("array too large")?;
    if nbytes > MAX_BYTES || count > MAX_BYTES / 4 {
        return Err("array too large".into());
    }
    Ok(NpyHeader {
        descr,
        fortran,
        shape,
        big,
        kind,
        size,
        count,
        data_start: start + hlen,
    })
}

/// Parse a `.npy` file (format versions 1-3; bool, integer and float dtypes of either byte
/// order; C or Fortran order).
pub fn npy(bytes: &[u8]) -> Result<NpyArray, String> {
    let header = npy_header(bytes)?;
    let nbytes = header.nbytes();
    let (big, size) = (header.big, header.size);
    let (descr, shape) = (header.descr, header.shape);
    let body = &bytes[header.data_start..];
    if body.len() < nbytes {
        return Err(format!(
            "truncated data: {} bytes for shape {shape:?} of `{descr}` ({nbytes} needed)",
            body.len()
        ));
    }
    let body = &body[..nbytes];
    fn word<const N: usize>(c: &[u8], big: bool) -> [u8; N] {
        let mut a = [0u8; N];
        a.copy_from_slice(c);
        if big {
            a.reverse();
        }
        a
    }
    /// Each element read by `read` and widened to `i64` (every type this takes fits).
    fn ints<'a, T: Into<i64>>(
        chunks: std::slice::ChunksExact<'a, u8>,
        read: impl Fn(&'a [u8]) -> T,
    ) -> Vec<i64> {
        chunks.map(|c| read(c).into()).collect()
    }
    let chunks = body.chunks_exact(size.max(1));
    let data = match (header.kind, size) {
        (b'b', 1) => NpyData::Int(body.iter().map(|&b| (b != 0) as i64).collect()),
        (b'u', 1) => NpyData::Int(body.iter().map(|&b| b as i64).collect()),
        (b'i', 1) => NpyData::Int(body.iter().map(|&b| b as i8 as i64).collect()),
        (b'u', 2) => NpyData::Int(ints(chunks, |c| u16::from_le_bytes(word(c, big)))),
        (b'i', 2) => NpyData::Int(ints(chunks, |c| i16::from_le_bytes(word(c, big)))),
        (b'u', 4) => NpyData::Int(ints(chunks, |c| u32::from_le_bytes(word(c, big)))),
        (b'i', 4) => NpyData::Int(ints(chunks, |c| i32::from_le_bytes(word(c, big)))),
        (b'u', 8) => NpyData::Int(
            chunks
                .map(|c| {
                    let v = u64::from_le_bytes(word(c, big));
                    i64::try_from(v).map_err(|_| format!("value {v} of `{descr}` is too large"))
                })
                .collect::<Result<_, _>>()?,
        ),
        (b'i', 8) => NpyData::Int(chunks.map(|c| i64::from_le_bytes(word(c, big))).collect()),
        (b'f', 2) => NpyData::F32(
            chunks
                .map(|c| f16_to_f32(u16::from_le_bytes(word(c, big))))
                .collect(),
        ),
        (b'f', 4) => NpyData::F32(chunks.map(|c| f32::from_le_bytes(word(c, big))).collect()),
        (b'f', 8) => NpyData::F64(chunks.map(|c| f64::from_le_bytes(word(c, big))).collect()),
        _ => {
            return Err(format!(
                "unsupported dtype `{descr}` (use an integer, bool or float dtype)"
            ))
        }
    };
    let data = if header.fortran && shape.len() > 1 {
        match data {
            NpyData::Int(v) => NpyData::Int(fortran_to_c(&v, &shape)),
            NpyData::F32(v) => NpyData::F32(fortran_to_c(&v, &shape)),
            NpyData::F64(v) => NpyData::F64(fortran_to_c(&v, &shape)),
        }
    } else {
        data
    };
    Ok(NpyArray { shape, data, descr })
}

fn fortran_to_c<T: Copy>(v: &[T], shape: &[usize]) -> Vec<T> {
    let n = v.len();
    let mut out = Vec::with_capacity(n);
    let mut idx = vec![0usize; shape.len()];
    // Fortran strides: the first axis varies fastest.
    let mut strides = vec![1usize; shape.len()];
    for a in 1..shape.len() {
        strides[a] = strides[a - 1] * shape[a - 1];
    }
    for _ in 0..n {
        let off: usize = idx.iter().zip(&strides).map(|(i, s)| i * s).sum();
        out.push(v[off]);
        for a in (0..shape.len()).rev() {
            idx[a] += 1;
            if idx[a] < shape[a] {
                break;
            }
            idx[a] = 0;
        }
    }
    out
}

fn f16_to_f32(h: u16) -> f32 {
    let sign = ((h >> 15) as u32) << 31;
    let exp = ((h >> 10) & 0x1f) as u32;
    let frac = (h & 0x3ff) as u32;
    let bits = match exp {
        0 if frac == 0 => sign,
        0 => {
            // Subnormal: value = frac * 2^-24.
            let v = frac as f32 * (1.0 / 16_777_216.0);
            return if sign != 0 { -v } else { v };
        }
        0x1f => sign | 0x7f80_0000 | (frac << 13),
        e => sign | ((e + 112) << 23) | (frac << 13),
    };
    f32::from_bits(bits)
}

/// Most bytes of a `.npy` header read before its shape is known.
const NPY_HEADER_MAX: u64 = 64 * 1024;

/// Read the named members (`<name>.npy`) of a `.npz` archive; absent names are left out.
/// `max_elements(name)` bounds each member's element count: the header is inflated and
/// checked first, so a member declaring more (a "zip bomb", or a prediction far larger than
/// the ground truth) is rejected before its data is inflated; at most the declared data is
/// ever read.
pub fn npz(
    bytes: &[u8],
    names: &[&str],
    max_elements: &dyn Fn(&str) -> usize,
) -> Result<BTreeMap<String, NpyArray>, String> {
    let mut zip = zip::ZipArchive::new(Cursor::new(bytes))
        .map_err(|e| format!("not a valid `.npz` (zip) archive ({e})"))?;
    let mut out = BTreeMap::new();
    for &name in names {
        let member = format!("{name}.npy");
        let mut file = match zip.by_name(&member) {
            Ok(f) => f,
            Err(zip::result::ZipError::FileNotFound) => continue,
            Err(e) => return Err(format!("cannot open member `{member}` ({e})")),
        };
        let read_err = |e: std::io::Error| format!("cannot read member `{member}` ({e})");
        let mut buf = Vec::new();
        (&mut file)
            .take(NPY_HEADER_MAX)
            .read_to_end(&mut buf)
            .map_err(read_err)?;
        let header = npy_header(&buf).map_err(|e| format!("member `{member}`: {e}"))?;
        let limit = max_elements(name);
        if header.count > limit {
            return Err(format!(
                "member `{member}` declares shape {:?} ({} values), more than the {limit} a prediction for this image can have",
                header.shape, header.count
            ));
        }
        let total = (header.data_start + header.nbytes()) as u64;
        if (buf.len() as u64) < total {
            (&mut file)
                .take(total - buf.len() as u64)
                .read_to_end(&mut buf)
                .map_err(read_err)?;
        }
        let arr = npy(&buf).map_err(|e| format!("member `{member}`: {e}"))?;
        out.insert(name.to_string(), arr);
    }
    Ok(out)
}

/// The names of the members of a `.npz` archive (without `.npy`), for error messages.
pub fn npz_names(bytes: &[u8]) -> Vec<String> {
    zip::ZipArchive::new(Cursor::new(bytes))
        .map(|z| {
            z.file_names()
                .map(|n| n.trim_end_matches(".npy").to_string())
                .collect()
        })
        .unwrap_or_default()
}

#[cfg(test)]
mod reason_tests {
    use super::*;

    #[test]
    fn a_bad_chunk_is_named_without_a_debug_dump() {
        let err = png_labels(b"\x89PNG\r\n\x1a\nXXXXgarbage").unwrap_err();
        assert!(err.starts_with("not a valid PNG ("), "{err}");
        assert!(
            !err.contains("ChunkType") && !err.contains("critical"),
            "{err}"
        );
        assert!(err.contains("chunk `"), "{err}");
    }
}
