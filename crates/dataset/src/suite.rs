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
    let root = crate::dataset::files::root(out)
        .map_err(|e| format!("cannot read `{}`: {e}", path.display()))?;
    let bytes = crate::dataset::files::read(&root, &path, 1 << 20)
        .map_err(|why| format!("`{}` cannot be read: {why}", path.display()))?;
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

/// The suite's lock in its folder: held while the folder is checked and its plan written, so
/// of two suites started together into one folder only the first writes `SUITE.json`.
pub const SUITE_LOCK: &str = ".clevrtex-suite.lock";

/// Check `out` for `plan` ([`check_folder`]) and record the plan ([`write`]), both under the
/// suite's lock ([`SUITE_LOCK`], an exclusive `flock`): a second suite (another scale or seed)
/// started at the same time then finds the first's `SUITE.json` and is refused, nothing of it
/// written. The lock file is kept (as the range locks' guard).
pub fn claim(out: &Path, plan: &SuitePlan) -> Result<()> {
    // First without the lock: a folder refused outright gets nothing, not even the lock file.
    check_folder(out, plan)?;
    make_out(out)?;
    let lock_path = out.join(SUITE_LOCK);
    let lock = crate::run_lock::open_lock_file(&lock_path).map_err(Error::Refused)?;
    lock.lock().map_err(|e| {
        Error::io(
            "cannot lock",
            &lock_path,
            e,
            "pass a writable `--out` folder",
        )
    })?;
    check_folder(out, plan)?;
    // What a killed write of `SUITE.json` or the card left in the folder.
    crate::atomic::remove_stale_temps(out);
    write(out, plan)
}

/// Refuse a `generate` without `--suite` of `variant` into `out` when `out` is a suite's
/// folder (its `SUITE.json`, or a manifest of the variant that records a suite): the run would
/// rewrite a suite variant's manifest without its suite, or add a variant outside the plan.
pub fn refuse_plain_run(out: &Path, variant: &str) -> Result<()> {
    let rerun = |p: &SuitePlan| {
        format!(
            "clevrtex generate --suite {} --scale {} --seed {} --out {}",
            p.suite,
            p.scale,
            p.seed,
            crate::verify::shell_words(&[out.display().to_string()])
        )
    };
    let suite = match read(out) {
        Ok(Some(plan)) => Some((
            plan.suite.clone(),
            out.join(SUITE_FILE),
            format!("make or repair the suite with `{}` (its size flags as before)", rerun(&plan)),
        )),
        Err(e) => {
            return Err(Error::Refused(format!(
                "{e}: this may be a suite's folder, which only `generate --suite` writes into\nhint: pass another `--out`, or repair the suite with its `generate --suite` command"
            )))
        }
        Ok(None) => {
            let vdir = crate::layout::variant_dir(out, variant);
            let root = crate::dataset::files::root(&vdir).ok();
            let entries = root
                .as_ref()
                .and_then(|r| crate::dataset::files::list(r, &vdir).ok())
                .unwrap_or_default();
            entries.into_iter().find_map(|(name, path, _)| {
                if !crate::manifest::is_manifest_name(&name) {
                    return None;
                }
                let m = crate::manifest::Manifest::read(&path).ok()?;
                let suite = m.suite?;
                Some((
                    suite,
                    path,
                    "rerun that manifest's `generate --suite` command (its `command`)".to_string(),
                ))
            })
        }
    };
    match suite {
        Some((suite, path, what)) => Err(Error::Refused(format!(
            "`{}` records suite `{}`: a `generate` without `--suite` would write variant `{}` of the suite's folder outside the suite (its manifest without the suite)\nhint: {what}, or pass another `--out` for a run of one variant",
            path.display(),
            clevrtex_scene::text::printable(&suite),
            clevrtex_scene::text::printable(variant)
        ))),
        None => Ok(()),
    }
}

/// Make the suite's folder `out` (and its parents), or say which cannot be made.
fn make_out(out: &Path) -> Result<()> {
    std::fs::create_dir_all(out).map_err(|e| {
        Error::io(
            "cannot make",
            out,
            e,
            "pass an `--out` folder that can be made",
        )
    })
}

/// Record `plan` in `out` (made if needed), atomically; a file with the same plan is kept.
pub fn write(out: &Path, plan: &SuitePlan) -> Result<()> {
    if matches!(read(out), Ok(Some(found)) if &found == plan) {
        return Ok(());
    }
    make_out(out)?;
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
    if one_variant {
        return Ok((true, String::new()));
    }
    // What the manifests record: the suite their runs were made for, and the rerun command
    // of one (its size flags kept, `--out` the folder verified, no shard: the whole suite).
    let mut recorded: Option<(String, Option<Vec<String>>)> = None;
    for path in reports.iter().flat_map(|r| r.manifests.iter()) {
        let Ok(m) = crate::manifest::Manifest::read(path) else {
            continue;
        };
        let Some(suite) = m.suite.clone() else {
            continue;
        };
        let out = path
            .parent()
            .and_then(Path::parent)
            .unwrap_or(Path::new("."));
        let command = crate::verify::command::rerun_command(&m.command, out)
            .map(|c| crate::verify::command::without_shard(&c));
        if recorded.as_ref().is_none_or(|(_, c)| c.is_none()) {
            recorded = Some((suite, command));
        }
    }
    let Some(plan) = plan else {
        // No `SUITE.json`: a suite's folder with its plan gone is not whole (which variants
        // and totals it should hold is no longer known).
        let Some((suite, command)) = recorded else {
            return Ok((true, String::new()));
        };
        let mut text = format!(
            "suite `{}`: not whole: its runs' manifests record the suite, but no `{SUITE_FILE}` is in {}, so its variants and totals are not known\n",
            clevrtex_scene::text::printable(&suite),
            dirs.iter()
                .map(|d| format!("`{}`", d.display()))
                .collect::<Vec<_>>()
                .join(", ")
        );
        if let Ok(s) = clevrtex_scene::suite::find(&suite) {
            for (v, _) in s.variants {
                if !reports.iter().any(|r| r.variant == *v) {
                    text += &format!("  `{v}`: no folder\n");
                }
            }
        }
        if let Some(c) = command {
            text += &format!(
                "  to repair: rerun `{}` (it writes `{SUITE_FILE}` again; complete samples are skipped)\n",
                crate::verify::shell_words(&c)
            );
        }
        return Ok((false, text));
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
    // The runs' own command (their size flags kept) where a manifest records one.
    let command = match recorded.and_then(|(_, c)| c) {
        Some(c) => crate::verify::shell_words(&c),
        None => format!(
            "clevrtex generate --suite {suite} --scale {scale} --seed {} --out {}",
            plan.seed,
            crate::verify::shell_words(&[dirs
                .first()
                .map(|d| d.display().to_string())
                .unwrap_or_default()])
        ),
    };
    text += &format!("  to repair: rerun `{command}` (complete samples are skipped)\n");
    Ok((false, text))
}
