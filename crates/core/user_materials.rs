//! User materials (`--materials DIR`) on the commands that build and render scenes
//! (`sample`, `generate`, `render`, `bench render`): the catalogue they resolve names in, the
//! checks of every user `.blend` before any image is rendered (one Blender worker inspects
//! each node group: [`check_before_run`]), and what the run records of them (its manifest's
//! `user_materials`, each sample's metadata).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

use anyhow::bail;
use clevrtex_dataset::manifest::UserMaterial;
use clevrtex_materials::{Catalogue, Set};
use clevrtex_render::RenderError;

use crate::blender_session::{command_error, BlenderSession, Settings};

/// Inputs of a ClevrTex node group that the instance drives (`blender_scripts/materials.py`
/// `DRIVEN_INPUTS`); any other input keeps the `.blend`'s default, as in the public generator.
const DRIVEN_INPUTS: [&str; 5] = [
    "Color",
    "Random",
    "Scale",
    "Displacement",
    "Displacement Strength",
];
/// Surface outputs, in the order the bridge tries them (`SURFACE_OUTPUTS`).
const SURFACE_OUTPUTS: [&str; 3] = ["Shader", "BSDF", "Surface"];
/// Time for one `inspect` request (loading a node group's data blocks, no pixels).
const INSPECT_TIMEOUT: Duration = Duration::from_secs(120);

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

/// Check every user material of `cat` that `used` names before a run renders anything, with
/// one Blender worker of `blender` that inspects each `.blend` node group: the group must
/// have a surface output, no input the instance cannot drive and no default for (a shader
/// input), and every image texture it reads must pass [`clevrtex_materials::texture`]'s
/// checks. Fixes each `.blend` to its group and checked textures in `cat` and returns what
/// the run's manifest records. No user material used: nothing started, empty map.
pub(crate) fn check_before_run(
    cat: &mut Catalogue,
    used: &BTreeSet<String>,
    blender: &Path,
    startup_timeout: Duration,
    interrupt: Arc<AtomicBool>,
) -> anyhow::Result<BTreeMap<String, UserMaterial>> {
    let user: Vec<String> = used
        .iter()
        .filter(|n| cat.get(n).is_some_and(|m| m.set == Set::User))
        .cloned()
        .collect();
    let blends: Vec<String> = user
        .iter()
        .filter(|n| cat.get(n).is_some_and(|m| m.recipe["kind"] == "blend"))
        .cloned()
        .collect();
    if !blends.is_empty() {
        let mut session = BlenderSession::new(Settings {
            blender: blender.to_path_buf(),
            materials_json: cat.resolved_json_for(blends.iter().map(String::as_str)),
            threads: 1,
            retries: 1,
            idle_timeout: None,
            interrupt,
            startup_timeout,
        })?;
        for name in &blends {
            let m = cat.require(name)?.clone();
            let path = PathBuf::from(m.recipe["path"].as_str().unwrap_or(""));
            let group = m.recipe["group"].as_str().map(String::from);
            let reply = session.request(|w| w.inspect(&path, group.as_deref(), INSPECT_TIMEOUT));
            let reply = match reply {
                Ok(r) => r,
                Err(RenderError::Bridge { message, .. }) => bail!(
                    "user material `{name}` (`{}`): {}\nhint: save a node group named after the file with a `Shader` (or `BSDF`, `Surface`) output in it, as the public generator's `data/materials` files have (docs/materials.md)",
                    m.file,
                    clevrtex_scene::text::printable(&message)
                ),
                Err(e) => return Err(command_error(e)),
            };
            check_group(name, &m.file, &reply)?;
            let mut refs = Vec::new();
            for img in &reply.images {
                if img.packed || img.source == "GENERATED" {
                    continue;
                }
                if img.source != "FILE" {
                    bail!(
                        "user material `{name}` (`{}`): texture `{}` is a {} image; only single image files are read\nhint: replace it with one PNG or JPEG file",
                        m.file,
                        clevrtex_scene::text::printable(&img.path),
                        clevrtex_scene::text::printable(&img.source.to_lowercase())
                    );
                }
                refs.push(img.path.clone());
            }
            cat.resolve_blend(name, &reply.group, &refs)?;
        }
        session.close();
    }
    Ok(user
        .iter()
        .filter_map(|n| cat.get(n))
        .map(|m| (m.name.clone(), manifest_entry(cat, m)))
        .collect())
}

/// The group's sockets against the convention.
fn check_group(
    name: &str,
    file: &str,
    reply: &clevrtex_render::InspectReply,
) -> anyhow::Result<()> {
    let is_shader = |t: &str| t == "SHADER" || t == "NodeSocketShader";
    let surface = reply
        .outputs
        .iter()
        .find(|s| SURFACE_OUTPUTS.contains(&s.name.as_str()));
    if !surface.is_some_and(|s| is_shader(&s.r#type)) {
        bail!(
            "user material `{name}` (`{file}`): node group `{}` has no shader output named `Shader`, `BSDF` or `Surface`\nhint: connect the group's shader to an output of that name",
            clevrtex_scene::text::printable(&reply.group)
        );
    }
    for s in &reply.inputs {
        if is_shader(&s.r#type) && !DRIVEN_INPUTS.contains(&s.name.as_str()) {
            bail!(
                "user material `{name}` (`{file}`): node group `{}` has input `{}` ({}), which the ClevrTex convention does not drive and which has no default\nhint: the convention's inputs are {}; remove the input or give it a value inside the group",
                clevrtex_scene::text::printable(&reply.group),
                clevrtex_scene::text::printable(&s.name),
                clevrtex_scene::text::printable(&s.r#type),
                DRIVEN_INPUTS.map(|i| format!("`{i}`")).join(", ")
            );
        }
    }
    Ok(())
}

/// What the manifest records of user material `m`: its file and textures relative to the
/// material folder (the folder's own location is not part of the dataset), group and hash.
fn manifest_entry(cat: &Catalogue, m: &clevrtex_materials::Material) -> UserMaterial {
    let root = cat.user_root(&m.name);
    let rel = |p: &str| {
        let p = Path::new(p);
        root.and_then(|r| p.strip_prefix(r).ok())
            .unwrap_or(p)
            .to_string_lossy()
            .into_owned()
    };
    let file = m.recipe["path"]
        .as_str()
        .map(rel)
        .unwrap_or_else(|| rel(&m.file));
    let images = m.recipe["images"].as_object().into_iter().flatten();
    let layers = m.recipe["layers"].as_array().into_iter().flatten();
    let mut textures: Vec<String> = images
        .filter_map(|(_, p)| p.as_str())
        .chain(layers.filter_map(|l| l["path"].as_str()))
        .map(rel)
        .collect();
    textures.sort();
    textures.dedup();
    UserMaterial {
        file,
        group: m.recipe["group"].as_str().map(String::from),
        textures,
        xxh3: m.hash.clone(),
    }
}

/// Name -> hash of the run's user materials, as each sample's metadata records them.
pub(crate) fn hashes(entries: &BTreeMap<String, UserMaterial>) -> BTreeMap<String, String> {
    entries
        .iter()
        .map(|(n, e)| (n.clone(), e.xxh3.clone()))
        .collect()
}

/// Every material a scene of `scenes` uses; an unknown one is an error naming the scene.
pub(crate) fn used_by_scenes<'a>(
    cat: &Catalogue,
    scenes: impl IntoIterator<Item = (&'a Path, &'a clevrtex_scene::SceneFile)>,
) -> anyhow::Result<BTreeSet<String>> {
    let mut used = BTreeSet::new();
    for (path, s) in scenes {
        for m in std::iter::once(&s.backdrop.material).chain(s.objects.iter().map(|o| &o.material))
        {
            if cat.get(&m.name).is_none() {
                bail!(
                    "scene file `{}` uses material `{}`, which is neither built in nor in `--materials`\nhint: pass the folder of user materials it was sampled with (`--materials DIR`)",
                    path.display(),
                    clevrtex_scene::text::printable(&m.name)
                );
            }
            used.insert(m.name.clone());
        }
    }
    Ok(used)
}
