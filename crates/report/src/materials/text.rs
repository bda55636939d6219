//! What `clevrtex materials` prints, as text (the command prints it): the catalogue's list
//! ([`list_lines`]), the results of `check` ([`check_text`]), `stats` ([`stats_text`]) and
//! `cost` ([`cost_text`]), and the note on CLEVR base materials left out ([`clevr_base_note`]).

use std::fmt::Write;

use clevrtex_materials::Catalogue;
use clevrtex_render::material_renders::Outcome;

use super::cost::Cost;
use super::stats::Distinctness;

/// `materials list`: a header, then one line per material.
pub fn list_lines(cat: &Catalogue) -> impl Iterator<Item = String> + '_ {
    let header = format!(
        "{:<26} {:<10} {:<9} description",
        "name", "set", "displaces"
    );
    std::iter::once(header).chain(cat.iter().map(|m| {
        let d = if m.displaces { "yes" } else { "no" };
        format!("{:<26} {:<10} {:<9} {}", m.name, m.set, d, m.description)
    }))
}

/// `materials check`: a line per material (`ok` or `FAILED` with the message and traceback),
/// and how many failed.
pub fn check_text(names: &[&str], outcomes: &[Outcome]) -> (String, usize) {
    let (mut out, mut failed) = (String::new(), 0);
    for (name, outcome) in names.iter().zip(outcomes) {
        match outcome {
            Outcome::Done(reply) if reply.measures.get("pink").copied().unwrap_or(0.0) == 0.0 => {
                let _ = writeln!(out, "ok     {name}");
            }
            Outcome::Done(_) => {
                failed += 1;
                let _ = writeln!(out, "FAILED {name}: pink (missing texture) pixels");
            }
            Outcome::Failed { message, traceback } => {
                failed += 1;
                let _ = writeln!(out, "FAILED {name}: {message}");
                if !traceback.is_empty() {
                    let _ = writeln!(out, "{traceback}");
                }
            }
        }
    }
    (out, failed)
}

/// `materials stats`: the table of nearest neighbours and the yardstick's line, and the pairs
/// closer than the median self-distance.
pub fn stats_text(names: &[&str], d: &Distinctness) -> (String, Vec<String>) {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{:<24} {:<24} {:>8} {:>8}",
        "material", "nearest", "distance", "self"
    );
    for (i, (j, dist)) in d.nearest.iter().enumerate() {
        let _ = writeln!(
            out,
            "{:<24} {:<24} {:>8.3} {:>8.3}",
            names[i], names[*j], dist, d.self_distance[i]
        );
    }
    let near: Vec<String> = d
        .near
        .iter()
        .map(|(i, j, dist)| format!("`{}` ~ `{}` ({dist:.3})", names[*i], names[*j]))
        .collect();
    let _ = writeln!(
        out,
        "self-distance (same material, random 0.37 vs 0.81): median {:.3}, max {:.3}; smallest distance between different materials {:.3}",
        d.threshold, d.max_self, d.min_inter
    );
    (out, near)
}

/// `materials cost`: seconds and cost relative to `plain` per material, then the median, the
/// maximum and the outliers.
pub fn cost_text(names: &[&str], times: &[f64], c: &Cost) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "{:<24} {:>8} {:>8}", "material", "seconds", "x plain");
    for ((name, t), x) in names.iter().zip(times).zip(&c.relative) {
        let _ = writeln!(out, "{name:<24} {t:>8.2} {x:>8.2}");
    }
    let _ = writeln!(
        out,
        "median {:.2}x plain, max {:.2}x plain; over 3x the median: {}",
        c.median,
        c.max,
        if c.outliers.is_empty() {
            "none".to_string()
        } else {
            c.outliers.join(", ")
        }
    );
    out
}

/// The one line saying which `.blend` files were left out as CLEVR base materials, if any.
pub fn clevr_base_note(cat: &Catalogue) -> Option<String> {
    let base = cat.clevr_base();
    if base.is_empty() {
        return None;
    }
    let quoted = |items: Vec<String>| items.join(", ");
    let files = quoted(
        base.iter()
            .map(|b| format!("`{}`", b.file.display()))
            .collect(),
    );
    let builtins = quoted(base.iter().map(|b| format!("`{}`", b.builtin)).collect());
    Some(format!(
        "note: {files}: the public generator's CLEVR base material{s}, which its textured variants never draw; left out of set `user` (the built-in {builtins} play{v} {their} part{s})",
        s = if base.len() == 1 { "" } else { "s" },
        v = if base.len() == 1 { "s" } else { "" },
        their = if base.len() == 1 { "its" } else { "their" },
    ))
}
