//! COCO instances JSON, as `clevrtex export --format coco` writes it ([`export_coco`]): one file
//! `OUT/<variant>-<split>.json` per variant and split, read by pycocotools, Detectron2,
//! MMDetection and torchvision's references.
//!
//! The samples, their splits (the one rule, [`crate::dataset::splits`]) and what is not followed
//! are those of every export ([`crate::export`]); the image and the mask are read with the
//! reader's caps and checked as the shards' passes are ([`crate::export::PassCheck`]: a sample
//! failing the checks is left out, named). Each object with at least one pixel in the mask is one
//! annotation: `segmentation` its compressed COCO RLE ([`rle`]), `area` its pixels, `bbox`
//! `[x, y, w, h]` its extent in the mask, `iscrowd` 0, `category_id` its shape (one category
//! per shape: the dataset's one id table, [`crate::ids`], id = shape id + 1, the same in every
//! file), the metadata's other properties of the object under `attributes` (its numbers as
//! the metadata has them, bit for bit) and `object_index` its place in the metadata's
//! `objects` (its mask id less one). An image is the sample's RGB, referenced where it lies
//! (`file_name` an absolute path) or copied to `OUT/images/<stem>.png` (`file_name` relative to
//! OUT); `id` is unique across the variants of a dataset ([`crate::ids::coco_image_id`]:
//! variant number * 10^8 + index), `index` the sample's index and `stem` its stem, so the
//! files of several variants merge. `OUT/ids.json` holds the id table.

pub mod rle;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;
use serde_json::{json, Value};

use crate::dataset::{self, Dataset};
use crate::export::{io_err, open_source, samples, ExportError, Sample};
use crate::ids::IdTables;
use crate::layout::Split;
use clevrtex_scene::Pass;

/// What [`export_coco`] exports and how.
#[derive(Debug, Clone, Default)]
pub struct CocoOptions {
    /// Only this variant (default: every variant found).
    pub variant: Option<String>,
    /// Only this split (default: every split).
    pub split: Option<Split>,
    /// Copy the images to `OUT/images/` (default: reference them where they lie).
    pub copy_images: bool,
}

/// What [`export_coco`] did.
#[derive(Debug)]
pub struct CocoReport {
    /// The JSON files written, with their images and annotations.
    pub files: Vec<(PathBuf, usize, usize)>,
    /// Files or folders not followed or not read (their samples are left out), one line each.
    pub skipped: Vec<String>,
}

/// One image's entry and its objects' annotations (ids and categories not yet given).
struct Image {
    entry: Value,
    split: Split,
    objects: Vec<Object>,
    image: Option<(PathBuf, PathBuf)>,
}

/// One object's annotation before its id and category: its place in the metadata, shape,
/// compressed RLE, area, extent and attributes.
struct Object {
    index: usize,
    shape: String,
    counts: String,
    area: u64,
    extent: [u32; 4],
    attributes: Value,
}

/// Export the dataset under `dir` (an output folder of `clevrtex generate`, or the published
/// ClevrTex) as COCO instances JSON into `out` (created if missing). Stops between samples when
/// `stop` is raised ([`ExportError::Interrupted`]; nothing of the file being made is written).
pub fn export_coco(
    dir: &Path,
    out: &Path,
    opts: &CocoOptions,
    stop: &AtomicBool,
) -> Result<CocoReport, ExportError> {
    let (ds, chosen, mut skipped) = open_source(dir, out, opts.variant.as_deref())?;
    let mut todo = Vec::new();
    for &i in &chosen {
        let vd = &ds.variants[i];
        let all = samples(&ds, vd, &mut skipped)?;
        let sizes = dataset::split_sizes(&all.iter().map(|s| s.split).collect::<Vec<_>>());
        let picked: Vec<Sample> = all
            .into_iter()
            .filter(|s| opts.split.is_none_or(|want| want == s.split))
            .collect();
        todo.push((vd.variant.clone(), picked, sizes));
    }
    if todo.iter().all(|(_, s, _)| s.is_empty()) {
        let found: Vec<String> = todo.iter().map(|(v, _, z)| format!("{v}: {z}")).collect();
        return Err(ExportError::Message(format!(
            "no sample to export{} in `{}` (splits found: {})\nhint: pick another `--split`, or leave it out",
            opts.split.map(|s| format!(" in split `{}`", s.name())).unwrap_or_default(),
            dir.display(),
            found.join("; ")
        )));
    }
    let variants: Vec<&str> = todo.iter().map(|(v, _, _)| v.as_str()).collect();
    if let Some((a, b)) = crate::ids::number_clash(&variants) {
        return Err(ExportError::Message(format!(
            "the variants `{a}` and `{b}` have the same number in COCO image ids (a hash of their names)\nhint: export them with `--variant` into separate folders, or rename one"
        )));
    }
    // The dataset's one id table: the categories and attribute names of every file, and
    // `OUT/ids.json`.
    let mut tables = IdTables::of_dataset(dir).map_err(ExportError::Message)?;
    std::fs::create_dir_all(out).map_err(io_err(format!("cannot create `{}`", out.display())))?;
    let mut files = Vec::new();
    for (variant, list, _) in &todo {
        let images: Vec<Result<Image, String>> = list
            .par_iter()
            .map(|s| {
                if stop.load(Ordering::SeqCst) {
                    return Err(ExportError::Interrupted);
                }
                image(&ds, dir, out, variant, s, opts.copy_images)
            })
            .collect::<Result<_, _>>()?;
        let mut by_split: Vec<Vec<Image>> = vec![Vec::new(), Vec::new(), Vec::new()];
        for im in images {
            let im = match im {
                Ok(im) => im,
                Err(why) => {
                    skipped.push(why);
                    continue;
                }
            };
            let at = Split::ALL
                .iter()
                .position(|x| *x == im.split)
                .expect("a split");
            by_split[at].push(im);
        }
        for (split, of_split) in Split::ALL.into_iter().zip(by_split) {
            if of_split.is_empty() {
                continue;
            }
            if stop.load(Ordering::SeqCst) {
                return Err(ExportError::Interrupted);
            }
            for im in &of_split {
                if let Some((from, to)) = &im.image {
                    copy_image(&ds, from, to)?;
                }
            }
            let path = out.join(format!("{variant}-{}.json", split.name()));
            let (doc, n_img, n_ann) = document(dir, variant, split, of_split, &mut tables);
            write_json(&path, &doc)
                .map_err(io_err(format!("cannot write `{}`", path.display())))?;
            files.push((path, n_img, n_ann));
        }
    }
    let ids_path = out.join("ids.json");
    write_json(&ids_path, &tables.to_json(&variants))
        .map_err(io_err(format!("cannot write `{}`", ids_path.display())))?;
    Ok(CocoReport { files, skipped })
}

/// The image entry and object annotations of sample `s` of `variant`: its metadata and mask read through
/// the dataset reader. The inner `Err` says why the sample is left out (a pass failing the
/// checks of every reader).
fn image(
    ds: &Dataset,
    dir: &Path,
    out: &Path,
    variant: &str,
    s: &Sample,
    copy: bool,
) -> Result<Result<Image, String>, ExportError> {
    let file = |key: &str| s.files.iter().find(|f| f.key == key).map(|f| &f.path);
    let need = |key: &str, pass: &str| {
        file(key).ok_or_else(|| {
            ExportError::Message(format!(
                "sample `{}` has no {pass} pass: a COCO export needs the image and the mask\nhint: generate with `--passes` including rgb and mask",
                s.stem
            ))
        })
    };
    let (rgb, mask, meta_path) = (
        need("png", "rgb")?,
        need("mask.npy", "mask")?,
        need("json", "metadata")?,
    );
    let read = |p: &Path| {
        ds.read(p, dataset::MAX_FILE_BYTES).map_err(|why| {
            ExportError::Message(format!(
                "`{}` {why}\nhint: check the dataset with `clevrtex verify`",
                p.display()
            ))
        })
    };
    let bad = |p: &Path, why: String| {
        ExportError::Message(format!(
            "`{}` {why}\nhint: check the dataset with `clevrtex verify`",
            p.display()
        ))
    };
    let meta: Value =
        serde_json::from_slice(&read(meta_path)?).map_err(|cause| ExportError::Json {
            what: format!("`{}` is not valid metadata", meta_path.display()),
            cause,
        })?;
    // The image and the mask checked as every export checks its passes (the shards' one
    // check, [`crate::export::PassCheck::check`]): a sample failing it is left out, named.
    let mut check = s.check;
    let refused = |why: String| format!("{why} (sample `{}` left out)", s.stem);
    if let Err(why) = check.check(&rgb.display().to_string(), &read(rgb)?, Pass::Rgb) {
        return Ok(Err(refused(why)));
    }
    let png = match check.check(&mask.display().to_string(), &read(mask)?, Pass::Mask) {
        Ok(png) => png,
        Err(why) => return Ok(Err(refused(why))),
    };
    if png.bits != 8 || png.channels != 1 {
        return Err(bad(
            mask,
            format!(
                "is a {}-bit {}-channel PNG, not the 8-bit 1-channel mask",
                png.bits, png.channels
            ),
        ));
    }
    let objects = meta["objects"].as_array().map(Vec::as_slice).unwrap_or(&[]);
    let n = objects.len();
    if let Some(&max) = png.data.iter().max() {
        if usize::from(max) > n {
            return Err(bad(
                mask,
                format!("holds id {max} but its metadata lists {n} objects"),
            ));
        }
    }
    let (w, h) = (png.width as usize, png.height as usize);
    let runs = rle::object_runs(&png.data, w, h, n);
    let mut objs = Vec::new();
    for (i, (obj, r)) in objects.iter().zip(runs).enumerate() {
        let Some(r) = r else { continue };
        let shape = obj["shape"].as_str().ok_or_else(|| {
            bad(
                meta_path,
                format!("key `objects[{i}].shape` is not a string"),
            )
        })?;
        let mut attributes = obj.as_object().cloned().unwrap_or_default();
        attributes.remove("shape");
        // The box and pixels the mask gives (verify checks the metadata's against it).
        let [x0, y0, x1, y1] = r.extent;
        attributes.insert("bbox".into(), json!([x0, y0, x1, y1]));
        attributes.insert("visible_pixels".into(), json!(r.area));
        objs.push(Object {
            index: i,
            shape: shape.to_string(),
            counts: rle::compress(&r.counts),
            area: r.area,
            extent: r.extent,
            attributes: Value::Object(attributes),
        });
    }
    let (file_name, image) = if copy {
        let name = format!("images/{}.png", s.stem);
        (name.clone(), Some((rgb.clone(), out.join(name))))
    } else {
        let rel = rgb.strip_prefix(dir).unwrap_or(rgb);
        (ds.root.join(rel).display().to_string(), None)
    };
    Ok(Ok(Image {
        split: s.split,
        entry: json!({
            "id": crate::ids::coco_image_id(variant, s.index),
            "file_name": file_name,
            "width": w,
            "height": h,
            "stem": s.stem,
            "variant": variant,
            "index": s.index,
            "split": s.split.name(),
            "ground_material": meta["ground_material"],
        }),
        objects: objs,
        image,
    }))
}

/// `doc` written as `path`, streamed through an atomic file (nothing left on an error).
fn write_json(path: &Path, doc: &Value) -> std::io::Result<()> {
    use std::io::Write;
    let mut w =
        std::io::BufWriter::with_capacity(1 << 20, crate::atomic::AtomicFile::create(path)?);
    serde_json::to_writer(&mut w, doc)?;
    w.write_all(b"\n")?;
    w.into_inner().map_err(|e| e.into_error())?.commit()
}

/// The image `from` of the dataset copied to `to` (written atomically; folders made).
fn copy_image(ds: &Dataset, from: &Path, to: &Path) -> Result<(), ExportError> {
    let bytes = ds.read(from, dataset::MAX_FILE_BYTES).map_err(|why| {
        ExportError::Message(format!(
            "`{}` {why}\nhint: check the dataset with `clevrtex verify`",
            from.display()
        ))
    })?;
    if let Some(parent) = to.parent() {
        std::fs::create_dir_all(parent)
            .map_err(io_err(format!("cannot create `{}`", parent.display())))?;
    }
    crate::atomic::write(to, &bytes).map_err(io_err(format!("cannot write `{}`", to.display())))
}

/// The COCO document of one variant's split: images, annotations, categories (the dataset's
/// shapes, [`crate::ids`]: `category_id` = shape id + 1; a shape outside the table, of a
/// dataset someone else made, is added to it, sorted), and what the ids and attributes mean.
/// Image and annotation ids are unique across the variants of a dataset
/// ([`crate::ids::coco_image_id`]). Returns it with its image and annotation counts.
fn document(
    dir: &Path,
    variant: &str,
    split: Split,
    images: Vec<Image>,
    tables: &mut IdTables,
) -> (Value, usize, usize) {
    let mut extra: Vec<&String> = images
        .iter()
        .flat_map(|im| im.objects.iter().map(|o| &o.shape))
        .filter(|s| tables.id("shape", s).is_none())
        .collect();
    extra.sort();
    extra.dedup();
    for s in extra {
        tables.id_or_add("shape", s);
    }
    let category = |s: &str| tables.id("shape", s).expect("listed") + 1;
    let n_img = images.len();
    let mut annotations = Vec::new();
    let mut entries = Vec::with_capacity(n_img);
    for im in images {
        let (h, w) = (im.entry["height"].clone(), im.entry["width"].clone());
        for o in im.objects {
            let [x0, y0, x1, y1] = o.extent;
            let image_id = im.entry["id"].as_u64().expect("an image id");
            annotations.push(json!({
                "id": crate::ids::coco_annotation_id(image_id, o.index),
                "image_id": im.entry["id"],
                "category_id": category(&o.shape),
                "segmentation": {"size": [h, w], "counts": o.counts},
                "area": o.area,
                "bbox": [x0, y0, x1 - x0 + 1, y1 - y0 + 1],
                "iscrowd": 0,
                "object_index": o.index,
                "attributes": o.attributes,
            }));
        }
        entries.push(im.entry);
    }
    let n_ann = annotations.len();
    let names = json!({
        "size": tables.size,
        "material": tables.material,
        "color": tables.color,
    });
    let doc = json!({
        "info": {
            "description": format!("ClevrTex `{variant}`, split `{}`, exported by clevrtex {}", split.name(), env!("CARGO_PKG_VERSION")),
            "version": env!("CARGO_PKG_VERSION"),
            "source": dir.display().to_string(),
            "variant": variant,
            "split": split.name(),
            "attribute_names": names,
            "ids": "ids.json: the dataset's one id table; image id = variant number * 10^8 + index, annotation id = image id * 1000 + object index + 1",
        },
        "licenses": [],
        "images": entries,
        "annotations": annotations,
        "categories": tables.shape.iter().enumerate().map(|(i, s)| json!({"id": i + 1, "name": s, "supercategory": "shape"})).collect::<Vec<_>>(),
    });
    (doc, n_img, n_ann)
}
