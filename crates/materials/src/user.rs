//! User materials (`--materials DIR`): the folder's `.json`, `.blend` and PBR texture folders
//! added to the catalogue ([`Catalogue::add_user_dir`]), a material's recipe replaced by one
//! naming the checked copies of its files ([`Catalogue::set_user_recipe`]), and where each
//! came from.

use std::path::Path;

use serde_json::{Map, Value};

use crate::{pbr, texture, Catalogue, Error, ErrorKind, Material, Set};

/// The public generator's CLEVR base materials, as (its name for the material: the file stem
/// lowercased, as its `sampling.py` names every `.blend`; the built-in that plays the part
/// here). Its `data/materials` folder, and the v2 tarballs that replace it, hold
/// `Rubber.blend`, `MyMetal.blend` and `TabulaRasa.blend` beside the textured materials; every
/// textured variant's config excludes exactly these three (`"exclude": ["tabularasa",
/// "rubber", "mymetal"]` in `full.json`, `outd.json`, `pbg_varied_on_plainbg.json`, ...), and
/// only CLEVR's objects (`clevr.json`, `vbg_colour_on_variedbg.json`: `rubber`, `mymetal`) and
/// plain backdrop (`clevr.json`, `pbg_varied_on_plainbg.json`: `tabularasa`) use them, parts
/// our built-in `rubber`, `metal` and `plain` play. So a user folder's `.blend` of one of
/// these names is left out of set `user` ([`Catalogue::clevr_base`] lists them), not a clash.
pub const CLEVR_BASE: [(&str, &str); 3] = [
    ("rubber", "rubber"),
    ("mymetal", "metal"),
    ("tabularasa", "plain"),
];

/// A `.blend` of a user folder recognised as one of the public generator's CLEVR base
/// materials ([`CLEVR_BASE`]) and left out of the user set.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ClevrBase {
    /// The file.
    pub file: std::path::PathBuf,
    /// The public generator's name for it (`rubber`, `mymetal`, `tabularasa`).
    pub name: &'static str,
    /// The built-in material that plays its part (`rubber`, `metal`, `plain`).
    pub builtin: &'static str,
}

impl ClevrBase {
    /// Why `name` is not a material: "material `mymetal` is the public generator's CLEVR
    /// base material `MyMetal.blend`, left out of set `user`".
    pub fn left_out(&self) -> String {
        format!(
            "material `{}` is the public generator's CLEVR base material `{}`, which its \
             textured variants never draw; `--materials` leaves it out of set `user`",
            self.name,
            self.file
                .file_name()
                .map(|f| f.to_string_lossy())
                .unwrap_or_default()
        )
    }
}

impl Catalogue {
    /// Add the materials of a user directory (`--materials DIR`), set [`Set::User`].
    ///
    /// A `.blend` file must be one (its header is checked: `BLENDER`, or gzip or zstd
    /// compressed), so a stray file fails here, naming it, not later inside Blender.
    ///
    /// `NAME.json` is a material in our format (relative paths resolve against `DIR`), or
    /// `{"blend": "file.blend", "group": "NodeGroup"}`; a `NAME.blend` that no JSON file
    /// refers to becomes material `NAME` using the first node group with the ClevrTex
    /// interface. A folder of Poly Haven or ambientCG texture maps becomes material
    /// `<folder name>` of kind `pbr` (see [`pbr`]; every map it uses is checked here).
    /// Names are the lowercased file stems (folder names); a clash is an error. A `.blend`
    /// that is one of the public generator's CLEVR base materials by name ([`CLEVR_BASE`]:
    /// `Rubber.blend`, `MyMetal.blend`, `TabulaRasa.blend`, any case) and that no JSON file
    /// refers to is left out, unread, and listed by [`Catalogue::clevr_base`].
    pub fn add_user_dir(&mut self, dir: &Path) -> Result<(), Error> {
        let shown = dir.display().to_string();
        let rd = std::fs::read_dir(dir).map_err(|e| {
            Error::new(
                ErrorKind::Io,
                &shown,
                "",
                format!("cannot read material directory: {e}"),
                "pass an existing directory to `--materials`",
            )
        })?;
        let root = dir.canonicalize().unwrap_or_else(|_| dir.to_path_buf());
        let mut files: Vec<_> = rd.flatten().map(|e| e.path()).collect();
        files.sort();
        // A link out of the folder is refused, naming it: the folder is what was given.
        for path in &files {
            let is_link = std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink());
            let material = path
                .extension()
                .is_some_and(|e| e == "json" || e == "blend");
            if is_link && material {
                let inside = path.canonicalize().is_ok_and(|c| c.starts_with(&root));
                if !inside {
                    return Err(Error::new(
                        ErrorKind::BadValue,
                        &path.display().to_string(),
                        "",
                        format!(
                            "material `{}` is a link out of the material folder `{}`",
                            user_name(path),
                            root.display()
                        ),
                        "copy the file into the folder instead of linking to it",
                    ));
                }
            }
        }
        let mut referenced = Vec::new();
        let mut added = Vec::new();
        let mut clevr_base = Vec::new();
        for path in &files {
            if path.extension().is_some_and(|e| e == "json") {
                let shown = path.display().to_string();
                let text = read_text(path).map_err(|e| {
                    Error::new(
                        ErrorKind::Io,
                        &shown,
                        "",
                        format!("cannot read: {e}"),
                        "check the file's permissions",
                    )
                })?;
                let name = user_name(path);
                let m = Material::parse(&name, Set::User, &shown, &text, Some(dir))?;
                if m.recipe["kind"] == "blend" {
                    referenced.push(m.recipe["path"].as_str().unwrap_or("").to_string());
                }
                added.push(m);
            }
        }
        for path in &files {
            if path.extension().is_some_and(|e| e == "blend") {
                let abs = path.canonicalize().unwrap_or(path.clone());
                if referenced.contains(&abs.to_string_lossy().into_owned()) {
                    continue;
                }
                let stem = path.file_stem().map(|s| s.to_string_lossy().to_lowercase());
                if let Some(&(name, builtin)) =
                    CLEVR_BASE.iter().find(|(n, _)| stem.as_deref() == Some(*n))
                {
                    clevr_base.push(ClevrBase {
                        file: path.clone(),
                        name,
                        builtin,
                    });
                    continue;
                }
                let shown = path.display().to_string();
                let problem =
                    texture::blend_size_problem(path).or_else(|| blend_file_problem(path));
                if let Some(problem) = problem {
                    return Err(Error::new(
                        ErrorKind::BadValue,
                        &shown,
                        "",
                        problem,
                        "save it again from Blender (File > Save), or remove it from the material directory",
                    ));
                }
                let mut recipe = Map::new();
                recipe.insert("kind".into(), "blend".into());
                recipe.insert("description".into(), "user node group".into());
                recipe.insert("path".into(), abs.to_string_lossy().into_owned().into());
                recipe.insert("group".into(), Value::Null);
                recipe.insert("displaces".into(), true.into());
                recipe.insert("tint".into(), "none".into());
                added.push(Material::from_recipe(
                    user_name(path),
                    Set::User,
                    shown,
                    Value::Object(recipe),
                ));
            }
        }
        self.add_pbr_folders(dir, &files, &mut added)?;
        for m in added {
            self.insert(m)?;
        }
        self.user_dirs.push(root);
        self.clevr_base.extend(clevr_base);
        Ok(())
    }

    /// The `.blend` files of the user directories that are the public generator's CLEVR base
    /// materials ([`CLEVR_BASE`]), left out of set `user`, in file order.
    pub fn clevr_base(&self) -> &[ClevrBase] {
        &self.clevr_base
    }

    /// The left-out CLEVR base material the public generator calls `name`, if a user
    /// directory held it (for an error that says why `name` is not a material).
    pub fn clevr_base_named(&self, name: &str) -> Option<&ClevrBase> {
        self.clevr_base.iter().find(|b| b.name == name)
    }

    /// The PBR texture folders among `files` (the entries of `dir`): each folder holding Poly
    /// Haven or ambientCG maps is material `<folder name>`, its maps checked ([`pbr`]).
    /// Folders without such maps (a `.blend` pack's `textures/`) are left alone.
    fn add_pbr_folders(
        &self,
        dir: &Path,
        files: &[std::path::PathBuf],
        added: &mut Vec<Material>,
    ) -> Result<(), Error> {
        let root = dir.canonicalize().map_err(|e| {
            Error::new(
                ErrorKind::Io,
                &dir.display().to_string(),
                "",
                format!("cannot resolve the material directory: {e}"),
                "pass an existing directory to `--materials`",
            )
        })?;
        for path in files {
            if !path.is_dir() {
                continue;
            }
            let shown = path.display().to_string();
            let name = user_name(path);
            let inside = path.canonicalize().is_ok_and(|p| p.starts_with(&root));
            if !inside {
                return Err(Error::new(
                    ErrorKind::BadValue,
                    &shown,
                    "",
                    format!(
                        "the folder of material `{name}` is a link out of the material directory"
                    ),
                    "copy the texture folder into the material directory instead of linking to it",
                ));
            }
            if let Some(recipe) = pbr::recipe(&name, path, &root)? {
                added.push(Material::from_recipe(name, Set::User, shown, recipe));
            }
        }
        Ok(())
    }

    /// Replace the recipe of user material `name` by `recipe` (its files checked and copied
    /// for a run: `render/src/user_materials/copies.rs`; a `.blend` fixed to its node group and the
    /// images it reads, `images`: the path the bridge sees -> the checked copy); the hash is
    /// computed again from the files the new recipe names.
    pub fn set_user_recipe(&mut self, name: &str, recipe: Value) -> Result<(), Error> {
        let m = self.require(name)?.clone();
        let updated = Material::from_recipe(m.name.clone(), m.set, m.file.clone(), recipe);
        if let Some(slot) = self.materials.iter_mut().find(|x| x.name == name) {
            *slot = updated;
        }
        Ok(())
    }

    /// The user directory (canonical) material `name` came from; `None` for built-ins.
    pub fn user_root(&self, name: &str) -> Option<&Path> {
        let m = self.get(name).filter(|m| m.set == Set::User)?;
        let path = Path::new(m.recipe["path"].as_str().unwrap_or(&m.file));
        let path = path.canonicalize().unwrap_or_else(|_| path.to_path_buf());
        self.user_dirs
            .iter()
            .find(|d| path.starts_with(d))
            .map(|d| d.as_path())
    }
}

fn user_name(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy())
        .unwrap_or_default()
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_lowercase()
            } else {
                '_'
            }
        })
        .collect()
}

/// The text of `path`, a regular file only, opened without blocking
/// ([`crate::hash::open_regular`]).
fn read_text(path: &Path) -> std::io::Result<String> {
    let mut text = String::new();
    std::io::Read::read_to_string(&mut crate::hash::open_regular(path)?, &mut text)?;
    Ok(text)
}

/// Why `path` is not a `.blend` file, if it is not: unreadable, or a header that is neither
/// Blender's `BLENDER` nor gzip or zstd compression (which Blender uses for compressed files).
pub fn blend_file_problem(path: &Path) -> Option<String> {
    let mut head = [0u8; 7];
    let read = crate::hash::open_regular(path)
        .and_then(|mut f| std::io::Read::read_exact(&mut f, &mut head).map(|()| head));
    match read {
        Err(e) => Some(format!("cannot read the `.blend` file: {e}")),
        Ok(h) => texture::blend_header_problem(&h),
    }
}
