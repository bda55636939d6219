//! The top of the page: its title, the datasets with their images and objects, and what the
//! report read (metadata of every image, the pixels of a capped sample).

use std::fmt::Write as _;

use crate::report::html::{esc, Page, CSS};
use crate::report::{Options, Summary};

/// Write the section into `page`.
pub(in crate::report) fn write(
    page: &mut Page,
    sums: &[Summary],
    labels: &[String],
    options: &Options,
) -> anyhow::Result<()> {
    let _ = write!(
        page.html,
        "<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>clevrtex report: {}</title><style>{CSS}</style></head><body><h1>Dataset report</h1>",
        esc(&labels.join(" vs "))
    );
    page.html += "<table><tr><th>dataset</th><th>folder</th><th>images</th><th>objects</th></tr>";
    for (s, l) in sums.iter().zip(labels) {
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
        options.max_texture_samples,
        if sums.len() > 1 {
            " With two datasets, every statistic has a two-sample test: chi-square on the category counts, Kolmogorov-Smirnov on continuous values (asymptotic p-values); a small p says the two differ."
        } else {
            ""
        }
    );
    Ok(())
}
