//! "Provenance": the run manifests (seed, config hash, indices, shard, versions, command),
//! the user materials they drew from (`--materials DIR`: file, group, textures, content
//! hash), the unreadable ones, and the seeds, versions and sizes found in the metadata.

use std::fmt::Write as _;

use crate::report::data;
use crate::report::html::{esc, Page, NOT_HERE};
use crate::report::Summary;

/// Write the section into `page`.
pub(in crate::report) fn write(
    page: &mut Page,
    sums: &[Summary],
    labels: &[String],
) -> anyhow::Result<()> {
    page.h2("Provenance");
    for (s, l) in sums.iter().zip(labels) {
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
            let mut user = std::collections::BTreeMap::new();
            for m in &s.data.manifests {
                for (name, u) in &m.user_materials {
                    user.entry(name.clone())
                        .or_insert_with(Vec::new)
                        .push(u.clone());
                }
            }
            if !user.is_empty() {
                page.html += "<p>User materials (<code>--materials DIR</code>) the runs drew from, with the content hash of each file and its textures:</p><table><tr><th>material</th><th>file</th><th>node group</th><th>textures</th><th>xxh3</th></tr>";
                for (name, list) in &user {
                    let mut hashes: Vec<&str> = list.iter().map(|u| u.xxh3.as_str()).collect();
                    hashes.sort_unstable();
                    hashes.dedup();
                    let u = &list[0];
                    let _ = write!(
                        page.html,
                        "<tr><td>{}</td><td><code>{}</code></td><td>{}</td><td>{}</td><td><code>{}</code></td></tr>",
                        esc(name),
                        esc(&u.file),
                        esc(u.group.as_deref().unwrap_or("")),
                        esc(&u.textures.join(", ")),
                        esc(&hashes.join(" / ")),
                    );
                }
                page.html += "</table>";
            }
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
    Ok(())
}
