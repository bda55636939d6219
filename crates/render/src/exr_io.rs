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
                let name = format!("{prefix}{}", ch.name);
                channels.insert(name, ch.sample_data.values_as_f32().collect());
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
