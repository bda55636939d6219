//! User materials (`--materials DIR`) on the commands that build and render scenes
//! (`sample`, `generate`, `render`, `bench render`): the argument, the catalogue they resolve
//! names in and `--material-set`. Their checks before a run renders, the copies Blender reads
//! and what a run records of them are the render crate's (`clevrtex_render::user_materials`).

use std::path::{Path, PathBuf};

use anyhow::bail;
use clevrtex_materials::{Catalogue, Set};

/// `--materials DIR`, shared by the commands that build scenes.
#[derive(Debug, Clone, clap::Args)]
pub struct MaterialsArg {
    /// A folder of user materials, added to the built-in catalogue as set `user`: ClevrTex
    /// `.blend` files (one node group each, textures relative to the file, as the public
    /// generator's `data/materials`) and material JSON files. Configs may then name them
    /// (`"include": ["name"]`, `"sets": ["user"]`); see docs/materials.md.
    #[arg(long, value_name = "DIR")]
    pub(crate) materials: Option<PathBuf>,
}

impl MaterialsArg {
    /// The built-in catalogue plus the folder, if given.
    pub(crate) fn catalogue(&self) -> anyhow::Result<Catalogue> {
        load(self.materials.as_deref())
    }
}

/// The built-in catalogue plus the folder `dir`, if given; the public generator's CLEVR base
/// materials found in it (`Rubber.blend`, `MyMetal.blend`, `TabulaRasa.blend`:
/// [`clevrtex_materials::CLEVR_BASE`]) are left out of set `user`, said in one line on stderr.
pub(crate) fn load(dir: Option<&Path>) -> anyhow::Result<Catalogue> {
    let cat = clevrtex_report::materials::load(dir)?;
    if let Some(line) = clevr_base_note(&cat) {
        eprintln!("{line}");
    }
    Ok(cat)
}

/// The one line saying which `.blend` files were left out as CLEVR base materials, if any.
fn clevr_base_note(cat: &Catalogue) -> Option<String> {
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

/// `--material-set SET` (`explicit`) on `config`, or `user` by default when `default_user`
/// (`--materials DIR` with a built-in `--variant`): the variant's textured materials drawn
/// from that set ([`clevrtex_scene::Config::use_material_set`]). An explicit set that
/// replaces nothing (`clevr`) is an error; the default then changes nothing.
pub(crate) fn apply_material_set(
    config: &mut clevrtex_scene::Config,
    cat: &Catalogue,
    explicit: Option<&str>,
    default_user: bool,
) -> anyhow::Result<()> {
    let Some(set) = explicit.or(default_user.then_some("user")) else {
        return Ok(());
    };
    let changed = config.use_material_set(cat, parse_set(set)?)?;
    if !changed && explicit.is_some() {
        bail!(
            "variant `{}` draws no textured material for `--material-set {set}` to replace\nhint: use a variant with textured materials (full, camo, vbg, pbg, grassbg, outd), or a config naming the materials (`--config`)",
            config.name
        );
    }
    Ok(())
}

/// `--material-set SET`: the set as a [`Set`] (`user`, `main`, `ood`).
pub(crate) fn parse_set(name: &str) -> anyhow::Result<Set> {
    match Set::from_name(name) {
        Some(s @ (Set::Main | Set::Ood | Set::User)) => Ok(s),
        _ => bail!(
            "unknown material set `{name}` for `--material-set`\nhint: use `user` (with `--materials DIR`), `main` or `ood`"
        ),
    }
}
