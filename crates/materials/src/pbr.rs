//! PBR texture folders: one folder of image maps per material, as Poly Haven and ambientCG
//! ship them, turned into a recipe of kind `pbr` for the bridge (`blender_scripts/materials.py`).
//!
//! File names (the map type is the suffix; case of the map token as the sites write it):
//!
//! - Poly Haven (docs.polyhaven.com, "Technical standards: textures"):
//!   `<slug>_<map>_<res>.<ext>` or `<slug>_<map>.<ext>`, maps `diff`, `nor_gl`, `nor_dx`,
//!   `rough`, `metal`, `disp`, `ao`, `arm` (R ambient occlusion, G roughness, B metalness),
//!   resolutions `1k`, `2k`, `4k`, ...
//! - ambientCG: `<Name>_<res>-<FORMAT>_<Map>.<ext>` (and the older `<Name>_<res>_<Map>.<ext>`),
//!   maps `Color`, `NormalGL`, `NormalDX`, `Roughness`, `Metalness`, `Displacement`,
//!   `AmbientOcclusion`, resolutions `1K`, `2K`, ... and formats `JPG`, `PNG`, `EXR`.
//!
//! Extensions `.jpg`, `.jpeg`, `.png`, `.exr`. Other files are ignored; a folder with no file
//! of either layout is not a PBR folder (a `.blend` pack's `textures/` folder, say).
//!
//! Every map read is checked here, from its header only (the `image` crate; nothing is
//! decoded), before any render: readable, a known image format, sides at most
//! [`MAX_TEXTURE_SIDE`] (the one cap on a loaded texture, `texture.rs`),
//! and of the right kind (colour, normal and packed ARM maps have 3 or 4 channels).

use std::path::{Path, PathBuf};

use serde_json::{Map, Value};

use crate::error::{Error, ErrorKind};
use crate::texture::{side_problem, MAX_TEXTURE_SIDE};

/// World units (scene units) per repeat of the maps, unless `material.json` says otherwise.
pub const DEFAULT_TILE: f64 = 1.0;
/// Displacement distance in world units at instance displacement strength 1 (the map's
/// 0..1 range, mid-level 0.5), unless `material.json` says otherwise.
pub const DEFAULT_RELIEF: f64 = 0.04;
/// The optional settings file inside a PBR folder.
pub const SETTINGS_FILE: &str = "material.json";

/// Which map a file is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Kind {
    Color,
    NormalGl,
    NormalDx,
    Roughness,
    Metalness,
    Displacement,
    Ao,
    Arm,
}

impl Kind {
    /// Maps that must hold 3 or 4 channels.
    fn needs_rgb(self) -> bool {
        matches!(
            self,
            Kind::Color | Kind::NormalGl | Kind::NormalDx | Kind::Arm
        )
    }

    fn what(self) -> &'static str {
        match self {
            Kind::Color => "colour map",
            Kind::NormalGl | Kind::NormalDx => "normal map",
            Kind::Arm => "packed AO/roughness/metalness map",
            Kind::Roughness => "roughness map",
            Kind::Metalness => "metalness map",
            Kind::Displacement => "displacement map",
            Kind::Ao => "ambient occlusion map",
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Layout {
    PolyHaven,
    AmbientCg,
}

impl Layout {
    fn name(self) -> &'static str {
        match self {
            Layout::PolyHaven => "polyhaven",
            Layout::AmbientCg => "ambientcg",
        }
    }
}

/// What a file name says.
#[derive(Debug, Clone, PartialEq)]
struct Named {
    layout: Layout,
    kind: Kind,
    /// The material part of the name (slug).
    material: String,
    /// Nominal resolution in pixels (`2k` = 2048); 0 when the name has none.
    res: u32,
    /// Preference among formats of one map: PNG, then JPEG, then EXR.
    format_rank: u8,
}

const POLYHAVEN_MAPS: &[(&str, Kind)] = &[
    ("nor_gl", Kind::NormalGl),
    ("nor_dx", Kind::NormalDx),
    ("diff", Kind::Color),
    ("rough", Kind::Roughness),
    ("metal", Kind::Metalness),
    ("disp", Kind::Displacement),
    ("arm", Kind::Arm),
    ("ao", Kind::Ao),
];

const AMBIENTCG_MAPS: &[(&str, Kind)] = &[
    ("Color", Kind::Color),
    ("NormalGL", Kind::NormalGl),
    ("NormalDX", Kind::NormalDx),
    ("Roughness", Kind::Roughness),
    ("Metalness", Kind::Metalness),
    ("Displacement", Kind::Displacement),
    ("AmbientOcclusion", Kind::Ao),
];

/// `2k` / `2K` -> 2048.
fn resolution(token: &str) -> Option<u32> {
    let digits = token.strip_suffix(['k', 'K'])?;
    if digits.is_empty() || digits.len() > 3 || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    digits.parse::<u32>().ok().map(|k| k * 1024)
}

/// Classify a file name; `None` for a file of neither layout.
fn classify(file_name: &str) -> Option<Named> {
    let (stem, ext) = file_name.rsplit_once('.')?;
    let format_rank = match ext.to_ascii_lowercase().as_str() {
        "png" => 0,
        "jpg" | "jpeg" => 1,
        "exr" => 2,
        _ => return None,
    };
    // ambientCG: <Name>_<res>[-<FORMAT>]_<Map>
    if let Some((rest, map)) = stem.rsplit_once('_') {
        if let Some(&(_, kind)) = AMBIENTCG_MAPS.iter().find(|(m, _)| *m == map) {
            if let Some((material, res)) = rest.rsplit_once('_') {
                let res_token = res.split_once('-').map_or(res, |(r, fmt)| {
                    if ["JPG", "PNG", "EXR"].contains(&fmt.to_ascii_uppercase().as_str()) {
                        r
                    } else {
                        ""
                    }
                });
                if let (Some(res), false) = (resolution(res_token), material.is_empty()) {
                    return Some(Named {
                        layout: Layout::AmbientCg,
                        kind,
                        material: material.to_string(),
                        res,
                        format_rank,
                    });
                }
            }
        }
    }
    // Poly Haven: <slug>_<map>[_<res>]
    let (body, res) = match stem.rsplit_once('_') {
        Some((b, r)) if resolution(r).is_some() => (b, resolution(r).unwrap_or(0)),
        _ => (stem, 0),
    };
    POLYHAVEN_MAPS.iter().find_map(|&(suffix, kind)| {
        let material = body.strip_suffix(suffix)?.strip_suffix('_')?;
        (!material.is_empty()).then(|| Named {
            layout: Layout::PolyHaven,
            kind,
            material: material.to_string(),
            res,
            format_rank,
        })
    })
}

/// The recipe of the PBR folder `dir` (material `name`), or `None` when no file in it is
/// named as a Poly Haven or ambientCG map. `root` is the canonical `--materials DIR`: no map
/// may resolve outside it.
pub(crate) fn recipe(name: &str, dir: &Path, root: &Path) -> Result<Option<Value>, Error> {
    let shown = dir.display().to_string();
    let err = |kind, file: &str, msg: String, hint: &str| Error::new(kind, file, "", msg, hint);
    let rd = std::fs::read_dir(dir).map_err(|e| {
        err(
            ErrorKind::Io,
            &shown,
            format!("cannot read the texture folder of material `{name}`: {e}"),
            "check the folder's permissions",
        )
    })?;
    let mut found: Vec<(Named, PathBuf)> = Vec::new();
    for entry in rd.flatten() {
        let file_name = entry.file_name();
        let Some(named) = file_name.to_str().and_then(classify) else {
            continue;
        };
        found.push((named, entry.path()));
    }
    if found.is_empty() {
        return Ok(None);
    }
    found.sort_by(|a, b| a.1.cmp(&b.1));
    let (layout, material) = (found[0].0.layout, found[0].0.material.clone());
    if let Some((other, path)) = found
        .iter()
        .find(|(n, _)| n.layout != layout || n.material != material)
    {
        return Err(err(
            ErrorKind::BadValue,
            &path.display().to_string(),
            format!(
                "texture folder of material `{name}` holds maps of more than one material \
                 (`{material}` and `{}`)",
                other.material
            ),
            "put each material's maps in a folder of its own",
        ));
    }
    // The resolution: the largest one with a colour map whose nominal side is within the cap.
    let colour_res: Vec<u32> = found
        .iter()
        .filter(|(n, _)| n.kind == Kind::Color)
        .map(|(n, _)| n.res)
        .collect();
    let Some(res) = colour_res
        .iter()
        .copied()
        .filter(|&r| r <= MAX_TEXTURE_SIDE)
        .max()
    else {
        let (msg, hint) = if colour_res.is_empty() {
            (
                format!("texture folder of material `{name}` has no colour map"),
                format!(
                    "add the base colour map ({})",
                    match layout {
                        Layout::PolyHaven => "`<name>_diff_<res>.jpg`",
                        Layout::AmbientCg => "`<Name>_<res>-JPG_Color.jpg`",
                    }
                ),
            )
        } else {
            (
                format!(
                    "every colour map of material `{name}` is larger than the {MAX_TEXTURE_SIDE}-pixel cap on a loaded texture"
                ),
                format!(
                    "download a resolution of {}K or less",
                    MAX_TEXTURE_SIDE / 1024
                ),
            )
        };
        return Err(err(ErrorKind::BadValue, &shown, msg, &hint));
    };
    let pick = |kind: Kind| -> Option<&PathBuf> {
        found
            .iter()
            .filter(|(n, _)| n.kind == kind && n.res == res)
            .min_by_key(|(n, p)| (n.format_rank, p.clone()))
            .map(|(_, p)| p)
    };
    let mut maps = Map::new();
    let mut read = |key: &str, kind: Kind, path: &PathBuf| -> Result<(), Error> {
        let abs = check_map(name, kind, path, root)?;
        maps.insert(key.into(), abs.to_string_lossy().into_owned().into());
        Ok(())
    };
    let color = pick(Kind::Color).expect("the resolution was chosen by its colour map");
    read("color", Kind::Color, color)?;
    let mut convention = Value::Null;
    if let Some(p) = pick(Kind::NormalGl) {
        read("normal", Kind::NormalGl, p)?;
        convention = "gl".into();
    } else if let Some(p) = pick(Kind::NormalDx) {
        read("normal", Kind::NormalDx, p)?;
        convention = "dx".into();
    }
    let rough = pick(Kind::Roughness);
    let metal = pick(Kind::Metalness);
    if let Some(p) = rough {
        read("roughness", Kind::Roughness, p)?;
    }
    if let Some(p) = metal {
        read("metallic", Kind::Metalness, p)?;
    }
    if rough.is_none() || metal.is_none() {
        if let Some(p) = pick(Kind::Arm) {
            read("arm", Kind::Arm, p)?;
        }
    }
    if let Some(p) = pick(Kind::Displacement) {
        read("displacement", Kind::Displacement, p)?;
    }
    let has_disp = maps.contains_key("displacement");
    let settings = read_settings(name, dir)?;
    let res_label = if res == 0 {
        "no resolution in the names".to_string()
    } else {
        format!("{}K", res / 1024)
    };
    let mut out = Map::new();
    out.insert("kind".into(), "pbr".into());
    let description = settings
        .get("description")
        .and_then(Value::as_str)
        .map(str::to_string)
        .unwrap_or_else(|| {
            let site = match layout {
                Layout::PolyHaven => "Poly Haven",
                Layout::AmbientCg => "ambientCG",
            };
            format!("{site} texture maps `{material}` ({res_label})")
        });
    out.insert("description".into(), description.into());
    out.insert("layout".into(), layout.name().into());
    out.insert("resolution".into(), res.into());
    out.insert("maps".into(), Value::Object(maps));
    out.insert("normal_convention".into(), convention);
    out.insert(
        "tile".into(),
        settings.get("tile").cloned().unwrap_or(DEFAULT_TILE.into()),
    );
    out.insert(
        "relief".into(),
        settings
            .get("relief")
            .cloned()
            .unwrap_or(DEFAULT_RELIEF.into()),
    );
    out.insert("scale".into(), 1.0.into());
    out.insert("displaces".into(), has_disp.into());
    out.insert("tint".into(), "multiply".into());
    Ok(Some(Value::Object(out)))
}

/// Check one map before any render: no link out of `root`, a regular file, a readable image
/// header of a known format, sides within [`MAX_TEXTURE_SIDE`], channels fit for `kind`. Returns the
/// canonical path.
fn check_map(name: &str, kind: Kind, path: &Path, root: &Path) -> Result<PathBuf, Error> {
    let shown = path.display().to_string();
    let what = kind.what();
    let err = |kind: ErrorKind, msg: String, hint: &str| Error::new(kind, &shown, "", msg, hint);
    let abs = path.canonicalize().map_err(|e| {
        err(
            ErrorKind::Io,
            format!("cannot resolve the {what} of material `{name}`: {e}"),
            "replace the file or the broken link with the image itself",
        )
    })?;
    if !abs.starts_with(root) {
        return Err(err(
            ErrorKind::BadValue,
            format!(
                "the {what} of material `{name}` is a link out of the material directory (to `{}`)",
                abs.display()
            ),
            "copy the image into the material's folder instead of linking to it",
        ));
    }
    if !std::fs::metadata(&abs).is_ok_and(|m| m.is_file()) {
        return Err(err(
            ErrorKind::BadValue,
            format!("the {what} of material `{name}` is not a regular file"),
            "replace it with the image file",
        ));
    }
    let bad_image = |e: String| {
        err(
            ErrorKind::BadValue,
            format!("the {what} of material `{name}` is not a readable image: {e}"),
            "download the map again (PNG, JPEG or OpenEXR), or remove it from the folder",
        )
    };
    let (w, h, channels) = map_header(&abs).map_err(bad_image)?;
    if let Some(problem) = side_problem(w, h) {
        return Err(err(
            ErrorKind::BadValue,
            format!("the {what} of material `{name}` {problem}"),
            &format!("use a download of {}K or less", MAX_TEXTURE_SIDE / 1024),
        ));
    }
    if kind.needs_rgb() && channels < 3 {
        return Err(err(
            ErrorKind::BadValue,
            format!(
                "the {what} of material `{name}` has {channels} channel(s); a {what} has 3 or 4 (RGB)"
            ),
            "check that the file is the right map (a greyscale image is a roughness, height or AO map)",
        ));
    }
    Ok(abs)
}

/// A map's width, height and channels from its header (nothing decoded), or why it cannot be
/// read: PNG, JPEG or OpenEXR only.
#[cfg(feature = "textures")]
fn map_header(abs: &Path) -> Result<(u32, u32, u8), String> {
    let reader = image::ImageReader::open(abs)
        .map_err(|e| e.to_string())?
        .with_guessed_format()
        .map_err(|e| e.to_string())?;
    let Some(format) = reader.format() else {
        return Err("unknown image format".into());
    };
    if !matches!(
        format,
        image::ImageFormat::Png | image::ImageFormat::Jpeg | image::ImageFormat::OpenExr
    ) {
        return Err(format!("{format:?} is not PNG, JPEG or OpenEXR"));
    }
    // Headers only: `into_decoder` reads the header, nothing is decoded.
    let decoder = reader.into_decoder().map_err(|e| e.to_string())?;
    let (w, h) = image::ImageDecoder::dimensions(&decoder);
    let channels = image::ImageDecoder::color_type(&decoder).channel_count();
    Ok((w, h, channels))
}

/// Without image decoders (the feature `textures`) no map can be read.
#[cfg(not(feature = "textures"))]
fn map_header(_abs: &Path) -> Result<(u32, u32, u8), String> {
    Err(crate::texture::NO_DECODERS.into())
}

/// The optional `material.json` of a PBR folder: `description`, `tile` (world units per
/// repeat), `relief` (displacement distance in world units).
fn read_settings(name: &str, dir: &Path) -> Result<Map<String, Value>, Error> {
    let path = dir.join(SETTINGS_FILE);
    let shown = path.display().to_string();
    let meta = match std::fs::symlink_metadata(&path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Map::new()),
        r => r,
    };
    let err =
        |kind, field: &str, msg: String, hint: &str| Error::new(kind, &shown, field, msg, hint);
    if !meta.is_ok_and(|m| m.is_file()) {
        return Err(err(
            ErrorKind::Io,
            "",
            format!("the settings of material `{name}` are not a regular file"),
            "make `material.json` a plain file (no link)",
        ));
    }
    let text = std::fs::read_to_string(&path).map_err(|e| {
        err(
            ErrorKind::Io,
            "",
            format!("cannot read: {e}"),
            "check the file's permissions",
        )
    })?;
    let v: Value = serde_json::from_str(&text).map_err(|e| {
        err(
            ErrorKind::Json,
            "",
            format!("invalid json: {e}"),
            "write `{\"tile\": 0.5, \"relief\": 0.03, \"description\": \"...\"}`",
        )
    })?;
    let Value::Object(obj) = v else {
        return Err(err(
            ErrorKind::BadValue,
            "",
            "expected a json object".into(),
            "write `{\"tile\": 0.5}`",
        ));
    };
    for (key, val) in &obj {
        let ok = match key.as_str() {
            "description" => val.is_string(),
            "tile" => val
                .as_f64()
                .is_some_and(|x| x.is_finite() && (0.001..=1000.0).contains(&x)),
            "relief" => val
                .as_f64()
                .is_some_and(|x| x.is_finite() && (0.0..=1.0).contains(&x)),
            _ => {
                return Err(err(
                    ErrorKind::UnknownField,
                    key,
                    format!("unknown field `{key}`"),
                    "known fields here: description, tile, relief",
                ))
            }
        };
        if !ok {
            return Err(err(
                ErrorKind::BadValue,
                key,
                format!("bad value `{val}`"),
                "`tile`: world units per repeat in [0.001, 1000]; `relief`: world units in [0, 1]; `description`: a string",
            ));
        }
    }
    Ok(obj)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn file_names_of_both_layouts() {
        let n = classify("red_brick_03_nor_gl_4k.exr").unwrap();
        assert_eq!(
            (n.layout, n.kind, n.material.as_str(), n.res, n.format_rank),
            (Layout::PolyHaven, Kind::NormalGl, "red_brick_03", 4096, 2)
        );
        let n = classify("red_brick_03_diff_1k.jpg").unwrap();
        assert_eq!((n.kind, n.res), (Kind::Color, 1024));
        let n = classify("red_brick_03_arm.png").unwrap();
        assert_eq!(
            (n.kind, n.res, n.material.as_str()),
            (Kind::Arm, 0, "red_brick_03")
        );
        let n = classify("Bricks076C_2K-JPG_Color.jpg").unwrap();
        assert_eq!(
            (n.layout, n.kind, n.material.as_str(), n.res),
            (Layout::AmbientCg, Kind::Color, "Bricks076C", 2048)
        );
        let n = classify("Bricks076C_8K-PNG_NormalDX.png").unwrap();
        assert_eq!((n.kind, n.format_rank), (Kind::NormalDx, 0));
        let n = classify("Ground054_1K_AmbientOcclusion.jpg").unwrap();
        assert_eq!((n.kind, n.res), (Kind::Ao, 1024));
        for other in [
            "Bricks_COL_3K.jpg",
            "Bricks_AO_3K.jpg",
            "Bricks_DISP_3K.jpg",
            "readme.txt",
            "_diff_2k.jpg",
            "preview.png",
            "x_diff_2k.tif",
            "Bricks_2K-TIF_Color.jpg",
        ] {
            assert_eq!(classify(other), None, "{other}");
        }
    }

    #[test]
    fn resolution_tokens() {
        assert_eq!(resolution("16k"), Some(16_384));
        assert_eq!(resolution("1K"), Some(1024));
        assert_eq!(resolution("k"), None);
        assert_eq!(resolution("4096"), None);
        assert_eq!(resolution("99999k"), None);
    }
}
