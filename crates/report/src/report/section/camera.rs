//! "Camera, lights and rendering": camera and light jitter, time per image, rejected layouts,
//! and the depth range of the measured images.

use crate::report::html::{esc, Page};
use crate::report::summary::{dist, per_image};
use crate::report::Summary;

/// Write the section into `page`.
pub(in crate::report) fn write(
    page: &mut Page,
    sums: &[Summary],
    labels: &[String],
) -> anyhow::Result<()> {
    page.h2("Camera, lights and rendering");
    page.html += "<div class=\"figs\">";
    page.continuous(
        "Camera jitter",
        "Distance (m) of each image's camera from the dataset's mean camera position (metadata camera.matrix_world).",
        &sums
            .iter()
            .map(|s| {
                let locs: Vec<[f64; 3]> =
                    s.data.samples.iter().filter_map(|x| x.camera_location).collect();
                if locs.is_empty() {
                    return Vec::new();
                }
                let n = locs.len() as f64;
                let mean = [0, 1, 2].map(|k| locs.iter().map(|l| l[k]).sum::<f64>() / n);
                locs.iter().map(|l| dist(*l, mean)).collect()
            })
            .collect::<Vec<_>>(),
        None,
        false,
    )?;
    let lights_note: Vec<String> = sums
        .iter()
        .zip(labels)
        .map(|(s, l)| {
            format!(
                "{}: {} of {} images recomputed",
                esc(l),
                s.lights_matched.0,
                s.lights_matched.1
            )
        })
        .collect();
    page.continuous(
        "Light jitter",
        &format!(
            "Distance (m) of each area light from its rig position. Lights are not in the metadata: each scene is recomputed from its seed, index and attempt with the built-in variant config, and used only when its objects equal the metadata's ({}).",
            lights_note.join("; ")
        ),
        &sums.iter().map(|s| s.light_offsets.clone()).collect::<Vec<_>>(),
        None,
        false,
    )?;
    page.continuous(
        "Time per image (s)",
        "Seconds one worker spent on each image (visibility passes, rejected layouts, final render, writing), from the run manifests' sample_seconds.",
        &sums
            .iter()
            .map(|s| {
                let secs = s.data.sample_seconds();
                s.data
                    .samples
                    .iter()
                    .filter_map(|x| secs.get(&x.stem).copied())
                    .collect()
            })
            .collect::<Vec<_>>(),
        None,
        false,
    )?;
    page.continuous(
        "Rejected layouts per image",
        "Layouts rejected by the visibility rule before the one kept (the metadata's attempt).",
        &per_image(sums, &|x| x.attempt.map(f64::from)),
        None,
        false,
    )?;
    let depth = |pick: fn((f64, f64)) -> f64| -> Vec<Vec<f64>> {
        sums.iter()
            .map(|s| {
                s.measures
                    .iter()
                    .filter_map(|m| m.1.depth_range.map(pick))
                    .collect()
            })
            .collect()
    };
    page.continuous(
        "Nearest depth per image (m)",
        "Smallest planar depth of the depth pass (measured images only). ClevrTex's own depth is an 8-bit mist, not metres: not shown for it.",
        &depth(|r| r.0),
        None,
        false,
    )?;
    page.continuous(
        "Farthest depth per image (m)",
        "Largest planar depth of the depth pass, background excluded (measured images only).",
        &depth(|r| r.1),
        None,
        false,
    )?;
    page.html += "</div>";
    Ok(())
}
