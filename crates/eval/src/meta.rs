//! The per-sample metadata `.json`: only what the per-object breakdown needs, after the
//! dataset reader's check (`clevrtex_dataset::dataset::check_metadata`: ours whole, the
//! downloaded ClevrTex's `objects` a list that `num_objects` counts). Unknown keys are ignored
//! and names of unexpected types are kept as their JSON text.

use serde::Deserialize;
use serde_json::Value;

/// The fields of one metadata object used by the breakdowns.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ObjectMeta {
    /// Material name.
    pub material: Option<String>,
    /// Shape name.
    pub shape: Option<String>,
    /// Size name (`large`, `medium`, `small`).
    pub size: Option<String>,
    /// Colour name (meaningful in `vbg` only).
    pub color: Option<String>,
}

/// The fields of a sample's metadata used by the breakdowns.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SampleMeta {
    /// Material of the ground (the background).
    pub ground_material: Option<String>,
    /// Objects in mask-label order (object `i` has label `i + 1`).
    pub objects: Vec<ObjectMeta>,
    /// How many objects the metadata says the mask holds (its `objects` list, checked
    /// against `num_objects`), when it says.
    pub num_objects: Option<usize>,
}

#[derive(Deserialize)]
struct RawMeta {
    #[serde(default)]
    ground_material: Value,
    #[serde(default)]
    objects: Value,
}

fn text(v: Option<&Value>) -> Option<String> {
    match v? {
        Value::Null => None,
        Value::String(s) => Some(s.clone()),
        other => Some(other.to_string()),
    }
}

/// Parse a metadata file's bytes.
pub fn parse(bytes: &[u8]) -> Result<SampleMeta, String> {
    let value: Value =
        serde_json::from_slice(bytes).map_err(|e| format!("not valid metadata JSON ({e})"))?;
    if !value.is_object() {
        return Err("metadata must be a JSON object".into());
    }
    // The check every reader of a dataset applies (preview, report, export, the Python
    // `Dataset`): ours must be whole, the downloaded ClevrTex's typed where it has keys.
    clevrtex_dataset::dataset::check_metadata(&value, "")
        .map_err(|e| format!("key `{}` {}", e.key, e.what))?;
    let num_objects = value["objects"]
        .as_array()
        .map(Vec::len)
        .or_else(|| value["num_objects"].as_u64().map(|n| n as usize));
    let raw: RawMeta =
        serde_json::from_value(value).map_err(|e| format!("not valid metadata JSON ({e})"))?;
    let objects = match raw.objects {
        Value::Null => Vec::new(),
        Value::Array(items) => items
            .iter()
            .map(|o| ObjectMeta {
                material: text(o.get("material")),
                shape: text(o.get("shape")),
                size: text(o.get("size")),
                color: text(o.get("color")),
            })
            .collect(),
        _ => return Err("`objects` must be a list".into()),
    };
    Ok(SampleMeta {
        ground_material: text(Some(&raw.ground_material)),
        objects,
        num_objects,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_objects_in_order() {
        let m = parse(br#"{"ground_material":"moss","objects":[{"material":"rope","shape":"cube","size":"large","color":[1,2,3]},{"shape":"sphere"}]}"#).unwrap();
        assert_eq!(m.ground_material.as_deref(), Some("moss"));
        assert_eq!(m.objects.len(), 2);
        assert_eq!(m.objects[0].color.as_deref(), Some("[1,2,3]"));
        assert_eq!(m.objects[1].material, None);
    }

    #[test]
    fn rejects_non_object() {
        assert!(parse(b"[1]").is_err());
        assert!(parse(br#"{"objects": 3}"#).is_err());
    }

    #[test]
    fn rejects_what_the_dataset_reader_rejects() {
        let e = parse(br#"{"num_objects": 2, "objects": [{}]}"#).unwrap_err();
        assert!(
            e.contains("key `objects` has 1 entries but `num_objects` is 2"),
            "{e}"
        );
        // Ours (with `render`) must be whole.
        let e = parse(br#"{"render": {}, "objects": []}"#).unwrap_err();
        assert!(e.starts_with("key `"), "{e}");
    }
}
