//! WebDataset tar shards, as `clevrtex export` writes them: the export of a dataset
//! ([`export`]), the shard names (`<variant>-<split>-<6 digits>.tar`, [`shard_name`],
//! [`is_shard_name`]) and the writer of one shard ([`ShardWriter`]: reproducible headers, a
//! temporary name until complete).
//!
//! `OUT/<variant>-<split>-%06d.tar`, each at most `shard_size` bytes (one sample is never
//! split; a sample larger than the limit gets a shard of its own), samples in index order. In a
//! shard a sample is `<stem>.<key>` for each pass it has, the key and form from the pass
//! table (`webdataset_key`, `webdataset_form`): `png` and `albedo.png` the dataset's PNGs,
//! `mask.npy` (uint8 ids), `depth.npy` (float32 metres, background +inf), `normal.npy` and
//! `shadow.npy` arrays decoded from the PNGs ([`pass_npy`], so no colour decoder can take them
//! for colours), and `<stem>.json`, so WebDataset's key is the stem. Splits are each sample's recorded `split`
//! (else, for the published ClevrTex, the public loader's position rule:
//! [`crate::dataset::splits`], the rule of every reader). The files are those of
//! the layout (`crate::layout`): a metadata `*_filename` only says whether a pass was
//! written and must name the layout's file. Links leading out of the dataset are not followed
//! and non-regular files not read (their samples are left out and listed). Shards of an
//! earlier export into OUT that this one did not write are removed (only names of the form
//! above). Tar headers carry no time, owner or mode of the machine: the same dataset gives the
//! same bytes (and the arrays no machine-dependent byte). Each shard is written under a
//! temporary name and renamed when complete; `OUT/index.json` lists the shards and their
//! sample counts, and what each key holds.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use crate::atomic::AtomicFile;
use crate::dataset::{Dataset, DatasetError, Kind, SampleRef, VariantDir};
use crate::layout::Split;
use clevrtex_scene::passes::WebdatasetForm;
use clevrtex_scene::Pass;
use serde_json::{json, Value};

use crate::dataset;

/// What can go wrong in an export. Shown as the command's error: the message, then (as the
/// error's source) the cause.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// A file or folder could not be read, created, written or removed.
    #[error("{what}")]
    Io {
        /// What failed and what to do.
        what: String,
        /// The OS error.
        #[source]
        cause: std::io::Error,
    },
    /// A sample's metadata is not JSON.
    #[error("{what}")]
    Json {
        /// Which file, and what to do.
        what: String,
        /// The parser's error.
        #[source]
        cause: serde_json::Error,
    },
    /// Anything else, with the file and what to do.
    #[error("{0}")]
    Message(String),
    /// A shard could not be written.
    #[error(transparent)]
    Shard(#[from] ShardError),
    /// The dataset could not be opened.
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// The stop flag was raised (Ctrl-C, SIGTERM): the shard being written was removed.
    #[error("interrupted")]
    Interrupted,
}

/// What [`export`] did.
#[derive(Debug)]
pub struct ExportReport {
    /// Samples written.
    pub samples: u64,
    /// Shards written.
    pub shards: usize,
    /// Bytes of the shards written.
    pub bytes: u64,
    /// `OUT/index.json`.
    pub index: PathBuf,
    /// Shards of an earlier export that this one did not write, removed.
    pub stale: Vec<String>,
    /// Files or folders not followed or not read (their samples are left out), one line each.
    pub skipped: Vec<String>,
}

/// One file of a sample in a shard: its key (the extension after the stem), its path in the
/// dataset, and the pass to decode it as when it becomes a `.npy` (`None`: the file's bytes).
pub type SampleFile = (String, PathBuf, Option<Pass>);

/// One sample to export: its metadata and the files it becomes.
struct Sample {
    index: u64,
    /// Its position among the variant's samples with metadata (for [`dataset::splits`]).
    pos: usize,
    stem: String,
    split: Split,
    files: Vec<SampleFile>,
}

/// The samples of one variant folder of `ds` (found by [`Dataset::open`]), in index order,
/// and what was not followed or not read (samples with such files are left out).
/// File names come from the layout and the pass table, never from the metadata: a
/// `*_filename` key only says whether the pass was written, and must name the layout's file
/// ([`dataset::listed_passes`]).
fn samples(
    ds: &Dataset,
    vd: &VariantDir,
    skipped: &mut Vec<String>,
) -> Result<Vec<Sample>, ExportError> {
    if let Some((dir, e)) = vd.unreadable.first() {
        return Err(ExportError::Message(format!(
            "cannot read `{}`: {e}",
            dir.display()
        )));
    }
    skipped.extend(vd.skipped_for_metadata().map(ToString::to_string));
    let found: BTreeMap<u64, &SampleRef> = vd
        .samples
        .iter()
        .filter(|s| s.has_metadata())
        .map(|s| (s.index, s))
        .collect();
    let mut out = Vec::new();
    let mut recorded = vec![None; found.len()];
    'samples: for (pos, (index, s)) in found.into_iter().enumerate() {
        let stem = s.stem.clone();
        let meta_path = s.metadata_path();
        let bytes = match ds.read(&meta_path, dataset::MAX_METADATA_BYTES) {
            Ok(b) => b,
            Err(why) => {
                skipped.push(format!("`{}` {why}", meta_path.display()));
                continue;
            }
        };
        let meta: Value = serde_json::from_slice(&bytes).map_err(|cause| ExportError::Json {
            what: format!(
                "`{}` is not valid metadata\nhint: check the dataset with `clevrtex verify`",
                meta_path.display()
            ),
            cause,
        })?;
        dataset::check_metadata(&meta, &meta_path.display().to_string()).map_err(|e| {
            ExportError::Message(format!(
                "{e}\nhint: check the dataset with `clevrtex verify`"
            ))
        })?;
        let bad = |e: dataset::MetadataError| {
            ExportError::Message(format!(
                "{e}\nhint: check the dataset with `clevrtex verify`; export takes file names from the layout, not from the metadata"
            ))
        };
        let file = meta_path.display().to_string();
        // Passes whose encoding the metadata describes (ours) become arrays by it; the mask's
        // ids are its pixels in any dataset. The published ClevrTex's other passes (another
        // encoding, not described) stay PNGs under `<pass>.png`.
        let described = dataset::MetadataView::of(&meta, &file)
            .map(|v| v.passes)
            .unwrap_or_default();
        let mut files: Vec<SampleFile> = dataset::listed_passes(&meta, &file, &stem)
            .map_err(bad)?
            .into_iter()
            .map(|pass| {
                let spec = pass.spec();
                match spec.webdataset_form {
                    WebdatasetForm::Npy { .. }
                        if pass == Pass::Mask || described.contains(&pass) =>
                    {
                        (
                            spec.webdataset_key.to_string(),
                            s.pass_path(pass),
                            Some(pass),
                        )
                    }
                    WebdatasetForm::Npy { .. } => {
                        (format!("{}.png", spec.name), s.pass_path(pass), None)
                    }
                    WebdatasetForm::Png => {
                        (spec.webdataset_key.to_string(), s.pass_path(pass), None)
                    }
                }
            })
            .collect();
        if files.is_empty() {
            return Err(ExportError::Message(format!(
                "`{file}` lists no pass (no `*_filename` key names a file): the sample has nothing to export\nhint: check the dataset with `clevrtex verify`"
            )));
        }
        recorded[pos] = dataset::recorded_split(&meta["split"], &vd.variant, &file).map_err(bad)?;
        files.push(("json".into(), meta_path, None));
        for (_, p, _) in &files {
            match ds.classify(p) {
                Kind::File => {}
                Kind::Skipped(why) => {
                    skipped.push(format!("`{}` {why}", p.display()));
                    continue 'samples;
                }
                Kind::Dir => {
                    skipped.push(format!("`{}` is a folder", p.display()));
                    continue 'samples;
                }
            }
            std::fs::metadata(p).map_err(|cause| ExportError::Io {
                what: format!(
                    "`{}` (a pass the metadata of `{stem}` lists) is missing\nhint: check the dataset with `clevrtex verify`",
                    p.display()
                ),
                cause,
            })?;
        }
        out.push(Sample {
            index,
            pos,
            split: Split::Train,
            stem,
            files,
        });
    }
    // The one split rule of every reader: the recorded split, else by position.
    let splits = dataset::splits(&vd.variant, &recorded);
    for s in &mut out {
        s.split = splits[s.pos];
    }
    Ok(out)
}

fn io_err(what: String) -> impl FnOnce(std::io::Error) -> ExportError {
    move |cause| ExportError::Io { what, cause }
}

/// Export the dataset under `dir` (an output folder of `clevrtex generate`) as WebDataset
/// shards of at most `shard_size` bytes into `out` (created if missing), the variant `variant`
/// only or every variant found. Stops between samples when `stop` is raised
/// ([`ExportError::Interrupted`]; the shard being written is removed).
pub fn export(
    dir: &Path,
    out: &Path,
    variant: Option<&str>,
    shard_size: u64,
    stop: &AtomicBool,
) -> Result<ExportReport, ExportError> {
    let ds = Dataset::open(dir).map_err(|e| match e {
        DatasetError::Unreadable { cause, .. } => ExportError::Io {
            what: format!("cannot read `{}`", dir.display()),
            cause,
        },
        other => other.into(),
    })?;
    // Shards written into the dataset would become stray files of it (and a later export of
    // it would pack nothing new): refused, as `preview` and `report` refuse an `--out` there.
    let existing = out
        .ancestors()
        .find(|p| p.exists())
        .unwrap_or(Path::new("."));
    if existing
        .canonicalize()
        .is_ok_and(|o| o.starts_with(&ds.root))
    {
        return Err(ExportError::Message(format!(
            "`{}` is inside the dataset `{}`: its shards would become files of the dataset\nhint: export into a folder outside the dataset",
            out.display(),
            dir.display()
        )));
    }
    let mut skipped = Vec::new();
    let wanted = |v: &str| variant.is_none_or(|want| want == v);
    // A `clevrtex_<variant>` folder given itself is not an output folder: nothing under it.
    let variants: Vec<&VariantDir> = if ds.is_variant_dir {
        Vec::new()
    } else {
        for (v, skip) in &ds.skipped {
            if wanted(v) {
                skipped.push(skip.to_string());
            }
        }
        ds.variants
            .iter()
            .filter(|vd| wanted(&vd.variant))
            .collect()
    };
    if variants.is_empty() {
        return Err(ExportError::Message(format!(
            "no `clevrtex_<variant>` folder{} in `{}`\nhint: pass the `--out` folder of `clevrtex generate`",
            variant.map(|v| format!(" for `{v}`")).unwrap_or_default(),
            dir.display()
        )));
    }
    std::fs::create_dir_all(out).map_err(io_err(format!("cannot create `{}`", out.display())))?;
    refuse_foreign_shards(out)?;
    let mut index = Vec::new();
    let mut total_bytes = 0u64;
    let mut total_samples = 0u64;
    let mut written = BTreeSet::new();
    for vd in &variants {
        let variant = &vd.variant;
        let all = samples(&ds, vd, &mut skipped)?;
        let mut by_split: BTreeMap<&str, Vec<&Sample>> = BTreeMap::new();
        for s in &all {
            by_split.entry(s.split.name()).or_default().push(s);
        }
        for (split, list) in by_split {
            let mut shard: Option<ShardWriter> = None;
            let mut n = 0;
            for s in list {
                if stop.load(Ordering::SeqCst) {
                    return Err(ExportError::Interrupted);
                }
                let entries = sample_entries(&ds.root, &s.files)?;
                let size = tar_bytes(&entries);
                if shard
                    .as_ref()
                    .is_some_and(|w| w.samples() > 0 && w.bytes() + size > shard_size)
                {
                    let done = shard.take().unwrap().finish()?;
                    total_bytes += done["bytes"].as_u64().unwrap_or(0);
                    index.push(json!({"variant": variant, "split": split, "shard": done}));
                }
                if shard.is_none() {
                    let name = shard_name(variant, split, n);
                    written.insert(name.clone());
                    n += 1;
                    shard = Some(ShardWriter::create(out.join(name))?);
                }
                shard.as_mut().unwrap().add(s.index, &s.stem, &entries)?;
                total_samples += 1;
            }
            if let Some(w) = shard {
                let done = w.finish()?;
                total_bytes += done["bytes"].as_u64().unwrap_or(0);
                index.push(json!({"variant": variant, "split": split, "shard": done}));
            }
        }
    }
    let stale = remove_stale(out, &written)?;
    let shards = index.len();
    let doc = json!({
        "format": "webdataset",
        "source": dir.display().to_string(),
        "samples": total_samples,
        "shards": index,
        "keys": std::iter::once(json!({"key": "__key__", "holds": "the sample's stem"}))
            .chain(Pass::ALL.map(|p| json!({"key": p.spec().webdataset_key, "holds": p.spec().webdataset_doc})))
            .chain([json!({"key": "json", "holds": "the sample's metadata (docs/output-format.md)"})])
            .collect::<Vec<_>>(),
    });
    let index_path = out.join("index.json");
    let text = serde_json::to_string_pretty(&doc).expect("JSON values serialise") + "\n";
    crate::atomic::write(&index_path, text.as_bytes())
        .map_err(io_err(format!("cannot write `{}`", index_path.display())))?;
    Ok(ExportReport {
        samples: total_samples,
        shards,
        bytes: total_bytes,
        index: index_path,
        stale,
        skipped,
    })
}

/// Files in `out` named like shards that no export wrote (not a tar file, or not a regular
/// file): refused before anything is written, since export replaces and removes files of
/// those names. Links named like shards are replaced or removed themselves, never followed.
fn refuse_foreign_shards(out: &Path) -> Result<(), ExportError> {
    for e in std::fs::read_dir(out)
        .map_err(io_err(format!("cannot read `{}`", out.display())))?
        .flatten()
    {
        let name = e.file_name().to_string_lossy().into_owned();
        if !is_shard_name(&name) || e.file_type().is_ok_and(|t| t.is_symlink()) {
            continue;
        }
        if !e.file_type().is_ok_and(|t| t.is_file()) || !is_tar(&e.path()) {
            return Err(ExportError::Message(format!(
                "`{}` is named like a shard but is not a tar file an export wrote: export would replace or remove it\nhint: move it out of `{}`, or export into an empty folder",
                e.path().display(),
                out.display()
            )));
        }
    }
    Ok(())
}

/// Whether `path` starts with a POSIX tar header (`ustar` at byte 257), as shards do.
fn is_tar(path: &Path) -> bool {
    use std::io::Read;
    let mut head = [0u8; 262];
    std::fs::File::open(path)
        .and_then(|mut f| f.read_exact(&mut head))
        .is_ok_and(|()| &head[257..262] == b"ustar")
}

/// Shards of an earlier export into `out` that this one did not write (fewer samples, another
/// variant): removed, so `index.json` and the shards on disk agree. Only export's own shard
/// names are touched.
fn remove_stale(out: &Path, written: &BTreeSet<String>) -> Result<Vec<String>, ExportError> {
    let mut stale = Vec::new();
    for e in std::fs::read_dir(out)
        .map_err(io_err(format!("cannot read `{}`", out.display())))?
        .flatten()
    {
        let name = e.file_name().to_string_lossy().into_owned();
        let file = e.file_type().is_ok_and(|t| t.is_file() || t.is_symlink());
        if file && is_shard_name(&name) && !written.contains(&name) {
            std::fs::remove_file(e.path()).map_err(io_err(format!(
                "cannot remove the stale shard `{}` of an earlier export\nhint: remove it by hand, or export into an empty folder",
                e.path().display()
            )))?;
            stale.push(name);
        }
    }
    Ok(stale)
}

/// What can go wrong while writing a shard. Shown as the command's error: the message, then
/// (as the error's source) the OS error.
#[derive(Debug, thiserror::Error)]
pub enum ShardError {
    /// A file of the shard could not be created or written.
    #[error("{what}")]
    Io {
        /// What failed, e.g. "cannot write `OUT/full-train-000000.tar.clevrtex-tmp`".
        what: String,
        /// The OS error.
        #[source]
        cause: std::io::Error,
    },
    /// The finished shard could not be looked at.
    #[error(transparent)]
    Stat(std::io::Error),
    /// A file of the dataset could not be read (the message says which and what to do).
    #[error("{0}")]
    Read(String),
}

fn io(what: &str, path: &Path) -> impl FnOnce(std::io::Error) -> ShardError {
    let what = format!("{what} `{}`", path.display());
    move |cause| ShardError::Io { what, cause }
}

/// The name of shard `n` of `split` of `variant`.
pub fn shard_name(variant: &str, split: &str, n: u64) -> String {
    format!("{variant}-{split}-{n:06}.tar")
}

/// Whether `name` is one of export's shard names, `<variant>-<split>-<6 digits>.tar`.
pub fn is_shard_name(name: &str) -> bool {
    let Some(rest) = name.strip_suffix(".tar") else {
        return false;
    };
    let Some((head, digits)) = rest.rsplit_once('-') else {
        return false;
    };
    let Some((variant, split)) = head.rsplit_once('-') else {
        return false;
    };
    !variant.is_empty()
        && Split::parse(split).is_some()
        && digits.len() == 6
        && digits.bytes().all(|b| b.is_ascii_digit())
}

/// The bytes a tar holds for `entries`: a 512-byte header and the data padded to 512 bytes
/// each.
pub fn tar_bytes(entries: &[(String, Vec<u8>)]) -> u64 {
    entries
        .iter()
        .map(|(_, d)| 512 + (d.len() as u64).div_ceil(512) * 512)
        .sum()
}

/// The entries of one sample in a shard: each file of `files` read from the dataset under its
/// canonical `root` ([`dataset::read`]: no link out of it, only regular files, capped), a pass
/// marked for it decoded into its `.npy` array ([`pass_npy`]).
pub fn sample_entries(
    root: &Path,
    files: &[SampleFile],
) -> Result<Vec<(String, Vec<u8>)>, ShardError> {
    let unread = |path: &Path, why: String| {
        ShardError::Read(format!(
            "`{}` {why}\nhint: check the dataset with `clevrtex verify`",
            path.display()
        ))
    };
    files
        .iter()
        .map(|(key, path, pass)| {
            let bytes =
                dataset::read(root, path, dataset::MAX_FILE_BYTES).map_err(|w| unread(path, w))?;
            let data = match pass {
                None => bytes,
                Some(pass) => pass_npy(*pass, &bytes).map_err(|w| unread(path, w))?,
            };
            Ok((key.clone(), data))
        })
        .collect()
}

/// The `.npy` of a pass's PNG `bytes` (of the layout and encoding of the pass table:
/// [`clevrtex_scene::passes`]): the mask's ids as `uint8 (H, W)` (a palette's indices, or an
/// 8-bit grey image's values: the published ClevrTex's masks); depth in metres as `float32
/// (H, W)`, background `+inf`; normals as `float32 (H, W, 3)` unit vectors, background
/// `(0, 0, 0)`; the shadow amount as `float32 (H, W)` in `[0, 1]`. `Err` says why not, one line.
pub fn pass_npy(pass: Pass, bytes: &[u8]) -> Result<Vec<u8>, String> {
    use clevrtex_scene::passes::{DEPTH_BACKGROUND, DEPTH_SCALE_M, NORMAL_BACKGROUND};
    let png = crate::png::decode(bytes)?;
    let WebdatasetForm::Npy { descr, channels } = pass.spec().webdataset_form else {
        return Err(format!(
            "the {} pass is not stored as an array",
            pass.name()
        ));
    };
    let (w, h) = (png.width as usize, png.height as usize);
    let layout = |bits: u8, ch: usize| -> Result<(), String> {
        if png.bits == bits && png.channels == ch {
            Ok(())
        } else {
            Err(format!(
                "is a {}-bit {}-channel PNG, not the {bits}-bit {ch}-channel {} pass",
                png.bits,
                png.channels,
                pass.name()
            ))
        }
    };
    let mut out = npy_header(
        descr,
        &[h, w, usize::from(channels)][..if channels == 1 { 2 } else { 3 }],
    );
    match pass {
        Pass::Mask => {
            layout(8, 1)?;
            out.extend(png.data.iter().map(|&v| v as u8));
        }
        Pass::Depth => {
            layout(16, 1)?;
            for &v in &png.data {
                let m = if v == DEPTH_BACKGROUND {
                    f32::INFINITY
                } else {
                    (f64::from(v) * DEPTH_SCALE_M) as f32
                };
                out.extend(m.to_le_bytes());
            }
        }
        Pass::Normal => {
            layout(16, 3)?;
            for px in png.data.chunks_exact(3) {
                let n = if px == NORMAL_BACKGROUND {
                    [0.0; 3]
                } else {
                    let v = [0, 1, 2].map(|i| f64::from(px[i]) / 65535.0 * 2.0 - 1.0);
                    let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
                    if len > 0.0 {
                        v.map(|c| c / len)
                    } else {
                        [0.0; 3]
                    }
                };
                for c in n {
                    out.extend((c as f32).to_le_bytes());
                }
            }
        }
        Pass::Shadow => {
            layout(8, 1)?;
            for &v in &png.data {
                out.extend((f32::from(v) / 255.0).to_le_bytes());
            }
        }
        Pass::Rgb | Pass::Albedo => {
            return Err(format!(
                "the {} pass is not stored as an array",
                pass.name()
            ))
        }
    }
    Ok(out)
}

/// The header of a NumPy `.npy` file (format version 1.0) of C-order `shape` and dtype
/// `descr`, padded with spaces so the data starts at a multiple of 64 bytes (NumPy's
/// `numpy.lib.format`). Nothing in it depends on the machine: the same array, the same bytes.
pub fn npy_header(descr: &str, shape: &[usize]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(ToString::to_string).collect();
    let shape = match dims.len() {
        1 => format!("({},)", dims[0]),
        _ => format!("({})", dims.join(", ")),
    };
    let mut dict = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}");
    // magic (6) + version (2) + length (2) + dict + '\n', to a multiple of 64.
    let pad = (64 - (10 + dict.len() + 1) % 64) % 64;
    dict.push_str(&" ".repeat(pad));
    dict.push('\n');
    let mut out = Vec::with_capacity(10 + dict.len());
    out.extend(b"\x93NUMPY\x01\x00");
    out.extend((dict.len() as u16).to_le_bytes());
    out.extend(dict.as_bytes());
    out
}

/// A tar shard being written under a unique temporary name (an [`AtomicFile`]: removed if it
/// is never finished).
pub struct ShardWriter {
    tmp: PathBuf,
    path: PathBuf,
    /// `None` once finished.
    builder: Option<tar::Builder<std::io::BufWriter<AtomicFile>>>,
    bytes: u64,
    samples: u64,
    first: u64,
    last: u64,
}

impl ShardWriter {
    /// Start the shard `path` (written under a temporary name of
    /// [`crate::atomic`] until [`ShardWriter::finish`]).
    pub fn create(path: PathBuf) -> Result<ShardWriter, ShardError> {
        let f = AtomicFile::create(&path).map_err(io("cannot create a temporary for", &path))?;
        let tmp = f.tmp_path().to_path_buf();
        Ok(ShardWriter {
            tmp,
            path,
            builder: Some(tar::Builder::new(std::io::BufWriter::new(f))),
            bytes: 0,
            samples: 0,
            first: 0,
            last: 0,
        })
    }

    /// Bytes written so far (tar headers and padding included).
    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    /// Samples written so far.
    pub fn samples(&self) -> u64 {
        self.samples
    }

    /// Add sample `index` with key `stem`: each `(extension, bytes)` of `entries`
    /// ([`sample_entries`]) becomes `<stem>.<extension>`. Headers carry no time, owner or mode
    /// of the machine.
    pub fn add(
        &mut self,
        index: u64,
        stem: &str,
        entries: &[(String, Vec<u8>)],
    ) -> Result<(), ShardError> {
        for (ext, data) in entries {
            let mut h = tar::Header::new_ustar();
            h.set_size(data.len() as u64);
            h.set_mode(0o644);
            h.set_mtime(0);
            h.set_uid(0);
            h.set_gid(0);
            h.set_entry_type(tar::EntryType::Regular);
            let name = format!("{stem}.{ext}");
            self.builder
                .as_mut()
                .expect("not finished")
                .append_data(&mut h, &name, data.as_slice())
                .map_err(io("cannot write", &self.tmp))?;
            self.bytes += 512 + (data.len() as u64).div_ceil(512) * 512;
        }
        if self.samples == 0 {
            self.first = index;
        }
        self.last = index;
        self.samples += 1;
        Ok(())
    }

    /// Finish the tar, flush it to disk and rename it to its final name; its entry of
    /// `index.json` (file, samples, bytes, first and last index).
    pub fn finish(mut self) -> Result<Value, ShardError> {
        let w = self
            .builder
            .take()
            .expect("finished once")
            .into_inner()
            .map_err(io("cannot write", &self.tmp))?;
        let f = w
            .into_inner()
            .map_err(|e| e.into_error())
            .map_err(io("cannot write", &self.tmp))?;
        f.commit().map_err(io("cannot write", &self.path))?;
        let size = std::fs::metadata(&self.path)
            .map_err(ShardError::Stat)?
            .len();
        Ok(json!({
            "file": self.path.file_name().unwrap().to_string_lossy(),
            "samples": self.samples,
            "bytes": size,
            "first_index": self.first,
            "last_index": self.last,
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shard_names_are_recognised_and_nothing_else() {
        assert!(is_shard_name(&shard_name("full", "train", 3)));
        assert_eq!(shard_name("camo", "val", 12), "camo-val-000012.tar");
        for name in [
            "full-train-00003.tar",
            "full-nope-000003.tar",
            "-train-000003.tar",
            "full-train-000003.tar.clevrtex-tmp",
            "index.json",
        ] {
            assert!(!is_shard_name(name), "{name}");
        }
    }

    #[test]
    fn an_unfinished_shard_leaves_nothing_and_a_finished_one_is_reproducible() {
        let dir = tempfile::tempdir().unwrap();
        let data = dir.path().join("data");
        std::fs::create_dir(&data).unwrap();
        std::fs::write(data.join("a.png"), b"not really a png").unwrap();
        let root = dataset::root(&data).unwrap();
        let files = vec![("png".to_string(), data.join("a.png"), None)];
        let entries = sample_entries(&root, &files).unwrap();
        let out = dir.path().join("full-train-000000.tar");
        {
            let mut w = ShardWriter::create(out.clone()).unwrap();
            w.add(7, "CLEVRTEX_full_000007", &entries).unwrap();
            assert_eq!((w.samples(), w.bytes()), (1, 1024));
        }
        assert!(
            std::fs::read_dir(dir.path()).unwrap().count() == 1,
            "a temporary shard is left"
        );
        let mut bytes = Vec::new();
        for _ in 0..2 {
            let mut w = ShardWriter::create(out.clone()).unwrap();
            w.add(7, "CLEVRTEX_full_000007", &entries).unwrap();
            let entry = w.finish().unwrap();
            assert_eq!(entry["first_index"], 7);
            assert_eq!(entry["samples"], 1);
            bytes.push(std::fs::read(&out).unwrap());
        }
        assert_eq!(bytes[0], bytes[1]);
        let err =
            sample_entries(&root, &[("png".into(), data.join("missing.png"), None)]).unwrap_err();
        assert!(err.to_string().contains("missing.png"), "{err}");
        assert!(err.to_string().contains("hint:"), "{err}");
    }

    #[test]
    fn npy_headers_are_numpy_s_and_pad_to_64_bytes() {
        for shape in [&[240usize, 320][..], &[2, 3, 3], &[5]] {
            let h = npy_header("<f4", shape);
            assert_eq!(h.len() % 64, 0);
            assert_eq!(&h[..8], b"\x93NUMPY\x01\x00");
            assert_eq!(usize::from(u16::from_le_bytes([h[8], h[9]])), h.len() - 10);
            assert_eq!(*h.last().unwrap(), b'\n');
        }
        let h = String::from_utf8(npy_header("|u1", &[240, 320])[10..].to_vec()).unwrap();
        assert!(h.starts_with("{'descr': '|u1', 'fortran_order': False, 'shape': (240, 320), }"));
        let h = String::from_utf8(npy_header("<f4", &[5])[10..].to_vec()).unwrap();
        assert!(h.contains("'shape': (5,)"), "{h}");
    }
}
