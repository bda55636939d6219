//! Reading and measuring one dataset for the report: its metadata ([`super::data`]), the
//! pixels of a capped, evenly spread sample per variant ([`super::texture`]), and the lights,
//! recomputed from each image's seed; and the per-image and per-object value lists the
//! sections draw.

use std::collections::BTreeMap;
use std::io::IsTerminal;
use std::path::Path;

use anyhow::Context;
use clevrtex_scene::{Config, SampleRequest};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use rayon::prelude::*;

use super::data::{self, Dataset};
use super::{texture, Options};

/// What the report shows of one dataset.
pub struct Summary {
    /// The dataset's folder, canonical where it can be.
    pub label: String,
    /// The dataset as read.
    pub data: Dataset,
    /// Samples left out of the measurements, one line each (`<stem>: <why>`).
    pub problems: Vec<String>,
    /// The measured images: (variant, measures).
    pub measures: Vec<(String, texture::ImageMeasures)>,
    /// Per variant: images measured, of those read.
    pub measured: BTreeMap<String, (usize, usize)>,
    /// Light offsets from their rig positions (m), when the scenes could be recomputed.
    pub light_offsets: Vec<f64>,
    /// Images whose scene was recomputed and matched, of those tried.
    pub lights_matched: (usize, usize),
    /// Per sample (in the order of `data.samples`): its light offsets, when its scene was
    /// recomputed and matched.
    sample_lights: Vec<Option<Vec<f64>>>,
}

impl Summary {
    /// The variants of the dataset's samples, in order.
    pub fn variants(&self) -> Vec<String> {
        let mut v: Vec<String> = self
            .data
            .samples
            .iter()
            .map(|s| s.variant.clone())
            .collect();
        v.dedup();
        v
    }

    /// The part of this summary about variant `variant`: its samples, manifests, failures
    /// and measurements. Problems stay with the whole dataset (they are reported once).
    pub fn of_variant(&self, variant: &str) -> Summary {
        let keep: Vec<usize> = (0..self.data.samples.len())
            .filter(|&i| self.data.samples[i].variant == variant)
            .collect();
        let sample_lights: Vec<Option<Vec<f64>>> = keep
            .iter()
            .map(|&i| self.sample_lights[i].clone())
            .collect();
        let tried = keep
            .iter()
            .filter(|&&i| self.data.samples[i].seed.is_some())
            .count();
        Summary {
            label: self.label.clone(),
            data: Dataset {
                root: self.data.root.clone(),
                samples: keep.iter().map(|&i| self.data.samples[i].clone()).collect(),
                manifests: (self.data.manifests.iter())
                    .filter(|m| m.variant == variant)
                    .cloned()
                    .collect(),
                failures: (self.data.failures.iter())
                    .filter(|f| f.variant == variant)
                    .cloned()
                    .collect(),
                bad_manifests: Vec::new(),
                problems: Vec::new(),
                loader_splits: (self.data.loader_splits.iter())
                    .filter(|(v, _)| *v == variant)
                    .map(|(v, d)| (v.clone(), d.clone()))
                    .collect(),
            },
            problems: Vec::new(),
            measures: (self.measures.iter())
                .filter(|(v, _)| v == variant)
                .cloned()
                .collect(),
            measured: (self.measured.iter())
                .filter(|(v, _)| v.as_str() == variant)
                .map(|(v, n)| (v.clone(), *n))
                .collect(),
            light_offsets: sample_lights.iter().flatten().flatten().copied().collect(),
            lights_matched: (sample_lights.iter().filter(|l| l.is_some()).count(), tried),
            sample_lights,
        }
    }
}

fn progress(len: u64, what: &str) -> ProgressBar {
    let target = if std::io::stderr().is_terminal() {
        ProgressDrawTarget::stderr()
    } else {
        ProgressDrawTarget::hidden()
    };
    let bar = ProgressBar::with_draw_target(Some(len), target);
    bar.set_style(
        ProgressStyle::with_template(&format!("{{bar:24}} {{pos}}/{{len}} {what}, ETA {{eta}}"))
            .expect("valid template"),
    );
    bar
}

/// Evenly spread pick of at most `n` of `items`.
fn spread<T>(items: &[T], n: usize) -> Vec<&T> {
    if items.len() <= n {
        return items.iter().collect();
    }
    (0..n).map(|i| &items[i * items.len() / n]).collect()
}

/// Read and measure the dataset under `dir`.
pub fn summarise(dir: &Path, args: &Options) -> anyhow::Result<Summary> {
    let bar = progress(0, "metadata files");
    let data = data::read(dir, &bar)?;
    bar.finish_and_clear();
    let root = clevrtex_dataset::dataset::root(dir)
        .with_context(|| format!("cannot read `{}`", dir.display()))?;
    // Pixels of a capped, evenly spread sample per variant.
    let mut by_variant: BTreeMap<&str, Vec<&data::Sample>> = BTreeMap::new();
    for s in &data.samples {
        by_variant.entry(&s.variant).or_default().push(s);
    }
    let mut picked = Vec::new();
    let mut measured = BTreeMap::new();
    for (v, list) in &by_variant {
        let p = spread(list, args.max_texture_samples);
        measured.insert(v.to_string(), (p.len(), list.len()));
        picked.extend(p.into_iter().copied());
    }
    let bar = progress(picked.len() as u64, "images measured");
    let measures = picked
        .par_iter()
        .map(|s| {
            let m = texture::measure(s, &root);
            bar.inc(1);
            (s, m)
        })
        .collect::<Vec<_>>();
    // A sample that cannot be read or measured is reported and left out; the report goes on.
    let mut problems = data.problems.clone();
    let measures = measures
        .into_iter()
        .filter_map(|(s, m)| match m {
            Ok(m) => Some((s.variant.clone(), m)),
            Err(e) => {
                problems.push(format!("{}: {e:#}", s.stem));
                None
            }
        })
        .collect::<Vec<_>>();
    bar.finish_and_clear();
    // Lights are not in the metadata: recompute the scene from the seed with the built-in
    // config, and trust it only when its objects are the metadata's.
    let totals: BTreeMap<&str, u64> = data
        .manifests
        .iter()
        .map(|m| (m.variant.as_str(), m.total))
        .collect();
    let max_index = data.samples.iter().map(|s| s.index).max().unwrap_or(0);
    let configs: BTreeMap<&str, Option<Config>> = by_variant
        .keys()
        .map(|v| (*v, Config::builtin(v).ok()))
        .collect();
    let lights: Vec<Option<Vec<f64>>> =
        data.samples
            .par_iter()
            .map(|s| {
                let mut config = configs.get(s.variant.as_str())?.as_ref()?.clone();
                config.set_layout_stream(&s.layout_stream).ok()?;
                let config = &config;
                let scene = clevrtex_scene::sample(
                    config,
                    &SampleRequest {
                        seed: s.seed?,
                        index: s.index,
                        attempt: s.attempt?,
                        total: totals
                            .get(s.variant.as_str())
                            .copied()
                            .unwrap_or(max_index + 1),
                    },
                )
                .ok()?;
                let same =
                    scene.objects.len() == s.objects.len()
                        && scene.objects.iter().zip(&s.objects).all(|(a, b)| {
                            (0..3).all(|k| (a.location[k] - b.coords[k]).abs() < 1e-6)
                        });
                same.then(|| {
                    scene
                        .lights
                        .iter()
                        .filter_map(|l| {
                            let rig = config.base.lights.iter().find(|r| r.name == l.name)?;
                            Some(dist(l.location, rig.location))
                        })
                        .collect()
                })
            })
            .collect();
    let tried = data.samples.iter().filter(|s| s.seed.is_some()).count();
    let matched = lights.iter().filter(|l| l.is_some()).count();
    let label = dir
        .canonicalize()
        .unwrap_or_else(|_| dir.to_path_buf())
        .display()
        .to_string();
    Ok(Summary {
        label,
        light_offsets: lights.iter().flatten().flatten().copied().collect(),
        lights_matched: (matched, tried),
        sample_lights: lights,
        data,
        problems,
        measures,
        measured,
    })
}

/// Euclidean distance.
pub(super) fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Counts per category.
pub(super) fn count_by<'a>(items: impl Iterator<Item = &'a str>) -> BTreeMap<String, f64> {
    let mut m = BTreeMap::new();
    for i in items {
        *m.entry(i.to_string()).or_insert(0.0) += 1.0;
    }
    m
}

/// One list per dataset of `f` of each image (where it gives a value).
pub(super) fn per_image(
    sums: &[Summary],
    f: &dyn Fn(&data::Sample) -> Option<f64>,
) -> Vec<Vec<f64>> {
    sums.iter()
        .map(|s| s.data.samples.iter().filter_map(f).collect())
        .collect()
}

/// One list per dataset of `f` of each object (where it gives a value).
pub(super) fn per_object(
    sums: &[Summary],
    f: &dyn Fn(&data::Object) -> Option<f64>,
) -> Vec<Vec<f64>> {
    sums.iter()
        .map(|s| {
            s.data
                .samples
                .iter()
                .flat_map(|x| x.objects.iter().filter_map(f))
                .collect()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spread_picks_evenly() {
        let v: Vec<u32> = (0..10).collect();
        assert_eq!(spread(&v, 5), vec![&0, &2, &4, &6, &8]);
        assert_eq!(spread(&v, 20).len(), 10);
    }
}
