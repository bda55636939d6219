//! "Failure ledger": the images that failed and are missing, grouped by the first line of
//! their error (`failures.jsonl`).

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
    page.h2("Failure ledger");
    for (s, l) in sums.iter().zip(labels) {
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
    Ok(())
}
