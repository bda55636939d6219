//! The commands `verify` offers to rerun (a manifest's command with `--out` set to the folder
//! verified, its shard, only flags known safe) and how it prints them and index ranges.

use std::path::Path;

/// `command` with the value of its `--out` replaced by `out` (the folder that was verified,
/// wherever the run wrote it first).
pub(super) fn with_out(command: &[String], out: &Path) -> Vec<String> {
    let out = out.display().to_string();
    let mut v = Vec::with_capacity(command.len());
    let mut it = command.iter();
    let mut replaced = false;
    while let Some(a) = it.next() {
        if a == "--out" {
            v.push(a.clone());
            if it.next().is_some() {
                v.push(out.clone());
                replaced = true;
            }
        } else if a.starts_with("--out=") {
            v.push(format!("--out={out}"));
            replaced = true;
        } else {
            v.push(a.clone());
        }
    }
    if !replaced {
        v.push("--out".into());
        v.push(out);
    }
    v
}

/// Flags of `clevrtex generate` a rerun command offered by `verify` may carry, with whether
/// each takes a value. None of them names a program (`--blender` is left out: the rerun
/// uses the user's own Blender); `--out` is set to the folder verified.
const RERUN_FLAGS: [(&str, bool); 29] = [
    ("--variant", true),
    ("--suite", true),
    ("--scale", true),
    ("--layout-stream", true),
    ("--material-set", true),
    ("--materials", true),
    ("--config", true),
    ("-n", true),
    ("--count", true),
    ("--seed", true),
    ("--start", true),
    ("--total", true),
    ("--shard", true),
    ("--shard-count", true),
    ("--width", true),
    ("--height", true),
    ("--samples", true),
    ("--shadow-samples", true),
    ("--quality", true),
    ("--max-attempts", true),
    ("--passes", true),
    ("--workers", true),
    ("--device", true),
    ("--threads", true),
    ("--timeout", true),
    ("--startup-timeout", true),
    ("--retries", true),
    ("--keep-exr", false),
    ("--out", true),
];

/// Whether a flag's value from a manifest may be offered: plain characters of numbers,
/// names, lists and paths, not empty, not a flag.
pub(super) fn safe_value(v: &str) -> bool {
    !v.is_empty()
        && !v.starts_with('-')
        && v.chars()
            .all(|c| c.is_ascii_alphanumeric() || "._,/:+@%=-".contains(c))
}

/// The rerun command of a manifest's `command` (untrusted): `clevrtex generate` with only the
/// flags of [`RERUN_FLAGS`] whose values are [`safe_value`]s, `--out` set to `out`; `None`
/// when it is not a `generate` command.
pub(crate) fn rerun_command(command: &[String], out: &Path) -> Option<Vec<String>> {
    if command.get(1).map(String::as_str) != Some("generate") {
        return None;
    }
    let mut v = vec!["clevrtex".to_string(), "generate".to_string()];
    let mut it = command.iter().skip(2);
    while let Some(a) = it.next() {
        let (flag, inline) = match a.split_once('=') {
            Some((f, val)) if f.starts_with("--") => (f, Some(val)),
            _ => (a.as_str(), None),
        };
        let Some(&(_, takes)) = RERUN_FLAGS.iter().find(|(f, _)| *f == flag) else {
            continue;
        };
        if !takes {
            if inline.is_none() {
                v.push(flag.to_string());
            }
            continue;
        }
        let value = match inline {
            Some(val) => Some(val.to_string()),
            None => it.next().cloned(),
        };
        if let Some(val) = value.filter(|val| safe_value(val)) {
            v.push(flag.to_string());
            v.push(val);
        }
    }
    Some(with_out(&v, out))
}

/// `command` with `--shard k/n` (replacing its `--shard` and `--shard-count`).
pub(super) fn with_shard(command: &[String], k: u64, n: u64) -> Vec<String> {
    let mut v = without_shard(command);
    v.push("--shard".into());
    v.push(format!("{k}/{n}"));
    v
}

/// `command` without its `--shard` and `--shard-count`: every shard's indices (a suite's
/// rerun, whose shards are the suite's, not a variant's).
pub(crate) fn without_shard(command: &[String]) -> Vec<String> {
    let mut v = Vec::with_capacity(command.len());
    let mut it = command.iter();
    while let Some(a) = it.next() {
        if a == "--shard" || a == "--shard-count" {
            it.next();
        } else if !(a.starts_with("--shard=") || a.starts_with("--shard-count=")) {
            v.push(a.clone());
        }
    }
    v
}

/// Indices (sorted) as compact ranges for a message: `0, 3..=5, 9`; at most 20 ranges shown.
pub fn index_ranges(v: &[u64]) -> String {
    let mut out = Vec::new();
    let mut i = 0;
    while i < v.len() {
        let mut j = i;
        while j + 1 < v.len() && v[j + 1] == v[j] + 1 {
            j += 1;
        }
        out.push(if i == j {
            v[i].to_string()
        } else {
            format!("{}..={}", v[i], v[j])
        });
        i = j + 1;
    }
    let shown = out.len().min(20);
    let mut s = out[..shown].join(", ");
    if out.len() > shown {
        s += &format!(", ... ({} more ranges)", out.len() - shown);
    }
    s
}

/// A command line (a manifest's, untrusted) as a shell would read it back: control characters
/// escaped ([`clevrtex_scene::text::printable`]: no escape sequence reaches the terminal), each
/// word that is not plainly safe single-quoted, so a printed rerun command runs only that
/// command.
pub fn shell_words(args: &[String]) -> String {
    args.iter()
        .map(|a| clevrtex_scene::text::printable(a).into_owned())
        .map(|a| {
            if !a.is_empty()
                && a.chars()
                    .all(|c| c.is_ascii_alphanumeric() || "-_./=:,+@%".contains(c))
            {
                a.clone()
            } else {
                format!("'{}'", a.replace('\'', "'\\''"))
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}
