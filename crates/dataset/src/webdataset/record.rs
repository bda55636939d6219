//! What a shard holds besides the passes: the sample's `json` in one schema for every variant
//! ([`record`]), and with `--objects K` the per-object arrays padded to `K` ([`object_arrays`],
//! ids into the dataset's one id table [`crate::ids::IdTables`]).
//!
//! One schema: Hugging Face `datasets` infers a shard set's types from its first samples and
//! casts every other sample to them, so a key that is `null` in one variant and a string in
//! another (`objects[i].color` on `camo` and `clevr`), or present in one and absent in another,
//! fails the load. The record has the same keys with the same types in every sample: a value
//! a sample lacks is the empty string, the empty list or -1; the metadata file itself is kept,
//! byte for byte, as a string under `metadata`.

use serde_json::{json, Value};

use super::{npy_header, Frame};
use crate::ids::{IdTables, TABLES};
use crate::layout::Split;

/// The shard's `json` of a sample (of `variant`, split `split`, index `index`, stem `stem`)
/// whose metadata file holds `bytes` (already checked to be JSON by the export's reader);
/// `intrinsics` and the objects' `pixel_coords` in the crop's `frame` when cropped (as the
/// Python `Dataset` gives them), the `metadata` text as it is.
pub fn record(
    bytes: &[u8],
    variant: &str,
    split: Split,
    index: u64,
    stem: &str,
    frame: Option<Frame>,
) -> Vec<u8> {
    let meta: Value = serde_json::from_slice(bytes).unwrap_or(Value::Null);
    let f = frame.unwrap_or(Frame {
        x0: 0.0,
        y0: 0.0,
        scale: 1.0,
    });
    let to_frame = |mut p: Vec<f64>| {
        if p.len() == 3 {
            p[0] = (p[0] - f.x0) * f.scale;
            p[1] = (p[1] - f.y0) * f.scale;
        }
        p
    };
    let text = |v: &Value| v.as_str().unwrap_or("").to_string();
    let num = |v: &Value| v.as_f64().filter(|x| x.is_finite()).unwrap_or(f64::NAN);
    let nums = |v: &Value, n: usize| -> Vec<f64> {
        match v.as_array() {
            Some(a) if a.len() == n => a.iter().map(num).collect(),
            _ => Vec::new(),
        }
    };
    let matrix = |v: &Value, n: usize| -> Vec<Vec<f64>> {
        match v.as_array() {
            Some(rows) if rows.len() == n => rows.iter().map(|r| nums(r, n)).collect(),
            _ => Vec::new(),
        }
    };
    let objects: Vec<Value> = meta["objects"]
        .as_array()
        .map(Vec::as_slice)
        .unwrap_or(&[])
        .iter()
        .map(|o| {
            json!({
                "shape": text(&o["shape"]),
                "size": text(&o["size"]),
                "material": text(&o["material"]),
                "color": text(&o["color"]),
                "rotation": num(&o["rotation"]),
                "coords_3d": nums(&o["3d_coords"], 3),
                "pixel_coords": to_frame(nums(&o["pixel_coords"], 3)),
                "visible_pixels": o["visible_pixels"].as_i64().unwrap_or(-1),
                "bbox": o["bbox"].as_array().map(|b| b.iter().map(|x| x.as_i64().unwrap_or(-1)).collect()).unwrap_or_else(Vec::new),
            })
        })
        .collect();
    let doc = json!({
        "stem": stem,
        "variant": variant,
        "split": split.name(),
        "index": index,
        "num_objects": objects.len(),
        "ground_material": text(&meta["ground_material"]),
        "objects": objects,
        "intrinsics": intrinsics(matrix(&meta["camera"]["intrinsics"], 3), f),
        "extrinsics": matrix(&meta["camera"]["extrinsics"], 4),
        "metadata": String::from_utf8_lossy(bytes),
    });
    // NaN is not JSON: a number a sample lacks is written as null by serde_json; there is none
    // in a checked sample of ours (rotation and coordinates are always numbers).
    serde_json::to_vec(&doc).expect("JSON values serialise")
}

/// `K` of the full image as the crop's `frame` sees it: `[[s, 0, -x0 s], [0, s, -y0 s], [0, 0,
/// 1]] @ K` (empty stays empty).
fn intrinsics(k: Vec<Vec<f64>>, f: Frame) -> Vec<Vec<f64>> {
    if k.len() != 3 || k.iter().any(|r| r.len() != 3) {
        return k;
    }
    let row = |i: usize| -> Vec<f64> {
        (0..3)
            .map(|j| match i {
                0 => f.scale * k[0][j] - f.x0 * f.scale * k[2][j],
                1 => f.scale * k[1][j] - f.y0 * f.scale * k[2][j],
                _ => k[2][j],
            })
            .collect()
    };
    vec![row(0), row(1), row(2)]
}

/// The per-object arrays of a sample with metadata `meta` and mask ids `mask` (`width` x
/// `height`, row-major), padded to `k`: `(key, .npy bytes)` for `shape.npy`, `size.npy`,
/// `material.npy`, `color.npy` (int64 (K,) ids, -1 for padding and a colour the variant does
/// not have), `bbox.npy` (float32 (K, 4), `[x_min, y_min, x_max, y_max]` inclusive in the
/// mask, 0 where not visible), `visibility.npy` (bool (K,): the object has a pixel in the mask)
/// and `valid.npy` (bool (K,): slot `k` holds an object). `Err` when the sample has more than
/// `k` objects, or its mask an id over its objects.
pub fn object_arrays(
    meta: &Value,
    mask: &[u16],
    width: usize,
    k: usize,
    tables: &mut IdTables,
) -> Result<Vec<(String, Vec<u8>)>, String> {
    let objects = meta["objects"].as_array().map(Vec::as_slice).unwrap_or(&[]);
    let n = objects.len();
    if n > k {
        return Err(format!(
            "has {n} objects, more than `--objects {k}`\nhint: give a larger `--objects`"
        ));
    }
    let mut ids = [vec![-1i64; k], vec![-1; k], vec![-1; k], vec![-1; k]];
    for (i, o) in objects.iter().enumerate() {
        for (t, table) in TABLES.iter().enumerate() {
            if let Some(name) = o[*table].as_str() {
                ids[t][i] = tables.id_or_add(table, name) as i64;
            }
        }
    }
    let mut boxes = vec![[u32::MAX, u32::MAX, 0, 0]; k];
    let mut seen = vec![false; k];
    for (p, &id) in mask.iter().enumerate() {
        if id == 0 {
            continue;
        }
        let i = usize::from(id) - 1;
        if i >= n {
            return Err(format!(
                "has a mask holding id {id} but its metadata lists {n} objects"
            ));
        }
        let (x, y) = ((p % width) as u32, (p / width) as u32);
        let b = &mut boxes[i];
        *b = [b[0].min(x), b[1].min(y), b[2].max(x), b[3].max(y)];
        seen[i] = true;
    }
    let mut out = Vec::new();
    for (t, table) in TABLES.iter().enumerate() {
        let mut a = npy_header("<i8", &[k]);
        for v in &ids[t] {
            a.extend(v.to_le_bytes());
        }
        out.push((format!("{table}.npy"), a));
    }
    let mut a = npy_header("<f4", &[k, 4]);
    for (b, s) in boxes.iter().zip(&seen) {
        for v in b {
            a.extend((if *s { *v as f32 } else { 0.0 }).to_le_bytes());
        }
    }
    out.push(("bbox.npy".into(), a));
    let bools = |v: Vec<bool>| {
        let mut a = npy_header("|b1", &[k]);
        a.extend(v.into_iter().map(u8::from));
        a
    };
    out.push(("visibility.npy".into(), bools(seen)));
    out.push(("valid.npy".into(), bools((0..k).map(|i| i < n).collect())));
    Ok(out)
}
