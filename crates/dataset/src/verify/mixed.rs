//! One dataset, one set of settings: the runs of one variant folder (a dataset grown with
//! `--start`, its shards) must agree on what makes its images comparable: the seed, the
//! variant config (its hash), the render settings (image size, samples, ...), the passes and
//! the user materials. Runs that differ are named, pair by pair against the first run, unless
//! one of the two was told to mix on purpose (`generate --mix-settings`, recorded in its
//! manifest as `mixed_settings`).

use crate::manifest::Manifest;

use super::report::ReadManifest;

/// The most pairs named (the rest are counted).
const MAX_NAMED: usize = 20;

/// The user materials of `b` that `a` lacks or records with other contents, and the reverse,
/// one phrase each.
fn material_differences(a: &Manifest, b: &Manifest) -> Vec<String> {
    let p = |s: &str| clevrtex_scene::text::printable(s).into_owned();
    let mut d = Vec::new();
    let names: std::collections::BTreeSet<&String> = a
        .user_materials
        .keys()
        .chain(b.user_materials.keys())
        .collect();
    for name in names {
        match (a.user_materials.get(name), b.user_materials.get(name)) {
            (Some(x), Some(y)) if x.xxh3 != y.xxh3 => d.push(format!(
                "user material {} xxh3 {} vs {}",
                p(name),
                p(&x.xxh3),
                p(&y.xxh3)
            )),
            (Some(_), None) => d.push(format!("user material {} vs (none)", p(name))),
            (None, Some(_)) => d.push(format!("user material (none) vs {}", p(name))),
            _ => {}
        }
    }
    d
}

/// Every setting that differs between runs `a` and `b`, one phrase each.
pub fn run_differences(a: &Manifest, b: &Manifest) -> Vec<String> {
    let mut d = a.settings_differ(b);
    // The config hash covers the render settings: named only when they do not explain it.
    if a.config_hash != b.config_hash
        && !d
            .iter()
            .any(|x| x.contains("config") || x.starts_with("render "))
    {
        d.push(format!(
            "config_hash {} vs {}",
            clevrtex_scene::text::printable(&a.config_hash),
            clevrtex_scene::text::printable(&b.config_hash)
        ));
    }
    d.extend(material_differences(a, b));
    d
}

/// What the runs of one variant folder mixed: (problems, mixes made on purpose), one line per
/// run that differs from the first run (by indices, then shard).
pub(super) fn mixed_runs(manifests: &[ReadManifest]) -> (Vec<String>, Vec<String>) {
    let mut runs: Vec<&ReadManifest> = manifests.iter().collect();
    runs.sort_by(|x, y| {
        (x.1.start, x.1.end, x.1.shard, &x.0).cmp(&(y.1.start, y.1.end, y.1.shard, &y.0))
    });
    let (mut problems, mut on_purpose) = (Vec::new(), Vec::new());
    let Some(((first_path, first, _), rest)) = runs.split_first() else {
        return (problems, on_purpose);
    };
    let name = |p: &std::path::Path| {
        p.file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    };
    let mut unnamed = 0;
    for (path, m, _) in rest {
        // The shards of one run are compared where the run's shards are gathered.
        if (m.start, m.end, m.shard[1]) == (first.start, first.end, first.shard[1]) {
            continue;
        }
        let d = run_differences(first, m);
        if d.is_empty() {
            continue;
        }
        let line = format!(
            "runs `{}` (indices {}..{}) and `{}` (indices {}..{}) differ in settings: {}",
            name(first_path),
            first.start,
            first.end,
            name(path),
            m.start,
            m.end,
            d.join(", ")
        );
        if first.mixed_settings || m.mixed_settings {
            on_purpose.push(line);
        } else if problems.len() < MAX_NAMED {
            problems.push(line + "; one dataset has one set of settings\nhint: move the later run's samples (its manifest lists their files) into another `--out`, or remake them with the first run's settings (its `command`); to keep the mix on purpose, rerun the later run's command with `--mix-settings`");
        } else {
            unnamed += 1;
        }
    }
    if unnamed > 0 {
        problems.push(format!(
            "{unnamed} more run(s) differ in settings from `{}`",
            name(first_path)
        ));
    }
    (problems, on_purpose)
}
