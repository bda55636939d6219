//! Validation and resolution of material files against `materials/blocks.json`.
//!
//! Resolution fills every default and converts sRGB hex colours to linear floats, so the
//! bridge reads complete recipes and holds no defaults of its own.

use std::path::Path;

use serde_json::{Map, Value};

use crate::error::{Error, ErrorKind};

/// The parsed `blocks.json`.
pub(crate) struct Schema {
    material: Map<String, Value>,
    surface: Map<String, Value>,
    layer: Map<String, Value>,
    blocks: Map<String, Value>,
}

/// Graph-link sources that are not nodes.
const SOURCES: &[&str] = &["coord", "random", "normal"];
/// Graph-link sinks.
const SINKS: &[&str] = &["out.fac", "out.height", "out.mask", "out.gap", "out.color"];

impl Schema {
    pub(crate) fn parse(text: &str) -> Result<Schema, Error> {
        let v: Value = serde_json::from_str(text).map_err(|e| {
            Error::new(
                ErrorKind::Json,
                "blocks.json",
                "",
                format!("invalid json: {e}"),
                "fix the block schema in `materials/blocks.json`",
            )
        })?;
        let get = |k: &str| -> Result<Map<String, Value>, Error> {
            v.get(k).and_then(Value::as_object).cloned().ok_or_else(|| {
                Error::new(
                    ErrorKind::MissingField,
                    "blocks.json",
                    k,
                    "missing object",
                    "restore the section in `materials/blocks.json`",
                )
            })
        };
        Ok(Schema {
            material: get("material")?,
            surface: get("surface")?,
            layer: get("layer")?,
            blocks: get("blocks")?,
        })
    }

    /// Names of every block, sorted.
    pub(crate) fn block_names(&self) -> Vec<String> {
        self.blocks.keys().cloned().collect()
    }

    /// Validate a material file's JSON and return the resolved recipe.
    pub(crate) fn resolve(
        &self,
        file: &str,
        v: &Value,
        base_dir: Option<&Path>,
    ) -> Result<Value, Error> {
        let ctx = Ctx { file, base_dir };
        let obj = v.as_object().ok_or_else(|| {
            ctx.err(
                ErrorKind::BadValue,
                "",
                "expected a json object",
                "a material file is `{\"description\": ..., \"layers\": [...]}`",
            )
        })?;
        if obj.contains_key("blend") {
            return self.resolve_blend(&ctx, obj);
        }
        let mut out = Map::new();
        out.insert("kind".into(), "layers".into());
        for key in obj.keys() {
            if !self.material.contains_key(key) {
                return Err(ctx.unknown(key, key, &self.material));
            }
        }
        for (key, spec) in &self.material {
            let val = match key.as_str() {
                "layers" => self.resolve_layers(&ctx, obj.get("layers"))?,
                "surface" => {
                    let empty = Value::Object(Map::new());
                    let s = obj.get("surface").unwrap_or(&empty);
                    ctx.resolve_fields("surface", s, &self.surface)?
                }
                _ => ctx.resolve_value(key, obj.get(key), spec)?,
            };
            out.insert(key.clone(), val);
        }
        Ok(Value::Object(out))
    }

    fn resolve_blend(&self, ctx: &Ctx<'_>, obj: &Map<String, Value>) -> Result<Value, Error> {
        let allowed = ["description", "blend", "group", "displaces", "tint"];
        for key in obj.keys() {
            if !allowed.contains(&key.as_str()) {
                return Err(ctx.err(
                    ErrorKind::UnknownField,
                    key,
                    format!("unknown field `{key}` of a `.blend` material"),
                    format!("allowed fields: {}", allowed.join(", ")),
                ));
            }
        }
        let mut out = Map::new();
        out.insert("kind".into(), "blend".into());
        let desc = obj
            .get("description")
            .and_then(Value::as_str)
            .unwrap_or("user node group");
        out.insert("description".into(), desc.into());
        let path = ctx.resolve_path("blend", obj.get("blend"))?;
        if let Some(problem) =
            crate::blend_file_problem(std::path::Path::new(path.as_str().unwrap_or("")))
        {
            return Err(ctx.err(
                ErrorKind::BadValue,
                "blend",
                problem,
                "save the node group from Blender (File > Save) and point `blend` at that file",
            ));
        }
        out.insert("path".into(), path);
        let group = match obj.get("group") {
            None | Some(Value::Null) => Value::Null,
            Some(Value::String(s)) => Value::String(s.clone()),
            Some(_) => {
                return Err(ctx.err(
                    ErrorKind::BadValue,
                    "group",
                    "expected a string",
                    "name the node group inside the `.blend` file",
                ))
            }
        };
        out.insert("group".into(), group);
        let displaces = match obj.get("displaces") {
            None => true,
            Some(Value::Bool(b)) => *b,
            Some(_) => {
                return Err(ctx.err(
                    ErrorKind::BadValue,
                    "displaces",
                    "expected true or false",
                    "set `displaces` to a boolean",
                ))
            }
        };
        out.insert("displaces".into(), displaces.into());
        out.insert("tint".into(), "none".into());
        Ok(Value::Object(out))
    }

    fn resolve_layers(&self, ctx: &Ctx<'_>, v: Option<&Value>) -> Result<Value, Error> {
        let Some(v) = v else {
            return Err(ctx.err(
                ErrorKind::MissingField,
                "layers",
                "missing field `layers`",
                "add `\"layers\": [{\"block\": \"noise\", ...}]`",
            ));
        };
        let arr = v.as_array().filter(|a| !a.is_empty()).ok_or_else(|| {
            ctx.err(
                ErrorKind::BadValue,
                "layers",
                "expected a non-empty array of layers",
                "add at least one layer such as `{\"block\": \"solid\"}`",
            )
        })?;
        let mut out = Vec::new();
        for (i, layer) in arr.iter().enumerate() {
            let path = format!("layers[{i}]");
            let obj = layer.as_object().ok_or_else(|| {
                ctx.err(
                    ErrorKind::BadValue,
                    &path,
                    "expected an object",
                    "a layer is `{\"block\": \"<name>\", ...parameters}`",
                )
            })?;
            let block = match obj.get("block") {
                Some(Value::String(s)) => s.clone(),
                Some(_) => {
                    return Err(ctx.err(
                        ErrorKind::BadValue,
                        &format!("{path}.block"),
                        "expected a block name",
                        self.blocks_hint(),
                    ))
                }
                None => {
                    return Err(ctx.err(
                        ErrorKind::MissingField,
                        &format!("{path}.block"),
                        "missing field `block`",
                        self.blocks_hint(),
                    ))
                }
            };
            let spec = self.blocks.get(&block).ok_or_else(|| {
                ctx.err(
                    ErrorKind::UnknownBlock,
                    &format!("{path}.block"),
                    format!("unknown block `{block}`"),
                    self.blocks_hint(),
                )
            })?;
            let params = spec
                .get("params")
                .and_then(Value::as_object)
                .cloned()
                .unwrap_or_default();
            let mut all = self.layer.clone();
            all.extend(params);
            let mut rest = obj.clone();
            rest.remove("block");
            let mut resolved = match ctx.resolve_fields(&path, &Value::Object(rest), &all)? {
                Value::Object(m) => m,
                _ => unreachable!("resolve_fields returns an object"),
            };
            if block == "graph" {
                check_graph(ctx, &path, &resolved)?;
            }
            resolved.insert("block".into(), block.into());
            out.push(Value::Object(resolved));
        }
        Ok(Value::Array(out))
    }

    fn blocks_hint(&self) -> String {
        format!(
            "use one of: {}",
            self.block_names()
                .iter()
                .map(|b| format!("`{b}`"))
                .collect::<Vec<_>>()
                .join(", ")
        )
    }
}

fn check_graph(ctx: &Ctx<'_>, path: &str, layer: &Map<String, Value>) -> Result<(), Error> {
    let nodes = layer["nodes"].as_object().expect("validated as nodes");
    let links = layer["links"].as_array().expect("validated as links");
    let endpoint_ok = |s: &str, is_source: bool| -> bool {
        if is_source && SOURCES.contains(&s) {
            return true;
        }
        if !is_source && SINKS.contains(&s) {
            return true;
        }
        match s.split_once('.') {
            Some((node, socket)) => nodes.contains_key(node) && !socket.is_empty(),
            None => false,
        }
    };
    for (i, link) in links.iter().enumerate() {
        let pair = link.as_array().expect("validated as links");
        for (j, is_source) in [(0, true), (1, false)] {
            let s = pair[j].as_str().expect("validated as links");
            if !endpoint_ok(s, is_source) {
                let valid = if is_source {
                    format!("`node.Socket` with a node of `nodes`, or one of {SOURCES:?}")
                } else {
                    format!("`node.Socket` with a node of `nodes`, or one of {SINKS:?}")
                };
                return Err(ctx.err(
                    ErrorKind::DanglingLink,
                    &format!("{path}.links[{i}][{j}]"),
                    format!("link endpoint `{s}` names no node or terminal"),
                    format!("use {valid}"),
                ));
            }
        }
    }
    Ok(())
}

struct Ctx<'a> {
    file: &'a str,
    base_dir: Option<&'a Path>,
}

impl Ctx<'_> {
    fn err(
        &self,
        kind: ErrorKind,
        field: &str,
        msg: impl Into<String>,
        hint: impl Into<String>,
    ) -> Error {
        Error::new(kind, self.file, field, msg, hint)
    }

    fn unknown(&self, field: &str, key: &str, known: &Map<String, Value>) -> Error {
        self.err(
            ErrorKind::UnknownField,
            field,
            format!("unknown field `{key}`"),
            format!(
                "known fields here: {}",
                known.keys().cloned().collect::<Vec<_>>().join(", ")
            ),
        )
    }

    /// Check an object against a field table and fill defaults.
    fn resolve_fields(
        &self,
        path: &str,
        v: &Value,
        table: &Map<String, Value>,
    ) -> Result<Value, Error> {
        let obj = v.as_object().ok_or_else(|| {
            self.err(
                ErrorKind::BadValue,
                path,
                "expected an object",
                "write this field as a json object",
            )
        })?;
        for key in obj.keys() {
            if !table.contains_key(key) {
                return Err(self.unknown(&format!("{path}.{key}"), key, table));
            }
        }
        let mut out = Map::new();
        for (key, spec) in table {
            let field = format!("{path}.{key}");
            out.insert(key.clone(), self.resolve_value(&field, obj.get(key), spec)?);
        }
        Ok(Value::Object(out))
    }

    fn resolve_value(&self, field: &str, v: Option<&Value>, spec: &Value) -> Result<Value, Error> {
        let ty = spec["type"].as_str().unwrap_or("");
        let required = spec["required"].as_bool().unwrap_or(false);
        let v = match v {
            Some(v) => v,
            None if required => {
                return Err(self.err(
                    ErrorKind::MissingField,
                    field,
                    format!("missing required field `{}`", last(field)),
                    format!("add it: {}", spec["doc"].as_str().unwrap_or(ty)),
                ))
            }
            None => match spec.get("default") {
                Some(d) => d,
                None => return Ok(Value::Null),
            },
        };
        let min = spec["min"].as_f64();
        let max = spec["max"].as_f64();
        let bad = |what: &str| {
            self.err(
                ErrorKind::BadValue,
                field,
                format!("expected {what}, found `{v}`"),
                format!(
                    "give {what}{}",
                    spec["doc"]
                        .as_str()
                        .map(|d| format!(" ({d})"))
                        .unwrap_or_default()
                ),
            )
        };
        let number = |x: &Value| -> Result<f64, Error> {
            let n = x.as_f64().ok_or_else(|| bad("a number"))?;
            if min.is_some_and(|m| n < m) || max.is_some_and(|m| n > m) || !n.is_finite() {
                return Err(self.err(
                    ErrorKind::BadValue,
                    field,
                    format!("value `{n}` is out of range"),
                    format!(
                        "use a number in [{}, {}]",
                        min.map_or("-inf".into(), |m| m.to_string()),
                        max.map_or("inf".into(), |m| m.to_string())
                    ),
                ));
            }
            Ok(n)
        };
        Ok(match ty {
            "number" => number(v)?.into(),
            "string" => v.as_str().ok_or_else(|| bad("a string"))?.into(),
            "bool" => v.as_bool().ok_or_else(|| bad("true or false"))?.into(),
            "enum" => {
                let values: Vec<&str> = spec["values"]
                    .as_array()
                    .map(|a| a.iter().filter_map(Value::as_str).collect())
                    .unwrap_or_default();
                let s = v.as_str().filter(|s| values.contains(s));
                s.ok_or_else(|| bad(&format!("one of {values:?}")))?.into()
            }
            "range" | "vec3" => {
                let n = if ty == "range" { 2 } else { 3 };
                let arr = v
                    .as_array()
                    .filter(|a| a.len() == n)
                    .ok_or_else(|| bad(&format!("an array of {n} numbers")))?;
                let nums = arr.iter().map(number).collect::<Result<Vec<_>, _>>()?;
                Value::from(nums)
            }
            "color" => Value::from(
                parse_color(v)
                    .ok_or_else(|| bad("an sRGB colour like \"#8a3a2a\""))?
                    .to_vec(),
            ),
            "colors" => {
                let arr = v
                    .as_array()
                    .filter(|a| !a.is_empty() && a.len() <= 16)
                    .ok_or_else(|| bad("an array of 1 to 16 sRGB colours"))?;
                let mut out = Vec::new();
                for (i, c) in arr.iter().enumerate() {
                    let lin = parse_color(c).ok_or_else(|| {
                        self.err(
                            ErrorKind::BadValue,
                            &format!("{field}[{i}]"),
                            format!("expected an sRGB colour like \"#8a3a2a\", found `{c}`"),
                            "write colours as `#rrggbb` hex strings",
                        )
                    })?;
                    out.push(Value::from(lin.to_vec()));
                }
                Value::Array(out)
            }
            "path" => self.resolve_path(field, Some(v))?,
            "nodes" => {
                let obj = v.as_object().ok_or_else(|| bad("an object of nodes"))?;
                for (name, node) in obj {
                    let f = format!("{field}.{name}");
                    if SOURCES.contains(&name.as_str()) || name == "out" || name.contains('.') {
                        return Err(self.err(
                            ErrorKind::BadValue,
                            &f,
                            format!("node name `{name}` is reserved or contains `.`"),
                            "rename the node",
                        ));
                    }
                    let n = node.as_object().ok_or_else(|| bad("node objects"))?;
                    for k in n.keys() {
                        if !["type", "inputs", "props"].contains(&k.as_str()) {
                            return Err(self.err(
                                ErrorKind::UnknownField,
                                &format!("{f}.{k}"),
                                format!("unknown field `{k}` of a node"),
                                "a node has `type`, `inputs` and `props`",
                            ));
                        }
                    }
                    let t = n.get("type").and_then(Value::as_str).unwrap_or("");
                    if !t.starts_with("ShaderNode") || t.len() <= "ShaderNode".len() {
                        return Err(self.err(
                            ErrorKind::BadValue,
                            &format!("{f}.type"),
                            format!("unknown node type `{t}`"),
                            "use a Blender shader node idname such as `ShaderNodeTexNoise`",
                        ));
                    }
                    for k in ["inputs", "props"] {
                        if n.get(k).is_some_and(|x| !x.is_object()) {
                            return Err(self.err(
                                ErrorKind::BadValue,
                                &format!("{f}.{k}"),
                                "expected an object",
                                "map socket or property names to values",
                            ));
                        }
                    }
                }
                v.clone()
            }
            "links" => {
                let arr = v.as_array().ok_or_else(|| bad("an array of links"))?;
                for (i, l) in arr.iter().enumerate() {
                    let ok = l
                        .as_array()
                        .is_some_and(|p| p.len() == 2 && p.iter().all(Value::is_string));
                    if !ok {
                        return Err(self.err(
                            ErrorKind::BadValue,
                            &format!("{field}[{i}]"),
                            format!("expected a [from, to] pair of strings, found `{l}`"),
                            "write links as [\"noise.Fac\", \"out.fac\"]",
                        ));
                    }
                }
                v.clone()
            }
            other => unreachable!("blocks.json uses unknown type `{other}`"),
        })
    }

    fn resolve_path(&self, field: &str, v: Option<&Value>) -> Result<Value, Error> {
        let Some(s) = v.and_then(Value::as_str) else {
            return Err(self.err(
                ErrorKind::MissingField,
                field,
                "expected a file path",
                "give a path relative to the material file",
            ));
        };
        let Some(base) = self.base_dir else {
            return Err(self.err(
                ErrorKind::BadValue,
                field,
                format!("built-in materials cannot reference files (`{s}`)"),
                "put image and `.blend` materials in a `--materials DIR`",
            ));
        };
        let p = base.join(s);
        // Its bytes are checked before a run (`render/src/user_materials/copies.rs`); here only whether
        // it is a file at all, said as it is (a FIFO or device is not "missing").
        let problem = match std::fs::metadata(&p) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Some("does not exist".into()),
            Err(e) => Some(format!("cannot be read: {e}")),
            Ok(m) if !m.is_file() => {
                Some("is not a regular file (a folder, FIFO or device)".into())
            }
            Ok(_) => None,
        };
        if let Some(problem) = problem {
            return Err(self.err(
                ErrorKind::BadValue,
                field,
                format!("file `{}` {problem}", p.display()),
                "give the path of a file inside the material folder, relative to the material file",
            ));
        }
        let abs = p.canonicalize().unwrap_or(p);
        Ok(abs.to_string_lossy().into_owned().into())
    }
}

fn last(field: &str) -> &str {
    field.rsplit('.').next().unwrap_or(field)
}

/// `"#rrggbb"` (sRGB) to linear RGB.
pub(crate) fn parse_color(v: &Value) -> Option<[f64; 3]> {
    let s = v.as_str()?.strip_prefix('#')?;
    if s.len() != 6 || !s.is_ascii() {
        return None;
    }
    let mut out = [0.0; 3];
    for (i, o) in out.iter_mut().enumerate() {
        let lin = crate::srgb_to_linear(u8::from_str_radix(&s[2 * i..2 * i + 2], 16).ok()?);
        *o = (lin * 1e5).round() / 1e5;
    }
    Some(out)
}
