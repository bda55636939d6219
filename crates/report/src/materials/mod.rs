//! The library parts of `clevrtex materials`: which materials a batch works on ([`load`],
//! [`select`]), the contact sheet's cell cache and stitching ([`sheet`]), the distinctness
//! statistics of rendered tiles ([`stats`], also the CIELAB conversion the report uses), the
//! render cost table ([`cost`]) and the dataset figures of `materials measure` ([`figures`]
//! reads a dataset, [`regions`] computes the figures, [`measure_output`] writes them as
//! tables or JSON), the Blender batches of `check`, `stats` and `cost` ([`batches`], on
//! `crates/render/src/material_renders.rs`), the table of `parity` across Blenders
//! ([`parity`]); what the command prints of them ([`text`]).

use std::path::Path;

use anyhow::{bail, Context};
use clevrtex_materials::{Catalogue, Set};

pub mod batches;
pub mod cost;
pub mod figures;
pub mod measure_output;
pub mod parity;
pub mod regions;
pub mod sheet;
pub mod stats;
pub mod text;

/// The built-in catalogue plus the user directory, if any.
pub fn load(dir: Option<&Path>) -> anyhow::Result<Catalogue> {
    let mut cat = Catalogue::builtin().context("the built-in material catalogue is invalid")?;
    if let Some(dir) = dir {
        cat.add_user_dir(dir)?;
    }
    Ok(cat)
}

/// The materials a batch works on: `names` when given (each must be in `cat`), else those of
/// the set named `set` (main, ood, basic, background, user, or all).
pub fn select<'a>(
    cat: &'a Catalogue,
    set: &str,
    names: &'a [String],
) -> anyhow::Result<Vec<&'a str>> {
    if !names.is_empty() {
        for n in names {
            cat.require(n)?;
        }
        return Ok(names.iter().map(String::as_str).collect());
    }
    if set == "all" {
        return Ok(cat.iter().map(|m| m.name.as_str()).collect());
    }
    let Some(set) = Set::from_name(set) else {
        bail!(
            "unknown material set `{}`\nhint: use main, ood, basic, background, user or all",
            set
        );
    };
    Ok(cat.names(set))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn select_takes_names_or_a_set_and_refuses_unknown_ones() {
        let cat = load(None).unwrap();
        let none: Vec<String> = Vec::new();
        assert_eq!(
            select(&cat, "all", &none).unwrap().len(),
            cat.iter().count()
        );
        let basic = select(&cat, "basic", &none).unwrap();
        assert!(!basic.is_empty() && basic.len() < cat.iter().count());
        let names = vec!["plain".to_string()];
        assert_eq!(select(&cat, "ood", &names).unwrap(), vec!["plain"]);
        let e = select(&cat, "nope", &none).unwrap_err().to_string();
        assert!(e.contains("unknown material set `nope`"), "{e}");
        let bad = vec!["no_such_material".to_string()];
        assert!(select(&cat, "all", &bad).is_err());
    }
}
