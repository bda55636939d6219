//! User materials (`--materials DIR`) before a run renders: the checks of every file a user
//! material makes Blender read (one Blender worker inspects each `.blend`'s node group:
//! [`check_before_run`]), the run-private copies Blender reads instead ([`copies`]), and what
//! the run records of them (its manifest's `user_materials`, each sample's metadata).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

use clevrtex_dataset::manifest::UserMaterial;
use clevrtex_materials::texture::Expect;
use clevrtex_materials::{Catalogue, Set};
use serde_json::Value;

use crate::command_session::{BlenderSession, Settings};
use crate::error::{RenderError, Result};

/// Refuse with a message and hint, as the command prints it.
macro_rules! refuse {
    ($($t:tt)*) => {
        return Err(RenderError::Refused(format!($($t)*)))
    };
}

pub mod copies;

use copies::Copies;

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

/// The user materials of a run, checked ([`check_before_run`]): what its manifest records of
/// them, and the private copies of their files that Blender reads (kept until it is dropped,
/// so it must outlive the run).
pub struct Checked {
    /// Name -> manifest record.
    pub entries: BTreeMap<String, UserMaterial>,
    _copies: Option<Copies>,
}

/// Check every user material of `cat` that `used` names before a run renders anything, and
/// point `cat` at private copies of exactly the bytes checked ([`Copies`]): every file a
/// user material makes Blender read, whatever its kind (a `.blend` and the images its node
/// group reads, files or packed, a JSON material's `image` layers, a PBR folder's maps), is
/// read once from inside its material folder and checked by
/// [`clevrtex_materials::texture::bytes_problem`]. One Blender worker of `blender` inspects
/// each `.blend` copy's node group: it must have a surface output, no input the instance
/// cannot drive and no default for (a shader input). No user material used: nothing
/// started, nothing copied.
pub fn check_before_run(
    cat: &mut Catalogue,
    used: &BTreeSet<String>,
    blender: &Path,
    startup_timeout: Duration,
    interrupt: Arc<AtomicBool>,
) -> Result<Checked> {
    let user: Vec<String> = used
        .iter()
        .filter(|n| cat.get(n).is_some_and(|m| m.set == Set::User))
        .cloned()
        .collect();
    if user.is_empty() {
        return Ok(Checked {
            entries: BTreeMap::new(),
            _copies: None,
        });
    }
    let mut copies = Copies::new()?;
    let mut entries = BTreeMap::new();
    let mut blends = Vec::new();
    // Every file that fails its check, over all materials: a library with many missing
    // textures is named whole, not one texture per run.
    let mut problems = Problems::default();
    for name in &user {
        let m = cat.require(name).map_err(refused)?.clone();
        let Some(root) = cat.user_root(name).map(Path::to_path_buf) else {
            refuse!("user material `{name}` (`{}`) is not inside a `--materials` folder\nhint: put the material in the folder", m.file);
        };
        let mut recipe = m.recipe.clone();
        let mut textures = Vec::new();
        let mut copy = |p: &mut Value, expect: Expect| {
            let path = Path::new(p.as_str().unwrap_or(""));
            match copies.copy(name, &m.file, &root, path, expect) {
                Ok(c) => *p = Value::String(c.copy.to_string_lossy().into_owned()),
                Err(e) => problems.push(e),
            }
        };
        let mut file = relative(&root, Path::new(&m.file));
        match m.recipe["kind"].as_str() {
            Some("blend") => {
                let c = copies.copy(
                    name,
                    &m.file,
                    &root,
                    Path::new(m.recipe["path"].as_str().unwrap_or("")),
                    Expect::Blend,
                );
                let c = match c {
                    Ok(c) => c,
                    Err(e) => {
                        problems.push(e);
                        continue;
                    }
                };
                file = c.rel;
                recipe["path"] = c.copy.to_string_lossy().into_owned().into();
                blends.push(name.clone());
            }
            Some("pbr") => {
                for (key, p) in recipe["maps"].as_object_mut().into_iter().flatten() {
                    let channels = if ["color", "normal", "arm"].contains(&key.as_str()) {
                        3
                    } else {
                        1
                    };
                    textures.push(relative(&root, Path::new(p.as_str().unwrap_or(""))));
                    copy(p, Expect::PbrMap { channels });
                }
            }
            _ => {
                for layer in recipe["layers"].as_array_mut().into_iter().flatten() {
                    if let Some(p) = layer.get_mut("path") {
                        textures.push(relative(&root, Path::new(p.as_str().unwrap_or(""))));
                        copy(p, Expect::Texture);
                    }
                }
            }
        }
        cat.set_user_recipe(name, recipe).map_err(refused)?;
        entries.insert(name.clone(), (root, file, textures));
    }
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
            let (root, _, textures) = entries.get_mut(name).expect("every user material");
            inspect_blend(
                &mut session,
                cat,
                &mut copies,
                name,
                root,
                textures,
                &mut problems,
            )?;
        }
        session.close();
    }
    problems.into_result()?;
    let entries = entries
        .into_iter()
        .map(|(name, (_, file, mut textures))| {
            let m = cat.require(&name).expect("checked above");
            textures.sort();
            textures.dedup();
            let entry = UserMaterial {
                file,
                group: m.recipe["group"].as_str().map(String::from),
                textures,
                xxh3: m.hash.clone(),
            };
            (name, entry)
        })
        .collect();
    Ok(Checked {
        entries,
        _copies: Some(copies),
    })
}

/// Inspect the copy of user `.blend` material `name` (its recipe's `path`) in `session`,
/// check its group, copy every image file it reads from the material folder `root` (`//x`
/// of the copy is `root/x`) and check every image packed into it (the bridge writes their
/// bytes into the private folder, where they stay: the bridge then loads them from there);
/// fix the recipe to the group and those files (`images`). `textures` gets what the
/// manifest records of them.
fn inspect_blend(
    session: &mut BlenderSession,
    cat: &mut Catalogue,
    copies: &mut Copies,
    name: &str,
    root: &Path,
    textures: &mut Vec<String>,
    problems: &mut Problems,
) -> Result<()> {
    let m = cat.require(name).map_err(refused)?.clone();
    let path = PathBuf::from(m.recipe["path"].as_str().unwrap_or(""));
    let group = m.recipe["group"].as_str().map(String::from);
    let packed_dir = copies.base(name).join(".packed");
    std::fs::create_dir_all(&packed_dir).map_err(|cause| {
        RenderError::io(
            "cannot create the folder for packed images",
            packed_dir.clone(),
            cause,
            "set `TMPDIR` to a writable folder with free space",
        )
    })?;
    let reply =
        session.request(|w| w.inspect(&path, group.as_deref(), Some(&packed_dir), INSPECT_TIMEOUT));
    let reply = match reply {
        Ok(r) => r,
        Err(RenderError::Bridge { message, .. }) => refuse!(
            "user material `{name}` (`{}`): {}\nhint: save a node group named after the file with a `Shader` (or `BSDF`, `Surface`) output in it, as the public generator's `data/materials` files have (docs/materials.md)",
            m.file,
            clevrtex_scene::text::printable(&message)
        ),
        Err(e) => return Err(e),
    };
    check_group(name, &m.file, &reply)?;
    let base = copies.base(name);
    let mut images = serde_json::Map::new();
    for img in &reply.images {
        let shown_name = clevrtex_scene::text::printable(&img.name);
        if img.source == "GENERATED" {
            if let Some(problem) = clevrtex_materials::texture::side_problem(img.width, img.height)
            {
                refuse!(
                    "user material `{name}` (`{}`): generated image `{shown_name}` {problem}\nhint: make the image smaller in the `.blend`",
                    m.file
                );
            }
            continue;
        }
        if img.source != "FILE" {
            refuse!(
                "user material `{name}` (`{}`): texture `{}` is a {} image; only single image files are read\nhint: replace it with one PNG or JPEG file",
                m.file,
                clevrtex_scene::text::printable(&img.path),
                clevrtex_scene::text::printable(&img.source.to_lowercase())
            );
        }
        if img.packed {
            let (Some(key), Some(file)) = (&img.key, &img.file) else {
                refuse!("user material `{name}` (`{}`): the bridge did not write packed image `{shown_name}`\nhint: this is a bug of clevrtex; please report it", m.file);
            };
            let what = format!("image `{shown_name}` packed into the `.blend`");
            if let Err(e) = copies.check_own(name, &m.file, &what, Path::new(file), Expect::Texture)
            {
                problems.push(e);
                continue;
            }
            images.insert(key.clone(), file.clone().into());
            textures.push(format!("packed:{}", img.name));
            continue;
        }
        // The copy's `//x` is the folder's `x`; any other path is taken as it is (and is
        // refused unless it lies inside the folder).
        let reported = Path::new(&img.path);
        let source = match reported.strip_prefix(&base) {
            Ok(rel) => root.join(rel),
            Err(_) => reported.to_path_buf(),
        };
        let c = match copies.copy(name, &m.file, root, &source, Expect::Texture) {
            Ok(c) => c,
            Err(e) => {
                problems.push(e);
                continue;
            }
        };
        textures.push(c.rel);
        images.insert(
            img.path.clone(),
            c.copy.to_string_lossy().into_owned().into(),
        );
    }
    let mut recipe = m.recipe.clone();
    recipe["group"] = reply.group.clone().into();
    recipe["images"] = Value::Object(images);
    cat.set_user_recipe(name, recipe).map_err(refused)?;
    Ok(())
}

/// The files of user materials that failed their checks, over a whole `--materials` folder.
#[derive(Default)]
struct Problems(Vec<RenderError>);

/// Problems named one per line before the rest are only counted; all of them with
/// `CLEVRTEX_LIST_ALL=1`.
const PROBLEMS_SHOWN: usize = 10;

impl Problems {
    fn push(&mut self, e: RenderError) {
        self.0.push(e);
    }

    /// One problem as it was (its message and hint); several as a count, one line each
    /// (the first [`PROBLEMS_SHOWN`], all with `CLEVRTEX_LIST_ALL=1`) and the first's hint.
    fn into_result(self) -> Result<()> {
        let all = std::env::var_os("CLEVRTEX_LIST_ALL").is_some_and(|v| v == "1");
        match self.0.len() {
            0 => Ok(()),
            1 => Err(self.0.into_iter().next().expect("one")),
            n => Err(RenderError::Refused(summary(&self.0, n, all))),
        }
    }
}

/// The message of `n` problems: a count, a line each (the first [`PROBLEMS_SHOWN`] unless
/// `all`), and the first one's hint.
fn summary(problems: &[RenderError], n: usize, all: bool) -> String {
    let texts: Vec<String> = problems.iter().map(|e| e.to_string()).collect();
    let first_line = |t: &String| t.lines().next().unwrap_or("").to_string();
    let shown = if all { n } else { n.min(PROBLEMS_SHOWN) };
    let mut out = format!("{n} files of user materials failed their checks:\n");
    for t in &texts[..shown] {
        out += &format!("  {}\n", first_line(t));
    }
    if shown < n {
        out += &format!(
            "  ... and {} more (all of them: rerun with CLEVRTEX_LIST_ALL=1)\n",
            n - shown
        );
    }
    match texts[0].lines().find(|l| l.starts_with("hint: ")) {
        Some(hint) => out += hint,
        None => out += "hint: fix or remove these files, then run again",
    }
    out
}

/// `path` relative to the material folder `root` (the folder's own location is not part of
/// the dataset); as it is when it is not inside.
fn relative(root: &Path, path: &Path) -> String {
    clevrtex_dataset::dataset::relative_to_root(root, path)
        .unwrap_or_else(|| path.to_path_buf())
        .to_string_lossy()
        .into_owned()
}

/// The group's sockets against the convention.
fn check_group(name: &str, file: &str, reply: &crate::worker::InspectReply) -> Result<()> {
    let is_shader = |t: &str| t == "SHADER" || t == "NodeSocketShader";
    let surface = reply
        .outputs
        .iter()
        .find(|s| SURFACE_OUTPUTS.contains(&s.name.as_str()));
    if !surface.is_some_and(|s| is_shader(&s.r#type)) {
        refuse!(
            "user material `{name}` (`{file}`): node group `{}` has no shader output named `Shader`, `BSDF` or `Surface`\nhint: connect the group's shader to an output of that name",
            clevrtex_scene::text::printable(&reply.group)
        );
    }
    for s in &reply.inputs {
        if is_shader(&s.r#type) && !DRIVEN_INPUTS.contains(&s.name.as_str()) {
            refuse!(
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

/// A catalogue error (a material it does not hold) as a refusal, its message kept.
fn refused(e: clevrtex_materials::Error) -> RenderError {
    RenderError::Refused(e.to_string())
}

/// Name -> hash of the run's user materials, as each sample's metadata records them.
pub fn hashes(entries: &BTreeMap<String, UserMaterial>) -> BTreeMap<String, String> {
    entries
        .iter()
        .map(|(n, e)| (n.clone(), e.xxh3.clone()))
        .collect()
}

/// Every material a scene of `scenes` uses; an unknown one is an error naming the scene.
pub fn used_by_scenes<'a>(
    cat: &Catalogue,
    scenes: impl IntoIterator<Item = (&'a Path, &'a clevrtex_scene::SceneFile)>,
) -> Result<BTreeSet<String>> {
    let mut used = BTreeSet::new();
    for (path, s) in scenes {
        for m in std::iter::once(&s.backdrop.material).chain(s.objects.iter().map(|o| &o.material))
        {
            if cat.get(&m.name).is_none() {
                refuse!(
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn many_problems_are_counted_and_the_first_ten_named() {
        let problems: Vec<RenderError> = (0..12)
            .map(|i| {
                RenderError::Refused(format!(
                    "user material `m{i}`: texture `t{i}.png` cannot be read\nhint: put it back"
                ))
            })
            .collect();
        let short = summary(&problems, 12, false);
        assert!(
            short.starts_with("12 files of user materials failed their checks:"),
            "{short}"
        );
        assert_eq!(short.matches("cannot be read").count(), 10, "{short}");
        assert!(
            short.contains("t9.png") && !short.contains("t10.png"),
            "{short}"
        );
        assert!(short.contains("... and 2 more"), "{short}");
        assert!(short.ends_with("hint: put it back"), "{short}");
        let all = summary(&problems, 12, true);
        assert_eq!(all.matches("cannot be read").count(), 12, "{all}");
        assert!(!all.contains("more"), "{all}");
    }
}
