//! User materials (`--materials DIR`) on the commands that build and render scenes
//! (`sample`, `generate`, `render`, `bench render`): the argument and the catalogue they
//! resolve names in (`--material-set` is `Config::apply_material_set`). Their checks before a run renders, the copies Blender reads
//! and what a run records of them are the render crate's (`clevrtex_render::user_materials`).

use std::path::{Path, PathBuf};

use clevrtex_materials::Catalogue;

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
    if let Some(line) = clevrtex_report::materials::text::clevr_base_note(&cat) {
        eprintln!("{line}");
    }
    Ok(cat)
}
