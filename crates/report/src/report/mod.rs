//! `clevrtex report DIR --out report.html [--compare OTHER]`: one self-contained HTML page
//! (plots as SVG and the preview sheet as PNG, both as data URIs; inline CSS; no script, no
//! network) with a dataset's statistics, or two datasets side by side with a two-sample test
//! per statistic. Works on our output and on the published ClevrTex layout; what a dataset
//! does not record is shown as "not in this dataset". See `docs/report.md`.
//!
//! Where things are: reading a dataset's metadata, manifests and ledger in [`data`]; the
//! pixel measurements in [`texture`] (object contrast, depth range) and `geometry.rs`
//! (occlusion); one dataset read and measured in `summary.rs`; the statistical tests in
//! [`stats`]; the plots in [`plot`]; the HTML (escaping, figures with their tables and tests)
//! in `html.rs`; and one module per section of the page, in its order, in `section/`
//! (`overview`, `splits`, `failures`, `scenes`, `visibility`, `camera`, `contrast`,
//! `preview`, `provenance`), each with its captions.

use std::path::Path;

use anyhow::Context;

pub mod data;
mod geometry;
mod html;
pub mod plot;
mod section;
pub mod stats;
mod summary;
pub mod texture;

pub use summary::{summarise, Summary};

/// What the report reads and draws (the options of `clevrtex report`).
#[derive(Debug, Clone)]
pub struct Options {
    /// Images per variant whose pixels are read (object contrast, depth range), evenly spread
    /// over the variant's indices; the metadata of every image is read regardless.
    pub max_texture_samples: usize,
    /// Samples in the preview sheet.
    pub preview: u32,
}

/// A report made: the page, and what `clevrtex report` says about it.
pub struct Report {
    /// The page (HTML).
    pub html: String,
    /// Images whose metadata was read, over the datasets.
    pub images: usize,
    /// Images whose pixels were measured.
    pub measured: usize,
    /// What was left out, one line each: samples of the datasets, then cells of the preview.
    pub problems: Vec<String>,
}

/// Read and measure the dataset `dir` (and `compare`, beside it) and build the page.
pub fn make(dir: &Path, compare: Option<&Path>, options: &Options) -> anyhow::Result<Report> {
    let mut sums = vec![summarise(dir, options)?];
    if let Some(other) = compare {
        sums.push(summarise(other, options)?);
    }
    let (html, drawing_problems) = build(&sums, options)?;
    Ok(Report {
        html,
        images: sums.iter().map(|s| s.data.samples.len()).sum(),
        measured: sums.iter().map(|s| s.measures.len()).sum(),
        problems: sums
            .iter()
            .flat_map(|s| s.problems.iter().cloned())
            .chain(drawing_problems)
            .collect(),
    })
}

/// Write the page to `out` with the one atomic writer ([`clevrtex_dataset::atomic`]), so that a
/// failure leaves an older page whole and no temporary behind.
pub fn write_page(out: &Path, html: &str) -> anyhow::Result<()> {
    clevrtex_dataset::atomic::write(out, html.as_bytes()).with_context(|| {
        format!(
            "cannot write `{}`\nhint: check that the folder exists and is writable",
            out.display()
        )
    })
}

/// The variants to give a part of the page each, in order, when the datasets hold several
/// (`None` when there is one, or two datasets of one variant each are compared, whatever
/// their names).
fn per_variant(sums: &[Summary]) -> Option<Vec<String>> {
    let each: Vec<Vec<String>> = sums.iter().map(Summary::variants).collect();
    if each.iter().all(|v| v.len() <= 1) {
        return None;
    }
    let all: std::collections::BTreeSet<String> = each.into_iter().flatten().collect();
    Some(all.into_iter().collect())
}

/// The sections about the scenes: objects, visibility, camera and lights.
fn write_scenes(page: &mut html::Page, sums: &[Summary], labels: &[String]) -> anyhow::Result<()> {
    section::scenes::write(page, sums, labels)?;
    section::visibility::write(page, sums)?;
    section::camera::write(page, sums, labels)
}

/// The page, and the problems met while drawing it (cells of the preview left empty).
pub fn build(sums: &[Summary], options: &Options) -> anyhow::Result<(String, Vec<String>)> {
    let mut problems = Vec::new();
    let labels: Vec<String> = sums
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let name = Path::new(&s.label)
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_else(|| s.label.clone());
            if sums.len() > 1 {
                format!("{} {name}", ["A", "B"][i])
            } else {
                name
            }
        })
        .collect();
    let mut page = html::Page {
        html: String::new(),
        labels: labels.clone(),
        prefix: String::new(),
    };
    section::overview::write(&mut page, sums, &labels, options)?;
    section::splits::write(&mut page, sums, &labels)?;
    section::failures::write(&mut page, sums, &labels)?;
    match per_variant(sums) {
        // One dataset (or two compared) of one variant each: the scenes as they are.
        None => write_scenes(&mut page, sums, &labels)?,
        // Several variants: pooling them would mix their distributions (`camo`'s objects
        // with `clevr`'s), so the scene statistics get one part per variant.
        Some(variants) => {
            for v in variants {
                let (subs, sub_labels): (Vec<Summary>, Vec<String>) = sums
                    .iter()
                    .zip(&labels)
                    .filter(|(s, _)| s.data.samples.iter().any(|x| x.variant == v))
                    .map(|(s, l)| (s.of_variant(&v), l.clone()))
                    .unzip();
                page.prefix = format!("{v}: ");
                page.labels.clone_from(&sub_labels);
                write_scenes(&mut page, &subs, &sub_labels)?;
            }
            page.prefix.clear();
            page.labels.clone_from(&labels);
        }
    }
    section::contrast::write(&mut page, sums, &labels)?;
    section::preview::write(&mut page, sums, &labels, options, &mut problems)?;
    section::provenance::write(&mut page, sums, &labels)?;
    page.html += "</body></html>\n";
    Ok((page.html, problems))
}
