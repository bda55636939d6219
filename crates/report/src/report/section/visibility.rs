//! "Visibility": visible pixels per object against the visibility rule, and the share of each
//! object occluded (from the silhouette geometry, `geometry.rs`).

use crate::report::html::Page;
use crate::report::summary::per_object;
use crate::report::Summary;

/// Write the section into `page`.
pub(in crate::report) fn write(page: &mut Page, sums: &[Summary]) -> anyhow::Result<()> {
    page.h2("Visibility");
    page.html += "<div class=\"figs\">";
    let threshold = sums
        .iter()
        .flat_map(|s| {
            s.data
                .samples
                .iter()
                .filter_map(|x| x.visibility_threshold_px)
        })
        .next();
    page.continuous(
        "Visible pixels per object",
        &format!(
            "Pixels of each object in the mask. Red line: the visibility rule (more than {} px at this resolution; 200 at 320x240), under which a layout is resampled.",
            threshold.map(|t| t.to_string()).unwrap_or_else(|| "200 * W * H / (320 * 240)".into())
        ),
        &per_object(sums, &|o| o.visible_pixels.map(|p| p as f64)),
        threshold.map(|t| t as f64),
        true,
    )?;
    page.continuous(
        "Share of each object occluded",
        "1 - visible pixels / the pixels of the object's unoccluded silhouette (the convex hull of its projected outline, clipped to the image, from the metadata's camera). Cubes, cylinders and spheres only (their outline is that hull); other shapes are left out.",
        &per_object(sums, &|o| o.occluded),
        None,
        false,
    )?;
    page.html += "</div>";
    Ok(())
}
