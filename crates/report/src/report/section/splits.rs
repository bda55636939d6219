//! "Images per variant and split": a table per dataset.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use crate::report::html::{esc, Page};
use crate::report::Summary;

/// Write the section into `page`.
pub(in crate::report) fn write(
    page: &mut Page,
    sums: &[Summary],
    labels: &[String],
) -> anyhow::Result<()> {
    page.h2("Images per variant and split");
    for (s, l) in sums.iter().zip(labels) {
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
        // Where a grown dataset's recorded splits are not the public loader's (as `verify`
        // says it): the public evaluator would score another test set.
        for (v, d) in &s.data.loader_splits {
            let _ = write!(
                page.html,
                "<p><b>warning</b>: {}: {}: <code>clevrtex eval --split</code> and the public loader and evaluator use other sets; remake the variant with one <code>--total</code> for every run, in a new folder.</p>",
                esc(v),
                esc(d)
            );
        }
    }
    Ok(())
}
