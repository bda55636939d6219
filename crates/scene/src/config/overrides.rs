//! The command line's changes to a variant config (`sample`, `generate`): `--material-set`
//! ([`Config::apply_material_set`]), `--layout-stream` and the render settings
//! ([`Overrides`]), each number checked as a flag ([`within`]).

use clevrtex_materials::{Catalogue, Set};

use super::Config;
use crate::scene_file::{Pass, MAX_IMAGE_SIDE, MAX_SAMPLES};

/// `v`, which must not be 0 (given as `flag`).
pub fn positive(flag: &str, v: u32) -> Result<u32, String> {
    if v == 0 {
        return Err(format!(
            "`{flag} 0` is not allowed\nhint: pass a positive number"
        ));
    }
    Ok(v)
}

/// `v`, which must be 1 to `max` (given as `flag`).
pub fn within(flag: &str, v: u32, max: u32) -> Result<u32, String> {
    if v > max {
        return Err(format!(
            "`{flag} {v}` is more than the {max} allowed\nhint: pass 1 to {max}"
        ));
    }
    positive(flag, v)
}

/// `--material-set SET`: the set as a [`Set`] (`user`, `main`, `ood`).
pub fn parse_set(name: &str) -> Result<Set, String> {
    match Set::from_name(name) {
        Some(s @ (Set::Main | Set::Ood | Set::User)) => Ok(s),
        _ => Err(format!(
            "unknown material set `{name}` for `--material-set`\nhint: use `user` (with `--materials DIR`), `main` or `ood`"
        )),
    }
}

/// What the command line changes of a config's render settings and layouts.
#[derive(Debug, Clone, Default)]
pub struct Overrides {
    /// `--layout-stream`.
    pub layout_stream: Option<String>,
    /// `--width`.
    pub width: Option<u32>,
    /// `--height`.
    pub height: Option<u32>,
    /// `--quality`, applied before `--samples`.
    pub quality: Option<crate::quality::Quality>,
    /// `--samples`.
    pub samples: Option<u32>,
    /// `--shadow-samples`.
    pub shadow_samples: Option<u32>,
}

impl Config {
    /// `--material-set SET` (`explicit`), or `user` by default when `default_user`
    /// (`--materials DIR` with a built-in `--variant`): the variant's textured materials drawn
    /// from that set ([`Config::use_material_set`]). An explicit set that replaces nothing
    /// (`clevr`) is an error; the default then changes nothing.
    pub fn apply_material_set(
        &mut self,
        cat: &Catalogue,
        explicit: Option<&str>,
        default_user: bool,
    ) -> Result<(), String> {
        let Some(set) = explicit.or(default_user.then_some("user")) else {
            return Ok(());
        };
        let changed = self
            .use_material_set(cat, parse_set(set)?)
            .map_err(|e| e.to_string())?;
        if !changed && explicit.is_some() {
            return Err(format!(
                "variant `{}` draws no textured material for `--material-set {set}` to replace\nhint: use a variant with textured materials (full, camo, vbg, pbg, grassbg, outd), or a config naming the materials (`--config`)",
                self.name
            ));
        }
        Ok(())
    }

    /// The overrides `o` applied (`--layout-stream` first, then the render settings), each
    /// number checked: 1 to [`MAX_IMAGE_SIDE`] for a side, 1 to [`MAX_SAMPLES`] for samples.
    pub fn apply_overrides(&mut self, o: &Overrides) -> Result<(), String> {
        if let Some(stream) = &o.layout_stream {
            self.set_layout_stream(stream)?;
        }
        let r = &mut self.base.render;
        if let Some(w) = o.width {
            r.width = within("--width", w, MAX_IMAGE_SIDE)?;
        }
        if let Some(h) = o.height {
            r.height = within("--height", h, MAX_IMAGE_SIDE)?;
        }
        if let Some(q) = o.quality {
            q.apply(r);
        }
        if let Some(s) = o.samples {
            r.samples = within("--samples", s, MAX_SAMPLES)?;
        }
        if let Some(s) = o.shadow_samples {
            r.shadow_samples = Some(within("--shadow-samples", s, MAX_SAMPLES)?);
        }
        Ok(())
    }
}

/// The config a `generate` run used, rebuilt from what its manifest records (`verify`
/// re-derives each sample's layout from it): the built-in `variant` with the run's material
/// set (none, `main` or `ood`, each tried as `--material-set` applies it), `--layout-stream`,
/// render settings and passes, as `generate` applies them; the one whose
/// [`Config::content_hash`] is `config_hash`. `Err` says why none is: a config given with
/// `--config`, user materials (`--materials`), a variant that is not built in, or another
/// version's configs.
pub fn recorded(
    variant: &str,
    layout_stream: Option<&str>,
    render: &crate::scene_file::RenderSettings,
    passes: &[Pass],
    config_hash: &str,
) -> Result<Config, String> {
    let base = Config::builtin(variant).map_err(|e| {
        format!(
            "variant `{}` is not built in ({})",
            crate::text::printable(variant),
            e.problem
        )
    })?;
    for set in [None, Some(Set::Main), Some(Set::Ood)] {
        let mut c = base.clone();
        if let Some(set) = set {
            if !c.use_material_set(super::catalogue(), set).unwrap_or(false) {
                continue;
            }
        }
        if let Some(stream) = layout_stream {
            c.set_layout_stream(stream)?;
        }
        c.base.render = render.clone();
        c.base.passes = passes.to_vec();
        if c.content_hash() == config_hash {
            return Ok(c);
        }
    }
    Err(format!(
        "no built-in config of `{}` with the run's settings hashes as its `config_hash` {} (a config given with `--config`, user materials, or another version's configs)",
        crate::text::printable(variant),
        crate::text::printable(config_hash)
    ))
}

/// `--passes`: the passes named, each once, in the pass table's order.
pub fn parse_passes(list: &[String]) -> Result<Vec<Pass>, String> {
    let mut out = Vec::new();
    let all = || Pass::ALL.map(Pass::name).join(", ");
    for name in list.iter().map(|s| s.trim()).filter(|s| !s.is_empty()) {
        match Pass::from_name(name) {
            Some(p) if !out.contains(&p) => out.push(p),
            Some(_) => {}
            None => {
                let all = all();
                return Err(format!(
                    "unknown pass `{name}`\nhint: use a comma-separated list of {all}"
                ));
            }
        }
    }
    if out.is_empty() {
        let all = all();
        return Err(format!(
            "`--passes` is empty\nhint: name at least one of {all}"
        ));
    }
    out.sort();
    Ok(out)
}

/// `--start + -n` (`end`) within the dataset cap: every index below
/// [`crate::bounds::INDEX_END`], so `verify` never refuses what a run made.
pub fn check_index_end(start: u64, end: u64) -> Result<(), String> {
    let cap = crate::bounds::INDEX_END;
    if end > cap {
        return Err(format!(
            "`--start {start}` plus `-n {}` reaches index {}, past the dataset cap of {cap} images\nhint: keep `--start + -n` at most {cap}",
            end - start,
            end - 1
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flags_are_checked_and_applied_in_order() {
        assert_eq!(within("--width", 320, 4096), Ok(320));
        assert!(within("--width", 5000, 4096)
            .unwrap_err()
            .contains("`--width 5000`"));
        assert!(within("--samples", 0, 10)
            .unwrap_err()
            .contains("`--samples 0`"));
        assert_eq!(
            parse_passes(&["mask".into(), " rgb".into(), "mask".into()]).unwrap(),
            vec![Pass::Rgb, Pass::Mask]
        );
        assert!(parse_passes(&["nope".into()])
            .unwrap_err()
            .contains("unknown pass `nope`"));
        assert!(parse_passes(&[" ".into()])
            .unwrap_err()
            .contains("`--passes` is empty"));
        assert!(check_index_end(0, crate::bounds::INDEX_END).is_ok());
        assert!(check_index_end(1, crate::bounds::INDEX_END + 1).is_err());
        assert!(parse_set("clevr").is_err());

        let cat = Catalogue::builtin().unwrap();
        let mut config = Config::builtin_in("full", &cat).unwrap();
        let o = Overrides {
            width: Some(64),
            samples: Some(3),
            quality: Some(crate::quality::Quality::Draft),
            ..Default::default()
        };
        config.apply_overrides(&o).unwrap();
        let r = &config.base.render;
        // `--samples` overrides the preset's samples, which come first.
        assert_eq!((r.width, r.samples), (64, 3));
        let bad = Overrides {
            height: Some(0),
            ..Default::default()
        };
        assert!(config
            .apply_overrides(&bad)
            .unwrap_err()
            .contains("`--height 0`"));
    }
}
