//! `clevrtex report DIR --out report.html [--compare OTHER]`: one self-contained HTML page
//! (plots as SVG and the preview sheet as PNG, both as data URIs; inline CSS; no script, no
//! network) with a dataset's statistics, or two datasets side by side with a two-sample test
//! per statistic. Works on our output and on the published ClevrTex layout; what a dataset
//! does not record is shown as "not in this dataset". See `docs/report.md`.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};

use anyhow::Context;
use clevrtex_scene::{Config, SampleRequest};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use rayon::prelude::*;

pub mod data;
mod geometry;
pub mod plot;
pub mod stats;
pub mod texture;

use data::Dataset;
use stats::Test;

/// What the report reads and draws (the options of `clevrtex report`).
#[derive(Debug, Clone)]
pub struct Options {
    /// Images per variant whose pixels are read (object contrast, depth range), evenly spread
    /// over the variant's indices; the metadata of every image is read regardless.
    pub max_texture_samples: usize,
    /// Samples in the preview sheet.
    pub preview: u32,
}

/// The reference's uniform object count.
const COUNT_RANGE: std::ops::RangeInclusive<usize> = 3..=10;

/// What the report shows of one dataset.
pub struct Summary {
    label: String,
    /// The dataset as read.
    pub data: Dataset,
    /// Samples left out of the measurements, one line each (`<stem>: <why>`).
    pub problems: Vec<String>,
    /// The measured images: (variant, measures).
    pub measures: Vec<(String, texture::ImageMeasures)>,
    measured: BTreeMap<String, (usize, usize)>,
    /// Light offsets from their rig positions (m), when the scenes could be recomputed.
    light_offsets: Vec<f64>,
    /// Images whose scene was recomputed and matched, of those tried.
    lights_matched: (usize, usize),
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
    let root = clevrtex_render::dataset::root(dir)
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
                let config = configs.get(s.variant.as_str())?.as_ref()?;
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
        light_offsets: lights.into_iter().flatten().flatten().collect(),
        lights_matched: (matched, tried),
        data,
        problems,
        measures,
        measured,
    })
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Standard base64 (RFC 4648, with padding) for the data URIs.
fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for c in bytes.chunks(3) {
        let n = (u32::from(c[0]) << 16)
            | (u32::from(*c.get(1).unwrap_or(&0)) << 8)
            | u32::from(*c.get(2).unwrap_or(&0));
        for k in 0..4 {
            if k <= c.len() {
                out.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

fn svg_img(svg: &str, alt: &str) -> String {
    format!(
        "<img class=\"plot\" alt=\"{}\" src=\"data:image/svg+xml;base64,{}\">",
        esc(alt),
        base64(svg.as_bytes())
    )
}

const NOT_HERE: &str = "not in this dataset";

fn fmt_p(p: f64) -> String {
    if p.is_nan() {
        "n/a".into()
    } else if p < 1e-4 {
        format!("{p:.1e}")
    } else {
        format!("{p:.4}")
    }
}

fn test_line(name: &str, t: Option<Test>) -> String {
    match t {
        Some(t) => match t.df {
            Some(df) => format!(
                "<p class=\"test\">{name}: χ² = {:.2}, df = {df:.0}, <b>p = {}</b></p>",
                t.statistic,
                fmt_p(t.p)
            ),
            None => format!(
                "<p class=\"test\">{name}: D = {:.4}, <b>p = {}</b></p>",
                t.statistic,
                fmt_p(t.p)
            ),
        },
        None => format!("<p class=\"test\">{name}: not enough data for a test</p>"),
    }
}

/// The page under construction.
struct Page {
    html: String,
    labels: Vec<String>,
}

impl Page {
    fn h2(&mut self, t: &str) {
        let _ = write!(self.html, "<h2>{}</h2>", esc(t));
    }

    /// A categorical statistic: one count map per dataset.
    fn categorical(
        &mut self,
        title: &str,
        caption: &str,
        counts: &[BTreeMap<String, f64>],
    ) -> anyhow::Result<()> {
        let _ = write!(self.html, "<div class=\"fig\"><h3>{}</h3>", esc(title));
        let present: Vec<usize> = (0..counts.len())
            .filter(|&i| !counts[i].is_empty())
            .collect();
        if present.is_empty() {
            let _ = write!(self.html, "<p class=\"na\">{NOT_HERE}</p></div>");
            return Ok(());
        }
        let cats: Vec<String> = counts
            .iter()
            .flat_map(|c| c.keys().cloned())
            .collect::<std::collections::BTreeSet<_>>()
            .into_iter()
            .collect();
        let vecs: Vec<Vec<f64>> = counts
            .iter()
            .map(|c| {
                cats.iter()
                    .map(|k| c.get(k).copied().unwrap_or(0.0))
                    .collect()
            })
            .collect();
        let series: Vec<plot::Series> = present
            .iter()
            .map(|&i| (self.labels[i].as_str(), vecs[i].clone()))
            .collect();
        let svg = plot::bars(title, &cats, &series, None)?;
        self.html += &svg_img(&svg, title);
        let _ = write!(self.html, "<p class=\"cap\">{}</p>", esc(caption));
        self.missing_note(counts.iter().map(|c| c.is_empty()));
        if counts.len() == 2 && present.len() == 2 {
            self.html += &test_line(
                "two-sample chi-square",
                stats::chi2_two_sample(&vecs[0], &vecs[1]),
            );
        }
        // The counts as a table (categories with their shares).
        self.html += "<details><summary>counts</summary><table><tr><th></th>";
        for i in &present {
            let _ = write!(self.html, "<th>{}</th>", esc(&self.labels[*i]));
        }
        self.html += "</tr>";
        for (k, cat) in cats.iter().enumerate() {
            let _ = write!(self.html, "<tr><td>{}</td>", esc(cat));
            for &i in &present {
                let n: f64 = vecs[i].iter().sum();
                let _ = write!(
                    self.html,
                    "<td>{} ({:.1}%)</td>",
                    vecs[i][k],
                    100.0 * vecs[i][k] / n.max(1.0)
                );
            }
            self.html += "</tr>";
        }
        self.html += "</table></details></div>";
        Ok(())
    }

    fn missing_note(&mut self, empty: impl Iterator<Item = bool>) {
        let names: Vec<String> = empty
            .zip(&self.labels)
            .filter(|(e, _)| *e)
            .map(|(_, l)| esc(l))
            .collect();
        if !names.is_empty() && self.labels.len() > 1 {
            let _ = write!(
                self.html,
                "<p class=\"na\">{}: {NOT_HERE}</p>",
                names.join(", ")
            );
        }
    }

    /// A continuous statistic: one list of values per dataset.
    fn continuous(
        &mut self,
        title: &str,
        caption: &str,
        values: &[Vec<f64>],
        marker: Option<f64>,
        log_x: bool,
    ) -> anyhow::Result<()> {
        let _ = write!(self.html, "<div class=\"fig\"><h3>{}</h3>", esc(title));
        if values.iter().all(|v| v.is_empty()) {
            let _ = write!(self.html, "<p class=\"na\">{NOT_HERE}</p></div>");
            return Ok(());
        }
        let series: Vec<plot::Series> = values
            .iter()
            .enumerate()
            .filter(|(_, v)| !v.is_empty())
            .map(|(i, v)| (self.labels[i].as_str(), v.clone()))
            .collect();
        let svg = plot::histogram(title, &series, marker, log_x)?;
        self.html += &svg_img(&svg, title);
        let _ = write!(self.html, "<p class=\"cap\">{}</p>", esc(caption));
        self.missing_note(values.iter().map(|v| v.is_empty()));
        self.html += "<table><tr><th></th><th>n</th><th>min</th><th>median</th><th>mean</th><th>max</th></tr>";
        for (i, v) in values.iter().enumerate() {
            if v.is_empty() {
                continue;
            }
            let mut s = v.clone();
            s.sort_by(f64::total_cmp);
            let mean = s.iter().sum::<f64>() / s.len() as f64;
            let _ = write!(
                self.html,
                "<tr><td>{}</td><td>{}</td><td>{:.4}</td><td>{:.4}</td><td>{:.4}</td><td>{:.4}</td></tr>",
                esc(&self.labels[i]),
                s.len(),
                s[0],
                s[s.len() / 2],
                mean,
                s[s.len() - 1]
            );
        }
        self.html += "</table>";
        if values.len() == 2 && values.iter().all(|v| !v.is_empty()) {
            self.html += &test_line(
                "two-sample Kolmogorov-Smirnov",
                stats::ks_two_sample(&values[0], &values[1]),
            );
        }
        self.html += "</div>";
        Ok(())
    }
}

fn count_by<'a>(items: impl Iterator<Item = &'a str>) -> BTreeMap<String, f64> {
    let mut m = BTreeMap::new();
    for i in items {
        *m.entry(i.to_string()).or_insert(0.0) += 1.0;
    }
    m
}

const CSS: &str = "body{font-family:sans-serif;margin:2em;max-width:1300px;color:#222}\
h1{font-size:1.6em}h2{border-bottom:1px solid #ccc;margin-top:2em}h3{font-size:1.05em;margin:.2em 0}\
.figs{display:flex;flex-wrap:wrap;gap:16px}.fig{border:1px solid #ddd;padding:8px;width:580px}\
img.plot{width:560px;height:300px;display:block}img.sheet{max-width:100%;display:block}\
table{border-collapse:collapse;font-size:.85em;margin:.4em 0}td,th{border:1px solid #ddd;padding:2px 6px;text-align:right}\
td:first-child,th:first-child{text-align:left}.cap{font-size:.85em;color:#555}.na{color:#a60}\
.test{font-size:.9em}code{background:#f4f4f4;padding:0 3px}pre{white-space:pre-wrap;font-size:.8em;background:#f8f8f8;padding:4px}";

/// The page, and the problems met while drawing it (cells of the preview left empty).
pub fn build(sums: &[Summary], args: &Options) -> anyhow::Result<(String, Vec<String>)> {
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
    let mut page = Page {
        html: String::new(),
        labels: labels.clone(),
    };
    let _ = write!(
        page.html,
        "<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>clevrtex report: {}</title><style>{CSS}</style></head><body><h1>Dataset report</h1>",
        esc(&labels.join(" vs "))
    );
    page.html += "<table><tr><th>dataset</th><th>folder</th><th>images</th><th>objects</th></tr>";
    for (s, l) in sums.iter().zip(&labels) {
        let objs: usize = s.data.samples.iter().map(|x| x.objects.len()).sum();
        let _ = write!(
            page.html,
            "<tr><td>{}</td><td><code>{}</code></td><td>{}</td><td>{objs}</td></tr>",
            esc(l),
            esc(&s.label),
            s.data.samples.len()
        );
    }
    let _ = write!(
        page.html,
        "</table><p class=\"cap\">Made by <code>clevrtex report</code> {}. Statistics read every image's metadata; the object contrast and depth range read the pixels of at most {} images per variant, evenly spread over its indices (<code>--max-texture-samples</code>).{}</p>",
        env!("CARGO_PKG_VERSION"),
        args.max_texture_samples,
        if sums.len() > 1 {
            " With two datasets, every statistic has a two-sample test: chi-square on the category counts, Kolmogorov-Smirnov on continuous values (asymptotic p-values); a small p says the two differ."
        } else {
            ""
        }
    );

    // Counts per split and variant.
    page.h2("Images per variant and split");
    for (s, l) in sums.iter().zip(&labels) {
        let mut t: BTreeMap<(&str, &str), usize> = BTreeMap::new();
        for x in &s.data.samples {
            *t.entry((&x.variant, &x.split)).or_default() += 1;
        }
        let splits: Vec<&str> = ["train", "val", "test"]
            .into_iter()
            .filter(|sp| t.keys().any(|k| k.1 == *sp))
            .chain(
                t.keys()
                    .map(|k| k.1)
                    .filter(|sp| !["train", "val", "test"].contains(sp))
                    .collect::<std::collections::BTreeSet<_>>(),
            )
            .collect();
        let _ = write!(page.html, "<h3>{}</h3><table><tr><th>variant</th>", esc(l));
        for sp in &splits {
            let _ = write!(page.html, "<th>{}</th>", esc(sp));
        }
        page.html += "<th>total</th></tr>";
        let variants: std::collections::BTreeSet<&str> = t.keys().map(|k| k.0).collect();
        for v in variants {
            let _ = write!(page.html, "<tr><td>{}</td>", esc(v));
            let mut tot = 0;
            for sp in &splits {
                let n = t.get(&(v, sp)).copied().unwrap_or(0);
                tot += n;
                let _ = write!(page.html, "<td>{n}</td>");
            }
            let _ = write!(page.html, "<td>{tot}</td></tr>");
        }
        page.html += "</table>";
    }

    // Failure ledger.
    page.h2("Failure ledger");
    for (s, l) in sums.iter().zip(&labels) {
        let f = &s.data.failures;
        let _ = write!(page.html, "<h3>{}</h3>", esc(l));
        if f.is_empty() {
            page.html +=
                "<p>No failures recorded (no <code>failures.jsonl</code>, or an empty one).</p>";
            continue;
        }
        let mut groups: BTreeMap<String, Vec<String>> = BTreeMap::new();
        for e in f {
            let first = e
                .error
                .lines()
                .next()
                .unwrap_or("")
                .chars()
                .take(160)
                .collect();
            groups
                .entry(first)
                .or_default()
                .push(format!("{} {}", e.variant, e.index));
        }
        let _ = write!(
            page.html,
            "<p>{} image(s) failed and are missing (rerun the run's command to retry them):</p><table><tr><th>error</th><th>images</th><th>which</th></tr>",
            f.len()
        );
        let mut groups: Vec<_> = groups.into_iter().collect();
        groups.sort_by_key(|g| std::cmp::Reverse(g.1.len()));
        for (err, which) in groups {
            let shown: Vec<&str> = which.iter().take(10).map(String::as_str).collect();
            let _ = write!(
                page.html,
                "<tr><td>{}</td><td>{}</td><td>{}{}</td></tr>",
                esc(&err),
                which.len(),
                esc(&shown.join(", ")),
                if which.len() > 10 { ", ..." } else { "" }
            );
        }
        page.html += "</table>";
    }

    // The statistics.
    page.h2("Scenes");
    page.html += "<div class=\"figs\">";
    let per_image = |f: &dyn Fn(&data::Sample) -> Option<f64>| -> Vec<Vec<f64>> {
        sums.iter()
            .map(|s| s.data.samples.iter().filter_map(f).collect())
            .collect()
    };
    let per_object = |f: &dyn Fn(&data::Object) -> Option<f64>| -> Vec<Vec<f64>> {
        sums.iter()
            .map(|s| {
                s.data
                    .samples
                    .iter()
                    .flat_map(|x| x.objects.iter().filter_map(f))
                    .collect()
            })
            .collect()
    };
    // Objects per image, against the uniform 3..10.
    {
        let cats: Vec<String> = COUNT_RANGE.map(|n| n.to_string()).collect();
        let counts: Vec<Vec<f64>> = sums
            .iter()
            .map(|s| {
                COUNT_RANGE
                    .map(|n| {
                        s.data
                            .samples
                            .iter()
                            .filter(|x| x.objects.len() == n)
                            .count() as f64
                    })
                    .collect()
            })
            .collect();
        let expected = vec![1.0 / cats.len() as f64; cats.len()];
        let series: Vec<plot::Series> = counts
            .iter()
            .zip(&labels)
            .map(|(c, l)| (l.as_str(), c.clone()))
            .collect();
        let svg = plot::bars("objects per image", &cats, &series, Some(&expected))?;
        page.html += "<div class=\"fig\"><h3>Objects per image</h3>";
        page.html += &svg_img(&svg, "objects per image");
        page.html += "<p class=\"cap\">Share of images with each object count; black ticks: the uniform 3..10 of the reference. The chi-square test of fit to that uniform is below.</p>";
        for ((s, c), l) in sums.iter().zip(&counts).zip(&labels) {
            let n = s.data.samples.len() as f64;
            let outside = n - c.iter().sum::<f64>();
            let e = vec![c.iter().sum::<f64>() / cats.len() as f64; cats.len()];
            page.html += &test_line(
                &format!("{} vs uniform 3..10", esc(l)),
                stats::chi2_fit(c, &e),
            );
            if outside > 0.0 {
                let _ = write!(
                    page.html,
                    "<p class=\"na\">{}: {outside} image(s) outside 3..10, left out of the test</p>",
                    esc(l)
                );
            }
        }
        if counts.len() == 2 {
            page.html += &test_line(
                "two-sample chi-square",
                stats::chi2_two_sample(&counts[0], &counts[1]),
            );
        }
        page.html += "</div>";
    }
    let cat_obj = |f: &dyn Fn(&data::Object) -> Option<&str>| -> Vec<BTreeMap<String, f64>> {
        sums.iter()
            .map(|s| {
                count_by(
                    s.data
                        .samples
                        .iter()
                        .flat_map(|x| x.objects.iter().filter_map(f)),
                )
            })
            .collect()
    };
    page.categorical(
        "Shapes",
        "Share of objects per shape.",
        &cat_obj(&|o| Some(&o.shape)),
    )?;
    page.categorical(
        "Sizes",
        "Share of objects per size.",
        &cat_obj(&|o| Some(&o.size)),
    )?;
    page.categorical(
        "Colours",
        "Share of objects per colour name (only the variants with colours, vbg and clevr, have them).",
        &cat_obj(&|o| o.color.as_deref()),
    )?;
    page.categorical(
        "Object materials",
        "Share of objects per material.",
        &cat_obj(&|o| Some(&o.material)),
    )?;
    page.categorical(
        "Ground materials",
        "Share of images per backdrop material.",
        &sums
            .iter()
            .map(|s| count_by(s.data.samples.iter().map(|x| x.ground_material.as_str())))
            .collect::<Vec<_>>(),
    )?;
    // Positions on the ground plane.
    {
        let series: Vec<(&str, Vec<(f64, f64)>)> = sums
            .iter()
            .zip(&labels)
            .map(|(s, l)| {
                (
                    l.as_str(),
                    s.data
                        .samples
                        .iter()
                        .flat_map(|x| x.objects.iter().map(|o| (o.coords[0], o.coords[1])))
                        .filter(|p| p.0.is_finite() && p.1.is_finite())
                        .collect(),
                )
            })
            .collect();
        let svg = plot::scatter("x (m)", "y (m)", &series)?;
        page.html += "<div class=\"fig\"><h3>Object positions on the ground plane</h3>";
        page.html += &svg_img(&svg, "object positions");
        page.html += "<p class=\"cap\">World x, y of every object's origin (at most 4,000 points drawn per dataset).</p>";
        if sums.len() == 2 {
            for (k, axis) in ["x", "y"].iter().enumerate() {
                let v = per_object(&|o| Some(o.coords[k]));
                page.html += &test_line(
                    &format!("two-sample Kolmogorov-Smirnov on {axis}"),
                    stats::ks_two_sample(&v[0], &v[1]),
                );
            }
        }
        page.html += "</div>";
    }
    page.html += "</div>";

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
        &per_object(&|o| o.visible_pixels.map(|p| p as f64)),
        threshold.map(|t| t as f64),
        true,
    )?;
    page.continuous(
        "Share of each object occluded",
        "1 - visible pixels / the pixels of the object's unoccluded silhouette (the convex hull of its projected outline, clipped to the image, from the metadata's camera). Cubes, cylinders and spheres only (their outline is that hull); other shapes are left out.",
        &per_object(&|o| o.occluded),
        None,
        false,
    )?;
    page.html += "</div>";

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
        .zip(&labels)
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
        &per_image(&|x| x.attempt.map(f64::from)),
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

    // Texture statistics per variant.
    page.h2("How much objects stand out: contrast to the background ring");
    page.html += "<p class=\"cap\">Per object: the mean colour difference (CIELAB ΔE*76) and the texture-feature distance (the material distinctness statistics: colour histogram and gradient energy and orientation; 0 = identical) between the object and the background within max(2, W/40) px around it. Low values mean the object is hard to tell from its surroundings by colour or texture: compare <code>full</code> and <code>camo</code> with <code>clevr</code>. Measured on a capped sample of images, see the table.</p>";
    page.html += "<table><tr><th>dataset</th><th>variant</th><th>images measured</th><th>objects</th><th>ΔE median</th><th>ΔE mean</th><th>feature distance median</th><th>feature distance mean</th></tr>";
    let mut de_series: Vec<(String, Vec<f64>)> = Vec::new();
    let mut fd_series: Vec<(String, Vec<f64>)> = Vec::new();
    for (s, l) in sums.iter().zip(&labels) {
        for (v, (n, of)) in &s.measured {
            let c: Vec<texture::Contrast> = s
                .measures
                .iter()
                .filter(|m| &m.0 == v)
                .flat_map(|m| m.1.contrasts.iter().copied())
                .collect();
            let med = |mut x: Vec<f64>| {
                if x.is_empty() {
                    return f64::NAN;
                }
                x.sort_by(f64::total_cmp);
                x[x.len() / 2]
            };
            let de: Vec<f64> = c.iter().map(|c| c.delta_e).collect();
            let fd: Vec<f64> = c.iter().map(|c| c.feature_distance).collect();
            let mean = |x: &[f64]| x.iter().sum::<f64>() / x.len().max(1) as f64;
            if c.is_empty() {
                let _ = write!(
                    page.html,
                    "<tr><td>{}</td><td>{}</td><td>{n} of {of}</td><td>0</td><td colspan=\"4\" class=\"na\">{NOT_HERE} (needs the rgb and mask passes)</td></tr>",
                    esc(l),
                    esc(v)
                );
                continue;
            }
            let _ = write!(
                page.html,
                "<tr><td>{}</td><td>{}</td><td>{n} of {of}</td><td>{}</td><td>{:.1}</td><td>{:.1}</td><td>{:.3}</td><td>{:.3}</td></tr>",
                esc(l),
                esc(v),
                c.len(),
                med(de.clone()),
                mean(&de),
                med(fd.clone()),
                mean(&fd)
            );
            let name = if sums.len() > 1 {
                format!("{} {v}", ["A", "B"][de_series.len().min(1)])
            } else {
                v.clone()
            };
            de_series.push((name.clone(), de));
            fd_series.push((name, fd));
        }
    }
    page.html += "</table><div class=\"figs\">";
    for (title, series) in [
        ("Object vs ring: ΔE*76", &de_series),
        ("Object vs ring: texture-feature distance", &fd_series),
    ] {
        if series.is_empty() {
            continue;
        }
        let s: Vec<plot::Series> = series
            .iter()
            .map(|(n, v)| (n.as_str(), v.clone()))
            .collect();
        let svg = plot::histogram(title, &s, None, false)?;
        let _ = write!(page.html, "<div class=\"fig\"><h3>{}</h3>", esc(title));
        page.html += &svg_img(&svg, title);
        page.html += "<p class=\"cap\">One curve per variant (and dataset).</p></div>";
    }
    page.html += "</div>";

    // Preview sheets.
    if args.preview > 0 {
        page.h2("Preview");
        for (s, l) in sums.iter().zip(&labels) {
            let sheet = crate::preview::draw(&crate::preview::Options::first(
                s.data.root.clone(),
                args.preview,
                128,
            ))?;
            problems.extend(sheet.problems.iter().map(|p| format!("preview: {p}")));
            let mut png = Vec::new();
            sheet
                .image
                .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
                .context("cannot encode the preview sheet")?;
            let _ = write!(
                page.html,
                "<h3>{}</h3><p class=\"cap\">The first {} sample(s): {} (as <code>clevrtex preview</code> draws them).</p><img class=\"sheet\" alt=\"preview of {}\" src=\"data:image/png;base64,{}\">",
                esc(l),
                sheet.samples,
                esc(&sheet.columns.join(", ")),
                esc(l),
                base64(&png)
            );
        }
    }

    // Provenance.
    page.h2("Provenance");
    for (s, l) in sums.iter().zip(&labels) {
        let _ = write!(page.html, "<h3>{}</h3>", esc(l));
        if s.data.manifests.is_empty() {
            let _ = write!(page.html, "<p class=\"na\">run manifest: {NOT_HERE}</p>");
        } else {
            page.html += "<table><tr><th>variant</th><th>seed</th><th>config hash</th><th>indices</th><th>shard</th><th>clevrtex</th><th>Blender</th><th>command</th></tr>";
            for m in &s.data.manifests {
                let _ = write!(
                    page.html,
                    "<tr><td>{}</td><td>{}</td><td><code>{}</code></td><td>{}..{} of {}</td><td>{} of {}</td><td>{}</td><td>{}</td><td><code>{}</code></td></tr>",
                    esc(&m.variant),
                    m.seed,
                    esc(&m.config_hash),
                    m.start,
                    m.end,
                    m.total,
                    m.shard[0],
                    m.shard[1],
                    esc(&m.tool_version),
                    esc(&m.blender_version),
                    esc(&m.command.join(" "))
                );
            }
            page.html += "</table>";
        }
        for (p, why) in &s.data.bad_manifests {
            let _ = write!(
                page.html,
                "<p class=\"na\">unreadable manifest <code>{}</code>: {}</p>",
                esc(&p.display().to_string()),
                esc(why)
            );
        }
        let distinct = |f: &dyn Fn(&data::Sample) -> Option<String>| {
            let v: std::collections::BTreeSet<String> =
                s.data.samples.iter().filter_map(f).collect();
            if v.is_empty() {
                NOT_HERE.to_string()
            } else {
                v.into_iter().collect::<Vec<_>>().join(", ")
            }
        };
        let _ = write!(
            page.html,
            "<table><tr><td>seeds in the metadata</td><td>{}</td></tr><tr><td>Blender versions in the metadata</td><td>{}</td></tr><tr><td>clevrtex versions in the metadata</td><td>{}</td></tr><tr><td>image sizes</td><td>{}</td></tr></table>",
            esc(&distinct(&|x| x.seed.map(|v| v.to_string()))),
            esc(&distinct(&|x| x.blender_version.clone())),
            esc(&distinct(&|x| x.clevrtex_version.clone())),
            esc(&distinct(&|x| x.size.map(|(w, h)| format!("{w}x{h}")))),
        );
    }
    page.html += "</body></html>\n";
    Ok((page.html, problems))
}

/// Refuse an `--out` file inside one of the datasets `dirs`: writing there could overwrite a
/// dataset file (`--out data/clevrtex_full/0/CLEVRTEX_full_000000.png`).
pub fn refuse_output_inside(out: &Path, dirs: &[&Path]) -> anyhow::Result<()> {
    let parent = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    // The folder the file would go to, with links resolved (it must exist to be written).
    let Ok(parent) = parent.canonicalize() else {
        return Ok(());
    };
    for dir in dirs {
        let Ok(root) = dir.canonicalize() else {
            continue;
        };
        if parent.starts_with(&root) {
            anyhow::bail!(
                "`--out {}` is inside the dataset `{}`: writing there could overwrite its files\nhint: write the output outside the dataset folder, e.g. `--out {}`",
                out.display(),
                dir.display(),
                out.file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_else(|| "report.html".into())
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc_4648() {
        assert_eq!(base64(b""), "");
        assert_eq!(base64(b"f"), "Zg==");
        assert_eq!(base64(b"fo"), "Zm8=");
        assert_eq!(base64(b"foo"), "Zm9v");
        assert_eq!(base64(b"foobar"), "Zm9vYmFy");
    }

    #[test]
    fn spread_picks_evenly() {
        let v: Vec<u32> = (0..10).collect();
        assert_eq!(spread(&v, 5), vec![&0, &2, &4, &6, &8]);
        assert_eq!(spread(&v, 20).len(), 10);
    }
}
