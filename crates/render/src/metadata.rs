//! The metadata file of a rendered sample: every key of the published dataset (from
//! [`clevrtex_scene::metadata()`]) plus ours (seed, attempt, camera matrices, visibility per
//! object, pass encodings, render settings, versions).

use std::collections::BTreeMap;

use clevrtex_scene::metadata::Visibility;
use clevrtex_scene::passes::Encoding;
use clevrtex_scene::scene_file::RenderSettings;
use clevrtex_scene::{ClevrMetadata, Pass, SceneFile};
use serde::Serialize;

use crate::post::{self, ObjectPixels};

/// Facts about the render that only exist after it ran.
#[derive(Debug, Clone)]
pub struct RenderFacts<'a> {
    /// Visible pixels and 2D box per object, from the final mask.
    pub objects: Vec<ObjectPixels>,
    /// Blender's version string (from the worker's `ready`).
    pub blender_version: String,
    /// The bridge's version-parity settings (the worker's `ready.compat`).
    pub blender_compat: BTreeMap<String, serde_json::Value>,
    /// Passes actually written (the scene's request).
    pub passes: Vec<Pass>,
    /// The run's user materials, name -> content hash; those the scene uses are recorded.
    pub user_materials: &'a BTreeMap<String, String>,
    /// The run's config hash (`generate`'s manifest `config_hash`); `None` for `render`.
    pub config_hash: Option<&'a str>,
}

/// The camera's metadata, from the scene crate (the sampler's side: `verify` re-derives it).
pub use clevrtex_scene::metadata::{extrinsics_opencv, intrinsics, CameraMetadata};

/// The metadata file of a rendered sample: every key of the published dataset (the
/// flattened [`ClevrMetadata`], with each object's visibility) plus ours.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SampleMetadata {
    /// The published keys.
    #[serde(flatten)]
    pub clevr: ClevrMetadata,
    /// Variant name.
    pub variant: String,
    /// File stem.
    pub stem: String,
    /// Run seed.
    pub seed: u64,
    /// The layout stream of the draws (the scene file's `layout_stream`: the variant's name
    /// unless `--layout-stream` chose another).
    pub layout_stream: String,
    /// The config hash of the `generate` run that made the sample (its manifest's
    /// `config_hash`), so `verify` can tell a sample made from another config; absent from
    /// `render` and in older datasets.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub config_hash: Option<String>,
    /// Accepted layout attempt.
    pub attempt: u32,
    /// The camera.
    pub camera: CameraMetadata,
    /// Objects at or under this many visible pixels were rejected.
    pub visibility_threshold_px: u64,
    /// How each written pass is encoded, by pass name (from the pass table).
    pub passes: BTreeMap<&'static str, Encoding>,
    /// The render settings.
    pub render: RenderSettings,
    /// Blender's version string.
    pub blender_version: String,
    /// The settings the bridge changed on this Blender to render as 3.4 does
    /// (`compat.parity_settings()`, e.g. `{"coat": true, ...}` on 4.x); absent on 3.x.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub blender_compat: BTreeMap<String, serde_json::Value>,
    /// This tool's version.
    pub clevrtex_version: &'static str,
    /// The user materials (`--materials DIR`) of the scene: name -> content hash of the
    /// `.blend` (or material file) and every image it reads; absent with built-ins only.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub user_materials: BTreeMap<String, String>,
}

impl SampleMetadata {
    /// The file's text: pretty JSON with every object's keys sorted (a canonical form, so
    /// equal metadata is equal bytes).
    pub fn to_json_pretty(&self) -> String {
        let value = serde_json::to_value(self).expect("metadata serialises");
        serde_json::to_string_pretty(&value).expect("metadata serialises")
    }
}

/// The full metadata of a rendered scene.
pub fn build(scene: &SceneFile, facts: &RenderFacts<'_>) -> SampleMetadata {
    let mut shown = scene.clone();
    shown.passes = facts.passes.clone();
    let mut clevr = clevrtex_scene::metadata(&shown);
    for (o, px) in clevr.objects.iter_mut().zip(&facts.objects) {
        o.visibility = Some(Visibility {
            visible_pixels: px.pixels,
            bbox: px.bbox,
        });
    }
    SampleMetadata {
        clevr,
        variant: scene.variant.clone(),
        stem: scene.stem.clone(),
        seed: scene.seed,
        layout_stream: scene.layout_stream.clone(),
        config_hash: facts.config_hash.map(str::to_string),
        attempt: scene.attempt,
        camera: CameraMetadata::of(scene),
        visibility_threshold_px: post::visibility_threshold(
            scene.render.width,
            scene.render.height,
        ),
        passes: facts
            .passes
            .iter()
            .map(|p| (p.name(), p.spec().encoding))
            .collect(),
        render: scene.render.clone(),
        blender_version: facts.blender_version.clone(),
        blender_compat: facts.blender_compat.clone(),
        clevrtex_version: env!("CARGO_PKG_VERSION"),
        user_materials: std::iter::once(&scene.backdrop.material)
            .chain(scene.objects.iter().map(|o| &o.material))
            .filter_map(|m| {
                let hash = facts.user_materials.get(&m.name)?;
                Some((m.name.clone(), hash.clone()))
            })
            .collect(),
    }
}
