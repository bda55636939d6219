//! "Scenes": objects per image against the reference's uniform 3..10, the category shares
//! (shapes, sizes, colours, materials, backdrops) and the objects' positions on the ground.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use crate::report::data;
use crate::report::html::{esc, svg_img, test_line, Page};
use crate::report::summary::{count_by, per_object};
use crate::report::{plot, stats, Summary};

/// The reference's uniform object count.
const COUNT_RANGE: std::ops::RangeInclusive<usize> = 3..=10;

/// Write the section into `page`.
pub(in crate::report) fn write(
    page: &mut Page,
    sums: &[Summary],
    labels: &[String],
) -> anyhow::Result<()> {
    page.h2("Scenes");
    page.html += "<div class=\"figs\">";
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
            .zip(labels)
            .map(|(c, l)| (l.as_str(), c.clone()))
            .collect();
        let svg = plot::bars("objects per image", &cats, &series, Some(&expected))?;
        page.html += "<div class=\"fig\"><h3>Objects per image</h3>";
        page.html += &svg_img(&svg, "objects per image");
        page.html += "<p class=\"cap\">Share of images with each object count; black ticks: the uniform 3..10 of the reference. The chi-square test of fit to that uniform is below.</p>";
        for ((s, c), l) in sums.iter().zip(&counts).zip(labels) {
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
            .zip(labels)
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
                let v = per_object(sums, &|o| Some(o.coords[k]));
                page.html += &test_line(
                    &format!("two-sample Kolmogorov-Smirnov on {axis}"),
                    stats::ks_two_sample(&v[0], &v[1]),
                );
            }
        }
        page.html += "</div>";
    }
    page.html += "</div>";
    Ok(())
}
