//! A benchmark suite's folder (`generate --suite`): `OUT/SUITE.json` records the suite's plan
//! ([`clevrtex_scene::suite::SuitePlan`]: each variant's total, seed and layout stream, fixed
//! before the first image), so every shard and rerun makes the same suite, and `verify` checks
//! the folder as a whole ([`check`]). The file is untrusted when read: capped, no link
//! followed out of the folder, its values checked against the suite table.

use std::path::{Path, PathBuf};

use clevrtex_scene::suite::SuitePlan;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::verify::VariantReport;

/// The suite file's name, in the `--out` folder.
pub const SUITE_FILE: &str = "SUITE.json";
/// Value of the file's `format`.
const FORMAT: &str = "clevrtex-suite";

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct SuiteFile {
    format: String,
    version: u32,
    plan: SuitePlan,
}

/// The suite plan recorded in `out` (`None`: no suite file). `Err`: one line, the file named.
pub fn read(out: &Path) -> std::result::Result<Option<SuitePlan>, String> {
    let path = out.join(SUITE_FILE);
    if std::fs::symlink_metadata(&path).is_err() {
        return Ok(None);
    }
    let root = crate::dataset::files::root(out).map_err(|e| e.to_string())?;
    let bytes = crate::dataset::files::read(&root, &path, 1 << 20)?;
    let file: SuiteFile = serde_json::from_slice(&bytes)
        .map_err(|e| format!("`{}` is not a suite file: {e}", path.display()))?;
    if file.format != FORMAT || file.version != 1 {
        return Err(format!(
            "`{}` is not a version 1 clevrtex suite file",
            path.display()
        ));
    }
    // The recorded plan must be one the suite table makes: nothing in it sizes anything else.
    let known = clevrtex_scene::suite::find(&file.plan.suite)
        .and_then(|s| s.plan(file.plan.scale, file.plan.seed))
        .map_err(|e| format!("`{}`: {}", path.display(), e.lines().next().unwrap_or("")))?;
    if known != file.plan {
        return Err(format!(
            "`{}` records variants, totals or streams that suite `{}` at scale {} does not make",
            path.display(),
            clevrtex_scene::text::printable(&file.plan.suite),
            file.plan.scale
        ));
    }
    Ok(Some(file.plan))
}

/// Refuse, before anything is written, to make `plan` into `out` when the folder records
/// another suite, scale or seed, or holds a variant folder (`clevrtex_<v>`) of no variant of
/// the suite.
pub fn check_folder(out: &Path, plan: &SuitePlan) -> Result<()> {
    let describe = |p: &SuitePlan| {
        format!(
            "suite `{}` at scale {} with seed {}",
            p.suite, p.scale, p.seed
        )
    };
    match read(out) {
        Ok(Some(found)) if &found != plan => {
            return Err(Error::Refused(format!(
                "`{}` holds {}, not {}\nhint: rerun with `--suite {} --scale {} --seed {}` to resume it, or pass another `--out` for this suite",
                out.join(SUITE_FILE).display(),
                describe(&found),
                describe(plan),
                found.suite,
                found.scale,
                found.seed
            )))
        }
        Err(e) => {
            return Err(Error::Refused(format!(
                "{e}\nhint: pass another `--out` for the suite, or move the file away"
            )))
        }
        _ => {}
    }
    let Ok(entries) = std::fs::read_dir(out) else {
        return Ok(());
    };
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let Some(variant) = name.strip_prefix("clevrtex_") else {
            continue;
        };
        if !plan.variants.iter().any(|v| v.variant == variant) {
            return Err(Error::Refused(format!(
                "`{}` holds `{}`, a variant that suite `{}` does not have (it has {})\nhint: pass another `--out` for the suite, or move that folder out",
                out.display(),
                clevrtex_scene::text::printable(&name),
                plan.suite,
                plan.variants
                    .iter()
                    .map(|v| v.variant.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        }
    }
    Ok(())
}

/// Record `plan` in `out` (made if needed), atomically; a file with the same plan is kept.
pub fn write(out: &Path, plan: &SuitePlan) -> Result<()> {
    if matches!(read(out), Ok(Some(found)) if &found == plan) {
        return Ok(());
    }
    std::fs::create_dir_all(out).map_err(|e| {
        Error::io(
            "cannot make",
            out,
            e,
            "pass an `--out` folder that can be made",
        )
    })?;
    let path = out.join(SUITE_FILE);
    let file = SuiteFile {
        format: FORMAT.into(),
        version: 1,
        plan: plan.clone(),
    };
    let text = serde_json::to_string_pretty(&file).expect("suite serialises") + "\n";
    crate::atomic::write(&path, text.as_bytes()).map_err(|e| Error::write(&path, e))
}

/// The suite `plan` checked as a whole against `verify`'s reports of its folder: one line per
/// variant that is incomplete (no folder, planned for another total, missing or broken
/// samples) or foreign to the suite; empty when the suite is whole.
pub fn check(plan: &SuitePlan, reports: &[VariantReport]) -> Vec<String> {
    let mut lines = Vec::new();
    for v in &plan.variants {
        let Some(r) = reports.iter().find(|r| r.variant == v.variant) else {
            lines.push(format!(
                "`{}`: no folder (0 of {} images)",
                v.variant, v.total
            ));
            continue;
        };
        if r.expected != v.total {
            lines.push(format!(
                "`{}`: its runs plan {} images, the suite {}",
                v.variant, r.expected, v.total
            ));
        } else if !r.is_whole() || r.ok != v.total {
            lines.push(format!(
                "`{}`: {} of {} images whole",
                v.variant, r.ok, v.total
            ));
        }
    }
    for r in reports {
        if !plan.variants.iter().any(|v| v.variant == r.variant) {
            lines.push(format!(
                "`{}`: not a variant of suite `{}`",
                clevrtex_scene::text::printable(&r.variant),
                plan.suite
            ));
        }
    }
    lines
}

/// `verify`'s check of the suite in `dirs` (their `SUITE.json`, which must agree) against its
/// `reports`: whether the suite is whole (`true` without a suite, or with `one_variant`,
/// `--variant`) and the lines to print.
pub fn verify_dirs(
    dirs: &[PathBuf],
    reports: &[VariantReport],
    one_variant: bool,
) -> std::result::Result<(bool, String), String> {
    let mut plan: Option<SuitePlan> = None;
    for d in dirs {
        match (&plan, read(d)?) {
            (Some(p), Some(f)) if p != &f => return Err(format!(
                "the folders hold different suites (`{}` and `{}` at scales {} and {})\nhint: verify each suite's folders apart",
                p.suite, f.suite, p.scale, f.scale
            )),
            (None, Some(f)) => plan = Some(f),
            _ => {}
        }
    }
    let Some(plan) = plan.filter(|_| !one_variant) else {
        return Ok((true, String::new()));
    };
    let lines = check(&plan, reports);
    let (suite, scale) = (&plan.suite, plan.scale);
    if lines.is_empty() {
        let text = format!(
            "suite `{suite}` at scale {scale}: whole ({} variants, {} images)\n",
            plan.variants.len(),
            plan.images()
        );
        return Ok((true, text));
    }
    let mut text = format!(
        "suite `{suite}` at scale {scale}: incomplete variants ({} of {}):\n",
        lines.len(),
        plan.variants.len()
    );
    for l in &lines {
        text += &format!("  {l}\n");
    }
    text += &format!(
        "  to repair: rerun `clevrtex generate --suite {suite} --scale {scale} --seed {} --out DIR` (complete samples are skipped)\n",
        plan.seed
    );
    Ok((false, text))
}
