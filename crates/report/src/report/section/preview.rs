//! "Preview": the preview sheet of the first samples of each dataset, drawn by
//! [`crate::preview`] as `clevrtex preview` draws it, embedded as a PNG.

use std::fmt::Write as _;

use anyhow::Context;

use crate::report::html::{base64, esc, Page};
use crate::report::{Options, Summary};

/// The sheets; cells left empty are added to `problems`.
pub(in crate::report) fn write(
    page: &mut Page,
    sums: &[Summary],
    labels: &[String],
    options: &Options,
    problems: &mut Vec<String>,
) -> anyhow::Result<()> {
    if options.preview > 0 {
        page.h2("Preview");
        for (s, l) in sums.iter().zip(labels) {
            let sheet = crate::preview::draw(&crate::preview::Options::first(
                s.data.root.clone(),
                options.preview,
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
    Ok(())
}
