//! Reading Blender's multilayer EXR files into named float channels.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use clevrtex_dataset::exr::MAX_CHANNELS;

use crate::error::{RenderError, Result};

/// Every channel of an EXR file, as `f32`, row-major from the top-left pixel.
#[derive(Debug, Clone)]
pub struct Channels {
    path: PathBuf,
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Samples by full channel name, e.g. `ViewLayer.IndexOB.X`.
    pub channels: BTreeMap<String, Vec<f32>>,
}

impl Channels {
    /// Read every channel of `path`.
    ///
    /// The file is not trusted (Blender's output): its header is read first, and a layer
    /// larger than [`clevrtex_scene::scene_file::MAX_IMAGE_SIDE`] on a side, more than 256
    /// channels or deep data are refused before anything is allocated for the pixels (a few
    /// hundred bytes of header can declare 100000x100000).
    pub fn read(path: &Path) -> Result<Channels> {
        Self::read_checked(path, None)
    }

    /// [`Channels::read`], refusing before decoding a file whose layers are not `size`
    /// (width, height) pixels: what a caller does that knows the size it asked Blender for.
    pub fn read_sized(path: &Path, size: (usize, usize)) -> Result<Channels> {
        Self::read_checked(path, Some(size))
    }

    fn read_checked(path: &Path, expected: Option<(usize, usize)>) -> Result<Channels> {
        use exr::prelude::*;
        let bad = |problem: String| RenderError::BadOutput {
            path: path.to_path_buf(),
            problem,
        };
        let meta = exr::meta::MetaData::read_from_file(path, false)
            .map_err(|e| bad(format!("cannot read EXR: {e}")))?;
        let max = clevrtex_scene::scene_file::MAX_IMAGE_SIDE as usize;
        let mut declared = 0;
        for header in &meta.headers {
            let (w, h) = (header.layer_size.width(), header.layer_size.height());
            if w > max || h > max {
                return Err(bad(format!(
                    "declares {w}x{h} pixels, more than the {max}x{max} any clevrtex image has"
                )));
            }
            if let Some((ew, eh)) = expected.filter(|&e| e != (w, h)) {
                return Err(bad(format!(
                    "declares {w}x{h} pixels but {ew}x{eh} were asked for"
                )));
            }
            if header.deep {
                return Err(bad("holds deep data, which Blender never writes".into()));
            }
            declared += header.channels.list.len();
        }
        if declared > MAX_CHANNELS {
            return Err(bad(format!(
                "declares {declared} channels, more than the {MAX_CHANNELS} read"
            )));
        }
        let image = read()
            .no_deep_data()
            .largest_resolution_level()
            .all_channels()
            .all_layers()
            .all_attributes()
            .from_file(path)
            .map_err(|e| bad(format!("cannot read EXR: {e}")))?;
        let mut size = None;
        let mut channels = BTreeMap::new();
        for layer in &image.layer_data {
            let layer_size = (layer.size.width(), layer.size.height());
            if *size.get_or_insert(layer_size) != layer_size {
                return Err(bad("layers have different sizes".into()));
            }
            let prefix = layer
                .attributes
                .layer_name
                .as_ref()
                .map(|n| format!("{n}."))
                .unwrap_or_default();
            for ch in &layer.channel_data.list {
                let full = ch.name.to_string();
                // Blender 5.0 writes one part per pass, named like its channels' prefix.
                let name = if !prefix.is_empty() && full.starts_with(&prefix) {
                    full
                } else {
                    format!("{prefix}{full}")
                };
                channels.insert(
                    short_pass_name(&name),
                    ch.sample_data.values_as_f32().collect(),
                );
            }
        }
        let (width, height) = size.ok_or_else(|| bad("no layers".into()))?;
        Ok(Channels {
            path: path.to_path_buf(),
            width,
            height,
            channels,
        })
    }

    /// One channel by its full name, or a [`RenderError::BadOutput`] naming what exists.
    pub fn get(&self, name: &str) -> Result<&[f32]> {
        self.channels
            .get(name)
            .map(Vec::as_slice)
            .ok_or_else(|| RenderError::BadOutput {
                path: self.path.clone(),
                problem: format!(
                    "no channel `{name}` (found: {})",
                    self.channels.keys().cloned().collect::<Vec<_>>().join(", ")
                ),
            })
    }

    /// The file these channels came from.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// Blender 5.0 names passes in EXR files by their long names (`ViewLayer.Object Index.X`);
/// 3.x and 4.x by the short ones the pass tables use (`ViewLayer.IndexOB.X`). Measured on
/// bpy 5.0's files; every other name is kept as it is.
const LONG_PASS_NAMES: &[(&str, &str)] = &[
    ("Object Index", "IndexOB"),
    ("Material Index", "IndexMA"),
    ("Diffuse Color", "DiffCol"),
    ("Diffuse Direct", "DiffDir"),
    ("Diffuse Indirect", "DiffInd"),
    ("Glossy Color", "GlossCol"),
    ("Glossy Direct", "GlossDir"),
    ("Glossy Indirect", "GlossInd"),
    ("Z", "Depth"),
];

/// `ViewLayer.<pass>.<channel>` with a long pass name made short (see [`LONG_PASS_NAMES`]).
pub fn short_pass_name(name: &str) -> String {
    let Some((layer_pass, channel)) = name.rsplit_once('.') else {
        return name.to_string();
    };
    let (layer, pass) = layer_pass.split_once('.').unwrap_or(("", layer_pass));
    match LONG_PASS_NAMES.iter().find(|(long, _)| *long == pass) {
        Some((_, short)) if layer.is_empty() => format!("{short}.{channel}"),
        Some((_, short)) => format!("{layer}.{short}.{channel}"),
        None => name.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::{short_pass_name, Channels};

    /// A scan-line EXR header declaring one float channel `Y` of `w`x`h` pixels, uncompressed,
    /// with its whole offset table (every line pointing past the end): a few bytes a line.
    fn declared_exr(w: i32, h: i32) -> Vec<u8> {
        fn attr(out: &mut Vec<u8>, name: &str, kind: &str, value: &[u8]) {
            for s in [name, kind] {
                out.extend_from_slice(s.as_bytes());
                out.push(0);
            }
            out.extend_from_slice(&(value.len() as i32).to_le_bytes());
            out.extend_from_slice(value);
        }
        let mut out = vec![0x76, 0x2f, 0x31, 0x01, 2, 0, 0, 0];
        let mut chlist = b"Y\0".to_vec();
        for v in [2i32, 0, 1, 1] {
            chlist.extend_from_slice(&v.to_le_bytes());
        }
        chlist.push(0);
        attr(&mut out, "channels", "chlist", &chlist);
        attr(&mut out, "compression", "compression", &[0]);
        let window: Vec<u8> = [0, 0, w - 1, h - 1]
            .iter()
            .flat_map(|v: &i32| v.to_le_bytes())
            .collect();
        attr(&mut out, "dataWindow", "box2i", &window);
        attr(&mut out, "displayWindow", "box2i", &window);
        attr(&mut out, "lineOrder", "lineOrder", &[0]);
        attr(&mut out, "pixelAspectRatio", "float", &1f32.to_le_bytes());
        attr(&mut out, "screenWindowCenter", "v2f", &[0; 8]);
        attr(&mut out, "screenWindowWidth", "float", &1f32.to_le_bytes());
        out.push(0);
        let end = (out.len() + 8 * h as usize) as u64;
        for _ in 0..h {
            out.extend_from_slice(&end.to_le_bytes());
        }
        out
    }

    /// Blender's output is not trusted: an EXR whose header declares 100000x100000 pixels
    /// (800 KB of file) is refused from its header. Before the check, decoding allocated the
    /// 40 GB its header asked for, and the allocation aborted the process.
    #[test]
    fn a_huge_declared_size_is_refused_before_decoding() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("passes.exr");
        std::fs::write(&path, declared_exr(100_000, 100_000)).unwrap();
        let msg = Channels::read(&path).unwrap_err().to_string();
        assert!(msg.contains("declares 100000x100000 pixels"), "{msg}");
        let small = dir.path().join("small.exr");
        std::fs::write(&small, declared_exr(64, 48)).unwrap();
        let msg = Channels::read_sized(&small, (32, 24))
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("declares 64x48 pixels but 32x24 were asked for"),
            "{msg}"
        );
    }

    #[test]
    fn long_pass_names_of_blender_5_are_made_short() {
        assert_eq!(
            short_pass_name("ViewLayer.Object Index.X"),
            "ViewLayer.IndexOB.X"
        );
        assert_eq!(
            short_pass_name("ViewLayer.Diffuse Color.R"),
            "ViewLayer.DiffCol.R"
        );
        assert_eq!(
            short_pass_name("ViewLayer.IndexOB.X"),
            "ViewLayer.IndexOB.X"
        );
        assert_eq!(
            short_pass_name("ViewLayer.Combined.R"),
            "ViewLayer.Combined.R"
        );
        assert_eq!(short_pass_name("R"), "R");
    }
}
