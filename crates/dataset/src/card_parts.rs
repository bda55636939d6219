//! Parts of the dataset card ([`crate::card`]) that say exactly what a dataset is: Markdown
//! escaping of untrusted text, the render settings of every run, the materials actually used
//! (built-in or user, with their content hashes), the identity of the dataset (suite, tool
//! version and commit, layout fingerprints) and the tool's citation (repository and year from
//! the repository's `CITATION.cff`, the one home of both).

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;

use crate::fingerprint::Layouts;
use crate::manifest::{Manifest, UserMaterial};

/// The repository's `CITATION.cff`: where the card's citation of the tool comes from.
const CITATION_CFF: &str = include_str!("../../../CITATION.cff");

/// `text` as a Markdown code span: control characters escaped, backticks and `|` replaced,
/// at most 200 characters.
pub(crate) fn code(text: &str) -> String {
    let t: String = clevrtex_scene::text::printable(text)
        .chars()
        .map(|c| match c {
            '`' => '\'',
            '|' => '/',
            c => c,
        })
        .take(200)
        .collect();
    format!("`{t}`")
}

/// A fenced block of `lines`, its fence longer than any run of backticks in them.
pub(crate) fn fenced(lang: &str, lines: &[String]) -> String {
    let longest = lines
        .iter()
        .flat_map(|l| l.split(|c| c != '`'))
        .map(str::len)
        .max()
        .unwrap_or(0);
    let fence = "`".repeat(longest.max(2) + 1);
    format!("{fence}{lang}\n{}\n{fence}\n", lines.join("\n"))
}

/// A top-level `key: value` of `CITATION.cff` (quotes removed).
pub(crate) fn citation_field(key: &str) -> Option<&'static str> {
    CITATION_CFF.lines().find_map(|l| {
        let v = l.strip_prefix(key)?.strip_prefix(':')?.trim();
        Some(v.trim_matches('"'))
    })
}

/// The tool's version as a manifest records it, with its commit: `0.1.0, commit
/// 0123456789ab (modified)`.
pub(crate) fn tool_of(m: &Manifest) -> String {
    let mut s = m.tool_version.clone();
    if !m.tool_commit.is_empty() {
        let short: String = m.tool_commit.chars().take(12).collect();
        let _ = write!(s, " @ {short}");
        if m.tool_modified == Some(true) {
            s += " (modified)";
        }
    }
    s
}

/// Render settings (width, height, samples per pixel) with the runs that used them.
pub(crate) type RenderSettings = BTreeMap<(u64, u64, u64), Vec<String>>;

/// The render settings of a manifest's `render` (`None` for older manifests).
pub(crate) fn render_of(m: &Manifest) -> Option<(u64, u64, u64)> {
    let r = m.render.as_ref()?;
    Some((
        r["width"].as_u64()?,
        r["height"].as_u64()?,
        r["samples"].as_u64()?,
    ))
}

/// The card's lines on render settings: one sentence when every run used the same, else a
/// warning and one line per setting with its runs.
pub(crate) fn render_lines(settings: &RenderSettings) -> String {
    let mut c = String::new();
    match settings.len() {
        0 => {}
        1 => {
            let (w, h, s) = settings.keys().next().expect("one");
            let _ = writeln!(
                c,
                "\nRender settings (from the runs' manifests): {w}x{h} pixels, {s} Cycles samples per pixel."
            );
        }
        _ => {
            c += "\n**Mixed settings**: the runs rendered with different settings (`clevrtex \
                  verify` fails such a folder unless it was mixed on purpose with `generate \
                  --mix-settings`):\n\n";
            for ((w, h, s), runs) in settings {
                let _ = writeln!(
                    c,
                    "- {w}x{h} pixels, {s} Cycles samples per pixel: {}",
                    runs.join(", ")
                );
            }
        }
    }
    c
}

/// The "Materials used" section: per variant the built-in and user materials the samples
/// name (from their metadata), user ones with the file, node group and content hash their
/// runs' manifests record.
pub(crate) fn materials_section(variants: &BTreeMap<String, (Vec<&Manifest>, &Layouts)>) -> String {
    let mut c = String::from("### Materials used\n\n");
    let mut any = false;
    for (v, (manifests, layouts)) in variants {
        let user: BTreeMap<&String, &UserMaterial> =
            manifests.iter().flat_map(|m| &m.user_materials).collect();
        if layouts.materials.is_empty() {
            continue;
        }
        any = true;
        let (mine, builtin): (Vec<_>, Vec<_>) = layouts
            .materials
            .iter()
            .partition(|(name, _)| user.contains_key(name));
        let _ = writeln!(
            c,
            "{}: {} built-in material(s) of clevrtex's catalogue, {} user material(s) from `--materials`, over {} sample(s).\n",
            code(v),
            builtin.len(),
            mine.len(),
            layouts.samples
        );
        if !builtin.is_empty() {
            let names: Vec<String> = builtin
                .iter()
                .map(|(n, k)| format!("{} ({k})", code(n)))
                .collect();
            let _ = writeln!(c, "- built-in: {}\n", names.join(", "));
        }
        if !mine.is_empty() {
            c += "| user material | file | node group | textures | xxh3 | samples |\n|---|---|---|---|---|---|\n";
            for (name, k) in &mine {
                let u = user[name];
                let _ = writeln!(
                    c,
                    "| {} | {} | {} | {} | {} | {k} |",
                    code(name),
                    code(&u.file),
                    u.group.as_deref().map(code).unwrap_or_else(|| "-".into()),
                    u.textures.len(),
                    code(&u.xxh3)
                );
            }
            c += "\n";
        }
    }
    if !any {
        c += "No finished run's sample could be read yet.\n\n";
    }
    c
}

/// Whether every material the samples name is a user material (`Some(true)`), none is
/// (`Some(false)`), or some are (`None`).
pub(crate) fn all_user(variants: &BTreeMap<String, (Vec<&Manifest>, &Layouts)>) -> Option<bool> {
    let (mut user, mut builtin) = (false, false);
    for (manifests, layouts) in variants.values() {
        let names: BTreeSet<&String> = manifests
            .iter()
            .flat_map(|m| m.user_materials.keys())
            .collect();
        for m in layouts.materials.keys() {
            if names.contains(m) {
                user = true;
            } else {
                builtin = true;
            }
        }
    }
    match (user, builtin) {
        (true, false) => Some(true),
        (true, true) => None,
        _ => Some(false),
    }
}

/// The "Identity" section: the suite, the tool's versions and commits, and each variant's
/// layout fingerprint.
pub(crate) fn identity_section(
    suites: &BTreeSet<String>,
    variants: &BTreeMap<String, (Vec<&Manifest>, &Layouts)>,
) -> String {
    let mut c = String::from("### Identity\n\n");
    let suite = if suites.is_empty() {
        "none (variants made one by one)".to_string()
    } else {
        suites
            .iter()
            .map(|s| code(s))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let _ = writeln!(c, "- **Suite**: {suite}");
    let tools: BTreeSet<String> = variants
        .values()
        .flat_map(|(ms, _)| ms.iter().map(|m| tool_of(m)))
        .collect();
    let tools: Vec<String> = tools.iter().map(|t| code(t)).collect();
    let _ = writeln!(c, "- **clevrtex**: {}", tools.join(", "));
    c += "- **Layout fingerprints** (xxh3 over every sample's stem and metadata, provenance \
          fields left out, in index order; `clevrtex verify DIR --against OTHER` compares two \
          datasets image by image):\n";
    for (v, (_, l)) in variants {
        if l.fingerprint.is_empty() {
            let _ = writeln!(c, "  - {}: none yet (no sample's metadata read)", code(v));
        } else {
            let _ = writeln!(
                c,
                "  - {}: {} over {} sample(s){}",
                code(v),
                code(&l.fingerprint),
                l.samples,
                if l.unread > 0 {
                    format!(" ({} listed but not read)", l.unread)
                } else {
                    String::new()
                }
            );
        }
    }
    c += "\n";
    c
}

/// The BibTeX entry of the tool at `version`, with the repository and the year of its release
/// from `CITATION.cff`.
pub(crate) fn tool_bibtex(version: &str) -> Vec<String> {
    let url = citation_field("repository-code").unwrap_or("");
    let year = citation_field("date-released")
        .and_then(|d| d.get(..4))
        .unwrap_or("");
    vec![
        "@software{clevrtex_tool,".into(),
        "  title   = {clevrtex: texture-rich synthetic benchmarks for unsupervised multi-object segmentation},".into(),
        "  author  = {{The clevrtex contributors}},".into(),
        format!("  version = {{{version}}},"),
        format!("  year    = {{{year}}},"),
        format!("  url     = {{{url}}},"),
        "  note    = {See CITATION.cff of the clevrtex repository}".into(),
        "}".into(),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_citation_names_the_repository_a_year_and_this_version() {
        let bib = tool_bibtex("0.1.0").join("\n");
        let url = citation_field("repository-code").unwrap();
        assert!(url.starts_with("https://"), "{url}");
        assert!(bib.contains(&format!("url     = {{{url}}}")), "{bib}");
        let year = citation_field("date-released").unwrap();
        assert!(
            year.len() == 10 && bib.contains(&format!("year    = {{{}}}", &year[..4])),
            "{bib}"
        );
        assert_eq!(citation_field("version"), Some(env!("CARGO_PKG_VERSION")));
    }
}
