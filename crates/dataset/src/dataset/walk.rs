//! The one walk of a dataset folder: [`Dataset::open`] finds its variant folders, samples
//! ([`SampleRef`]), manifests, ledgers, temporaries and what was not followed.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use clevrtex_scene::Pass;
use serde_json::Value;

use super::files::{classify, list, read, root, Kind, MAX_LEDGER_BYTES, MAX_METADATA_BYTES};
use crate::layout;
use crate::manifest::Manifest;

/// Why a dataset cannot be opened at all (what is wrong inside it is recorded, not an error).
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// The path given is not a folder.
    #[error("`{}` is not a folder", .path.display())]
    NotAFolder {
        /// The path given.
        path: PathBuf,
    },
    /// The folder given cannot be resolved or listed.
    #[error("`{}` cannot be read: {cause}", .path.display())]
    Unreadable {
        /// The path given.
        path: PathBuf,
        /// Why.
        cause: std::io::Error,
    },
}

/// An entry of the dataset that was not followed or not read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Skip {
    /// Its path.
    pub path: PathBuf,
    /// Why, one line (`is a symbolic link leading out of the dataset ...`).
    pub why: String,
    /// The stem of the sample it belongs to, when its name is one of the layout's files.
    pub stem: Option<String>,
}

impl std::fmt::Display for Skip {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "`{}` {}", self.path.display(), self.why)
    }
}

/// One sample found: the regular files of its stem in one folder.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SampleRef {
    /// The variant its stem names.
    pub variant: String,
    /// Its index.
    pub index: u64,
    /// Its stem, `CLEVRTEX_<variant>_<index:06>`.
    pub stem: String,
    /// The folder it was found in.
    pub dir: PathBuf,
    /// The names of its regular files in `dir` (files of the layout only; links inside the
    /// dataset included).
    pub files: BTreeSet<String>,
}

impl SampleRef {
    /// The path of the file `name` in the sample's folder.
    pub fn path(&self, name: &str) -> PathBuf {
        self.dir.join(name)
    }

    /// The path of `pass`'s file (from the pass table), whether it exists or not.
    pub fn pass_path(&self, pass: Pass) -> PathBuf {
        self.path(&layout::pass_file(&self.stem, pass))
    }

    /// Whether `pass`'s file was found, a regular file.
    pub fn has_pass(&self, pass: Pass) -> bool {
        self.files.contains(&layout::pass_file(&self.stem, pass))
    }

    /// The metadata's file name.
    pub fn metadata_name(&self) -> String {
        layout::metadata_file(&self.stem)
    }

    /// The path of the metadata.
    pub fn metadata_path(&self) -> PathBuf {
        self.path(&self.metadata_name())
    }

    /// Whether the metadata was found, a regular file.
    pub fn has_metadata(&self) -> bool {
        self.files.contains(&self.metadata_name())
    }

    /// The split the layout's position rule gives the sample in a run of `total` images (what
    /// `generate` records; `verify` checks the recorded split against it).
    pub fn rule_split(&self, total: u64) -> layout::Split {
        layout::Split::of(layout::variant_splits(&self.variant), self.index, total)
    }
}

/// One `clevrtex_<variant>` folder and what was found in it.
#[derive(Debug, Clone, Default)]
pub struct VariantDir {
    /// The variant its name says.
    pub variant: String,
    /// The folder (under the path given).
    pub dir: PathBuf,
    /// The folder its runs wrote into (`--out`): the path given, or its parent when the path
    /// given is the variant folder.
    pub out: PathBuf,
    /// Samples in walk order (sample folders by name, stems by name); an index may be found
    /// in more than one folder.
    pub samples: Vec<SampleRef>,
    /// Run manifests (`MANIFEST-*.json`), regular files.
    pub manifests: Vec<PathBuf>,
    /// Failure ledgers ([`layout::LEDGER_FILE`]).
    pub ledgers: Vec<PathBuf>,
    /// Temporary files of writers (`*.clevrtex-tmp`, `.*.tmp*` in sample folders).
    pub temp_files: Vec<PathBuf>,
    /// Entries not followed or not read, in walk order: links out of the dataset, FIFOs,
    /// devices, folders named like a sample's file, folders that cannot be listed.
    pub skipped: Vec<Skip>,
    /// Folders that cannot be listed (this one or a sample folder), with the error.
    pub unreadable: Vec<(PathBuf, String)>,
    /// Regular files and folders that are not the layout's (stray names).
    pub strays: Vec<PathBuf>,
    /// Files named like a sample's that lie in the variant folder itself, outside every
    /// sample folder: not a sample of the layout, but the public loader's `**/` glob reads
    /// them as one (a second copy when the sample is also in its folder). `verify` names them.
    pub misplaced: Vec<PathBuf>,
}

impl VariantDir {
    /// The entries not followed that are not a sample's file, or are a sample's metadata:
    /// what the readers of metadata report (a pass's link or FIFO is reported by who reads
    /// the pass).
    pub fn skipped_for_metadata(&self) -> impl Iterator<Item = &Skip> {
        self.skipped.iter().filter(|s| match &s.stem {
            None => true,
            Some(stem) => s
                .path
                .file_name()
                .is_some_and(|n| n.to_string_lossy() == layout::metadata_file(stem)),
        })
    }

    /// The manifests read ([`Manifest::read`]): (path, manifest or why not).
    pub fn read_manifests(&self) -> Vec<(PathBuf, Result<Manifest, String>)> {
        self.manifests
            .iter()
            .map(|p| (p.clone(), Manifest::read(p)))
            .collect()
    }
}

/// A dataset folder opened: one walk, nothing read but folder listings. The one place that
/// walks a dataset, recognises its stems and builds its files' paths (`verify`, `export`,
/// `preview`, `report`, `eval`'s ground truth and the Python `Dataset` use it).
#[derive(Debug, Clone)]
pub struct Dataset {
    /// The path given.
    pub given: PathBuf,
    /// Its canonical form, which no link may leave.
    pub root: PathBuf,
    /// Whether the path given is itself a `clevrtex_<variant>` folder.
    pub is_variant_dir: bool,
    /// The variant folders, by name.
    pub variants: Vec<VariantDir>,
    /// Entries named `clevrtex_<variant>` that were not followed: (variant, why).
    pub skipped: Vec<(String, Skip)>,
}

/// One line of a failure ledger.
#[derive(Debug, Clone, PartialEq)]
pub struct LedgerEntry {
    /// `variant`, when a string.
    pub variant: Option<String>,
    /// `index`, when a whole number.
    pub index: Option<u64>,
    /// `error`, when a string (else empty).
    pub error: String,
}

impl Dataset {
    /// Open the dataset at `path` (trusted: the command line's): an output folder of
    /// `clevrtex generate` (its `clevrtex_<variant>` folders), or one variant folder.
    pub fn open(path: &Path) -> Result<Dataset, DatasetError> {
        if !path.is_dir() {
            return Err(DatasetError::NotAFolder {
                path: path.to_path_buf(),
            });
        }
        let unreadable = |cause| DatasetError::Unreadable {
            path: path.to_path_buf(),
            cause,
        };
        let root = root(path).map_err(unreadable)?;
        let name = root
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let mut ds = Dataset {
            given: path.to_path_buf(),
            root: root.clone(),
            is_variant_dir: false,
            variants: Vec::new(),
            skipped: Vec::new(),
        };
        if let Some(v) = name.strip_prefix("clevrtex_") {
            ds.is_variant_dir = true;
            let out = path.parent().unwrap_or(Path::new(".")).to_path_buf();
            ds.variants.push(walk_variant(&root, v, path, out));
            return Ok(ds);
        }
        for (name, p, kind) in list(&root, path).map_err(unreadable)? {
            let Some(v) = name.strip_prefix("clevrtex_") else {
                continue;
            };
            // `clevrtex_` followed by no variant name (or one no run could have written) is
            // named, not passed over: its samples would go unchecked.
            if let Some(why) = clevrtex_scene::names::variant_name_problem(v) {
                ds.skipped.push((
                    v.to_string(),
                    Skip {
                        path: p,
                        why: format!("is not a variant folder: the name after `clevrtex_` {why}"),
                        stem: None,
                    },
                ));
                continue;
            }
            match kind {
                Kind::Dir => ds
                    .variants
                    .push(walk_variant(&root, v, &p, path.to_path_buf())),
                Kind::Skipped(why) => ds.skipped.push((
                    v.to_string(),
                    Skip {
                        path: p,
                        why,
                        stem: None,
                    },
                )),
                Kind::File => {}
            }
        }
        Ok(ds)
    }

    /// The bytes of `path` (a file found in this dataset), at most `cap`; `Err` says why not.
    pub fn read(&self, path: &Path, cap: u64) -> Result<Vec<u8>, String> {
        read(&self.root, path, cap)
    }

    /// What `path` (under this dataset) is, links resolved only inside the root.
    pub fn classify(&self, path: &Path) -> Kind {
        classify(&self.root, path)
    }

    /// A sample's metadata: read up to [`MAX_METADATA_BYTES`] and parsed as JSON; `Err`
    /// says why not, in one line, without the path.
    pub fn read_metadata(&self, s: &SampleRef) -> Result<Value, String> {
        let bytes = self.read(&s.metadata_path(), MAX_METADATA_BYTES)?;
        serde_json::from_slice(&bytes).map_err(|e| format!("is not valid metadata: {e}"))
    }

    /// The lines of a failure ledger (read up to [`MAX_LEDGER_BYTES`]) that are JSON.
    pub fn read_ledger(&self, path: &Path) -> Result<Vec<LedgerEntry>, String> {
        let bytes = self.read(path, MAX_LEDGER_BYTES)?;
        Ok(String::from_utf8_lossy(&bytes)
            .lines()
            .filter_map(|l| serde_json::from_str::<Value>(l).ok())
            .map(|v| LedgerEntry {
                variant: v["variant"].as_str().map(str::to_string),
                index: v["index"].as_u64(),
                error: v["error"].as_str().unwrap_or("").to_string(),
            })
            .collect())
    }
}

/// The run manifests of the dataset at `out` (an output folder of `clevrtex generate`), by
/// variant folder name order: `(variant, path)`. Lists only `out` and its `clevrtex_<variant>`
/// folders (never a sample folder: cheap on any dataset), with the same rules as
/// [`Dataset::open`] (no link out of `out` followed, only regular files).
pub fn manifests_in(out: &Path) -> std::io::Result<Vec<(String, PathBuf)>> {
    let root = root(out)?;
    let mut found = Vec::new();
    for (name, p, kind) in list(&root, out)? {
        let Some(v) = name.strip_prefix("clevrtex_") else {
            continue;
        };
        if kind != Kind::Dir || clevrtex_scene::names::variant_name_problem(v).is_some() {
            continue;
        }
        let Ok(entries) = list(&root, &p) else {
            continue;
        };
        for (name, m, kind) in entries {
            if kind == Kind::File && crate::manifest::is_manifest_name(&name) {
                found.push((v.to_string(), m));
            }
        }
    }
    Ok(found)
}

/// Walk one variant folder: its sample folders, manifests, ledgers and temporaries.
fn walk_variant(root: &Path, variant: &str, dir: &Path, out: PathBuf) -> VariantDir {
    let mut vd = VariantDir {
        variant: variant.to_string(),
        dir: dir.to_path_buf(),
        out,
        ..VariantDir::default()
    };
    let entries = match list(root, dir) {
        Ok(e) => e,
        Err(e) => {
            vd.cannot_list(dir, e);
            return vd;
        }
    };
    for (name, p, kind) in entries {
        if name.ends_with(layout::TMP_SUFFIX) {
            vd.temp_files.push(p);
            continue;
        }
        match kind {
            Kind::Skipped(why) => vd.skipped.push(Skip {
                path: p,
                why,
                stem: None,
            }),
            Kind::Dir => walk_sample_dir(root, &p, &mut vd),
            Kind::File if crate::manifest::is_manifest_name(&name) => vd.manifests.push(p),
            Kind::File if name == layout::LEDGER_FILE => vd.ledgers.push(p),
            Kind::File if layout::parse_file_name(&name).is_some() => vd.misplaced.push(p),
            Kind::File => vd.strays.push(p),
        }
    }
    vd
}

impl VariantDir {
    fn cannot_list(&mut self, dir: &Path, e: std::io::Error) {
        self.skipped.push(Skip {
            path: dir.to_path_buf(),
            why: format!("cannot be read: {e}"),
            stem: None,
        });
        self.unreadable.push((dir.to_path_buf(), e.to_string()));
    }
}

/// Collect the samples, temporaries and skipped entries of one sample folder.
fn walk_sample_dir(root: &Path, dir: &Path, vd: &mut VariantDir) {
    let entries = match list(root, dir) {
        Ok(e) => e,
        Err(e) => {
            vd.cannot_list(dir, e);
            return;
        }
    };
    let mut by_stem: BTreeMap<String, SampleRef> = BTreeMap::new();
    for (name, p, kind) in entries {
        if name.ends_with(layout::TMP_SUFFIX) || (name.starts_with('.') && name.contains(".tmp")) {
            vd.temp_files.push(p);
            continue;
        }
        let Some((stem, variant, index)) = layout::parse_file_name(&name) else {
            vd.strays.push(p);
            continue;
        };
        let why = match kind {
            Kind::File => {
                by_stem
                    .entry(stem.to_string())
                    .or_insert_with(|| SampleRef {
                        variant: variant.to_string(),
                        index,
                        stem: stem.to_string(),
                        dir: dir.to_path_buf(),
                        files: BTreeSet::new(),
                    })
                    .files
                    .insert(name.clone());
                continue;
            }
            Kind::Skipped(why) => why,
            Kind::Dir => "is a folder named like a file".to_string(),
        };
        vd.skipped.push(Skip {
            path: p,
            why,
            stem: Some(stem.to_string()),
        });
    }
    vd.samples.extend(by_stem.into_values());
}
