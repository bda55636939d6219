//! Reading Blender's multilayer EXR files into named float channels.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

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
    pub fn read(path: &Path) -> Result<Channels> {
        use exr::prelude::*;
        let bad = |problem: String| RenderError::BadOutput {
            path: path.to_path_buf(),
            problem,
        };
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
    use super::short_pass_name;

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
