//! The page's HTML: escaping, data URIs, the p-value lines, and the two kinds of figure every
//! statistic is drawn as ([`Page::categorical`], [`Page::continuous`]), with their plot, count
//! table and two-sample test. The sections (`section/`) say what is drawn, with which caption.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use super::plot;
use super::stats::{self, Test};

pub(super) fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Standard base64 (RFC 4648, with padding) for the data URIs.
pub(super) fn base64(bytes: &[u8]) -> String {
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

pub(super) fn svg_img(svg: &str, alt: &str) -> String {
    format!(
        "<img class=\"plot\" alt=\"{}\" src=\"data:image/svg+xml;base64,{}\">",
        esc(alt),
        base64(svg.as_bytes())
    )
}

pub(super) const NOT_HERE: &str = "not in this dataset";

fn fmt_p(p: f64) -> String {
    if p.is_nan() {
        "n/a".into()
    } else if p < 1e-4 {
        format!("{p:.1e}")
    } else {
        format!("{p:.4}")
    }
}

pub(super) fn test_line(name: &str, t: Option<Test>) -> String {
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
pub(super) struct Page {
    pub(super) html: String,
    pub(super) labels: Vec<String>,
    /// Put before every section heading: the variant (`camo: `) in a part of the page about
    /// one variant, else empty.
    pub(super) prefix: String,
}

impl Page {
    pub(super) fn h2(&mut self, t: &str) {
        let _ = write!(self.html, "<h2>{}{}</h2>", esc(&self.prefix), esc(t));
    }

    /// A categorical statistic: one count map per dataset.
    pub(super) fn categorical(
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
    pub(super) fn continuous(
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

pub(super) const CSS: &str = "body{font-family:sans-serif;margin:2em;max-width:1300px;color:#222}\
h1{font-size:1.6em}h2{border-bottom:1px solid #ccc;margin-top:2em}h3{font-size:1.05em;margin:.2em 0}\
.figs{display:flex;flex-wrap:wrap;gap:16px}.fig{border:1px solid #ddd;padding:8px;width:580px}\
img.plot{width:560px;height:300px;display:block}img.sheet{max-width:100%;display:block}\
table{border-collapse:collapse;font-size:.85em;margin:.4em 0}td,th{border:1px solid #ddd;padding:2px 6px;text-align:right}\
td:first-child,th:first-child{text-align:left}.cap{font-size:.85em;color:#555}.na{color:#a60}\
.test{font-size:.9em}code{background:#f4f4f4;padding:0 3px}pre{white-space:pre-wrap;font-size:.8em;background:#f8f8f8;padding:4px}";

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
}
