//! "How much objects stand out": each object's contrast to the background ring around it
//! (`texture.rs` measures it), a table per variant and the two histograms.

use std::fmt::Write as _;

use crate::report::html::{esc, svg_img, Page, NOT_HERE};
use crate::report::{plot, texture, Summary};

/// Write the section into `page`.
pub(in crate::report) fn write(
    page: &mut Page,
    sums: &[Summary],
    labels: &[String],
) -> anyhow::Result<()> {
    page.h2("How much objects stand out: contrast to the background ring");
    page.html += "<p class=\"cap\">Per object: the mean colour difference (CIELAB ΔE*76) and the texture-feature distance (the material distinctness statistics: colour histogram and gradient energy and orientation; 0 = identical) between the object and the background within max(2, W/40) px around it. Low values mean the object is hard to tell from its surroundings by colour or texture: compare <code>full</code> and <code>camo</code> with <code>clevr</code>. Measured on a capped sample of images, see the table.</p>";
    page.html += "<table><tr><th>dataset</th><th>variant</th><th>images measured</th><th>objects</th><th>ΔE median</th><th>ΔE mean</th><th>feature distance median</th><th>feature distance mean</th></tr>";
    let mut de_series: Vec<(String, Vec<f64>)> = Vec::new();
    let mut fd_series: Vec<(String, Vec<f64>)> = Vec::new();
    for (s, l) in sums.iter().zip(labels) {
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
    Ok(())
}
