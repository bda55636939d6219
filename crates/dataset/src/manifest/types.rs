//! The run manifest: what one `clevrtex generate` run (or one shard of it) made, with the size
//! and xxh3 hash of every file, so `clevrtex verify` can check the bytes later (after a copy,
//! on another machine, for the union of shards).
//!
//! `OUT/clevrtex_<variant>/MANIFEST-<start>-<end>-<k>of<n>.json`: one per range and shard
//! (`0of1` unsharded), so runs of other ranges into one folder (a dataset grown with `--start`)
//! and shards never overwrite each other's; `verify` takes their union. Written atomically
//! twice: before the first image as the run's plan (`finished: false`, no files), and at the
//! end of a run that was not interrupted with every file (`finished: true`). Paths are relative
//! to the variant folder, e.g. `0/CLEVRTEX_full_000000.png`.
//!
//! The types and the reading side; the dataset reader ([`crate::dataset`]) and the writing side
//! ([`crate::manifest::write`]) share them.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

/// Value of [`Manifest::format`].
pub const MANIFEST_FORMAT: &str = "clevrtex-manifest";
/// Current value of [`Manifest::version`].
pub const MANIFEST_VERSION: u32 = 1;
/// The most indices one manifest's range (`end - start`), or the union of a dataset's runs,
/// may hold: 100 million, a hundred times the largest dataset anyone renders. A file with
/// more is refused before anything is sized by it. The bound of image indices
/// ([`clevrtex_scene::bounds::INDEX_END`]), so a run never makes an index `verify` refuses.
pub const MAX_RUN_INDICES: u64 = clevrtex_scene::bounds::INDEX_END;

/// One file of the manifest.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct FileEntry {
    /// Size in bytes.
    pub size: u64,
    /// xxh3-64 of the bytes, written as 16 hex digits.
    pub xxh3: Xxh3,
}

/// An xxh3-64 content hash ([`clevrtex_materials::content_hash`]), kept as its number (8
/// bytes, where its text took 40: a manifest of a million files is read in memory of the
/// order of its size) and written as 16 lowercase hex digits, the only form read: anything
/// else in a manifest makes it unreadable, with the value named.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Xxh3(pub u64);

impl Xxh3 {
    /// The hash of `bytes`.
    pub fn of(bytes: &[u8]) -> Xxh3 {
        Xxh3(clevrtex_materials::content_hash(&[bytes]))
    }

    /// Parse 16 lowercase hex digits (the form [`std::fmt::Display`] writes).
    pub fn parse(text: &str) -> Option<Xxh3> {
        let ok = text.len() == 16 && text.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f'));
        ok.then(|| u64::from_str_radix(text, 16).ok().map(Xxh3))
            .flatten()
    }
}

impl std::fmt::Display for Xxh3 {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:016x}", self.0)
    }
}

impl Serialize for Xxh3 {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for Xxh3 {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Xxh3, D::Error> {
        struct Visit;
        impl serde::de::Visitor<'_> for Visit {
            type Value = Xxh3;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("an xxh3 hash: 16 lowercase hex digits")
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<Xxh3, E> {
                Xxh3::parse(v).ok_or_else(|| {
                    E::custom(format!(
                        "`{}` is not an xxh3 hash (16 lowercase hex digits)",
                        clevrtex_scene::text::printable(&v.chars().take(40).collect::<String>())
                    ))
                })
            }
        }
        d.deserialize_str(Visit)
    }
}

/// A map read as a list and built at once ([`BTreeMap::from_iter`] packs its nodes full): a
/// manifest's `files` and `sample_seconds` by serde's default insert one key at a time and
/// leave the tree's nodes about half empty. Duplicate keys keep one value, as before.
fn packed_map<'de, D, V>(d: D) -> Result<BTreeMap<String, V>, D::Error>
where
    D: serde::Deserializer<'de>,
    V: Deserialize<'de>,
{
    struct Visit<V>(std::marker::PhantomData<V>);
    impl<'de, V: Deserialize<'de>> serde::de::Visitor<'de> for Visit<V> {
        type Value = BTreeMap<String, V>;
        fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            f.write_str("an object")
        }
        fn visit_map<A: serde::de::MapAccess<'de>>(
            self,
            mut a: A,
        ) -> Result<BTreeMap<String, V>, A::Error> {
            let mut list = Vec::new();
            while let Some((k, v)) = a.next_entry::<String, V>()? {
                list.push((k, v));
            }
            Ok(list.into_iter().collect())
        }
    }
    d.deserialize_map(Visit(std::marker::PhantomData))
}

/// A user material (`--materials DIR`) a run could draw, as its manifest records it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct UserMaterial {
    /// Its file, relative to the material folder (`Bricks01.blend`).
    pub file: String,
    /// The node group used, for a `.blend`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub group: Option<String>,
    /// The image textures it reads, relative to the material folder.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub textures: Vec<String>,
    /// Content hash of the file and every texture (`clevrtex_materials::content_hash`, 16
    /// hex digits): the value each sample's metadata records under `user_materials`.
    pub xxh3: String,
}

/// What one run (or shard) made.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// Always [`MANIFEST_FORMAT`].
    pub format: String,
    /// Always [`MANIFEST_VERSION`] for files this version writes.
    pub version: u32,
    /// Variant name.
    pub variant: String,
    /// Run seed.
    pub seed: u64,
    /// The layout stream of the run's draws (the variant's name unless `--layout-stream`
    /// chose another); absent in manifests of clevrtex 0.1, whose every variant drew from the
    /// one stream `shared` ([`Manifest::layout_stream`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub layout_stream: Option<String>,
    /// xxh3 of the resolved variant config (render settings and passes included), hex.
    pub config_hash: String,
    /// First index of the run.
    pub start: u64,
    /// One past the last index of the run (before sharding).
    pub end: u64,
    /// Size of the whole dataset (fixes the splits).
    pub total: u64,
    /// This shard `[k, n]`: the run made the indices of `start..end` with `index % n == k`.
    pub shard: [u64; 2],
    /// Passes written.
    pub passes: Vec<String>,
    /// The render settings of every sample of the run (the samples' metadata `render`: size,
    /// samples, bounces, colour management), so `verify` can tell a sample rendered with
    /// other settings; absent in older manifests.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub render: Option<serde_json::Value>,
    /// `clevrtex` version.
    pub tool_version: String,
    /// The git commit `clevrtex` was built from (40 hex digits, `unknown` for a build outside
    /// git without `CLEVRTEX_BUILD_COMMIT`); absent in older manifests. Kept out of the
    /// samples' metadata, which stays byte-identical across builds (docs/runs.md, "Provenance").
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub tool_commit: String,
    /// Whether a tracked source differed from `tool_commit` when it was built; absent when
    /// not known (and in older manifests).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tool_modified: Option<bool>,
    /// Blender version of the samples (from their metadata).
    pub blender_version: String,
    /// The settings the bridge changed on that Blender to render as 3.4 does (the samples'
    /// `blender_compat`, e.g. `{"coat": true, ...}` on 4.x); absent on 3.x and in older
    /// manifests.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub blender_compat: BTreeMap<String, serde_json::Value>,
    /// The command line that made the run (rerunning it resumes and repairs).
    pub command: Vec<String>,
    /// Whether the run got to its end (`false`: only its plan, written before the first
    /// image; the run was interrupted or is still going). Absent in older manifests, which
    /// were only written at the end.
    #[serde(default = "finished_default")]
    pub finished: bool,
    /// Every file of the run's complete samples, by path relative to the variant folder.
    #[serde(deserialize_with = "packed_map")]
    pub files: BTreeMap<String, FileEntry>,
    /// Seconds one worker spent on each complete sample, by stem: its visibility passes,
    /// rejected layouts, final render and writing (what `clevrtex report` plots). Kept from
    /// the previous manifest for samples an earlier run made; absent in older manifests.
    #[serde(
        default,
        skip_serializing_if = "BTreeMap::is_empty",
        deserialize_with = "packed_map"
    )]
    pub sample_seconds: BTreeMap<String, f64>,
    /// The user materials (`--materials DIR`) the run could draw, by name; absent when it
    /// drew only built-in ones (and in older manifests).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub user_materials: BTreeMap<String, UserMaterial>,
    /// Whether the run was told to mix its settings with other runs' in one folder on purpose
    /// (`generate --mix-settings`): `verify` then names the runs' differences without failing
    /// the dataset. Absent (false) otherwise.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub mixed_settings: bool,
    /// The suite the run was made for (`generate --suite NAME`); absent for a run of one
    /// variant (and in older manifests). The card and `verify --against` name it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub suite: Option<String>,
}

/// The render settings that differ between two `render` objects (a manifest's or a sample's
/// metadata's), as `width 32 vs 40`; keys sorted.
pub fn render_differences(a: &serde_json::Value, b: &serde_json::Value) -> Vec<String> {
    let empty = serde_json::Map::new();
    let (a, b) = (
        a.as_object().unwrap_or(&empty),
        b.as_object().unwrap_or(&empty),
    );
    let keys: std::collections::BTreeSet<&String> = a.keys().chain(b.keys()).collect();
    let show = |v: Option<&serde_json::Value>| {
        v.map_or("(none)".to_string(), crate::dataset::metadata::short)
    };
    keys.into_iter()
        .filter(|k| a.get(*k) != b.get(*k))
        .take(20)
        .map(|k| format!("render {k} {} vs {}", show(a.get(k)), show(b.get(k))))
        .collect()
}

/// xxh3-64 of `bytes` as 16 hex digits ([`clevrtex_materials::content_hash`], the one content
/// hash of the project).
pub fn hash_hex(bytes: &[u8]) -> String {
    Xxh3::of(bytes).to_string()
}

fn finished_default() -> bool {
    true
}

/// The manifest's file name for shard `k` of `n` of the indices `start..end`.
pub fn file_name(start: u64, end: u64, k: u64, n: u64) -> String {
    format!("MANIFEST-{start}-{end}-{k}of{n}.json")
}

/// Whether `name` is a manifest's file name (this version's or an older `MANIFEST-<k>of<n>.json`).
pub fn is_manifest_name(name: &str) -> bool {
    name.starts_with("MANIFEST-") && name.ends_with(".json")
}

impl Manifest {
    /// A manifest of this format and version that names no run yet: not finished, no Blender,
    /// no files (a run's plan starts from it).
    pub fn unfinished() -> Manifest {
        Manifest {
            format: MANIFEST_FORMAT.into(),
            version: MANIFEST_VERSION,
            variant: String::new(),
            seed: 0,
            layout_stream: None,
            config_hash: String::new(),
            start: 0,
            end: 0,
            total: 0,
            shard: [0, 1],
            passes: Vec::new(),
            render: None,
            tool_version: String::new(),
            tool_commit: String::new(),
            tool_modified: None,
            blender_version: String::new(),
            blender_compat: BTreeMap::new(),
            command: Vec::new(),
            finished: false,
            files: BTreeMap::new(),
            sample_seconds: BTreeMap::new(),
            user_materials: BTreeMap::new(),
            mixed_settings: false,
            suite: None,
        }
    }

    /// The layout stream of the run's draws: the recorded one, else `shared` (a manifest of
    /// clevrtex 0.1, when every variant drew from one stream).
    pub fn layout_stream(&self) -> &str {
        self.layout_stream
            .as_deref()
            .unwrap_or(clevrtex_scene::SHARED_STREAM)
    }

    /// This manifest's file name ([`file_name`]).
    pub fn name(&self) -> String {
        file_name(self.start, self.end, self.shard[0], self.shard[1])
    }

    /// Read a manifest file: a regular file (a link only within its folder), at most
    /// [`crate::dataset::files::MAX_FILE_BYTES`], whose values pass [`Manifest::check`].
    pub fn read(path: &Path) -> Result<Manifest, String> {
        let dir = path.parent().unwrap_or(Path::new("."));
        let root = crate::dataset::files::root(dir).map_err(|e| e.to_string())?;
        // Streamed, not read whole first: what is held is the parsed manifest alone.
        let file =
            crate::dataset::files::open_capped(&root, path, crate::dataset::files::MAX_FILE_BYTES)?;
        let m: Manifest = serde_json::from_reader(std::io::BufReader::with_capacity(1 << 16, file))
            .map_err(|e| e.to_string())?;
        if m.format != MANIFEST_FORMAT || m.version != MANIFEST_VERSION {
            return Err(format!(
                "not a version {MANIFEST_VERSION} clevrtex manifest (format `{}`, version {})",
                m.format, m.version
            ));
        }
        m.check()?;
        Ok(m)
    }

    /// The values that size or steer a reader, checked: `start <= end`, `end - start` at most
    /// [`MAX_RUN_INDICES`], `shard` `[k, n]` with `0 <= k < n`; the error names the key.
    pub fn check(&self) -> Result<(), String> {
        if self.start > self.end {
            return Err(format!(
                "key `start` ({}) is after `end` ({})",
                self.start, self.end
            ));
        }
        if self.end - self.start > MAX_RUN_INDICES {
            return Err(format!(
                "keys `start`..`end` ({}..{}) hold more than the {MAX_RUN_INDICES} indices a run may have",
                self.start, self.end
            ));
        }
        let [k, n] = self.shard;
        if n == 0 || k >= n {
            return Err(format!(
                "key `shard` is [{k}, {n}], not [k, n] with 0 <= k < n"
            ));
        }
        Ok(())
    }

    /// Whether `index` is one this manifest's run was asked to make.
    /// What of a run's settings differs between `self` and `other` (seed, passes, each render
    /// setting, the rest of the variant config), one phrase each, or nothing (`--total` is not
    /// a setting of the images: a grown dataset keeps each sample's recorded split):
    /// what `generate` names when it refuses to write into a folder of another run, and what
    /// `verify` names for a sample.
    pub fn settings_differ(&self, other: &Manifest) -> Vec<String> {
        let mut d = Vec::new();
        if self.variant != other.variant {
            d.push(format!("variant {} vs {}", self.variant, other.variant));
        }
        if self.seed != other.seed {
            d.push(format!("--seed {} vs {}", self.seed, other.seed));
        }
        if self.layout_stream() != other.layout_stream() {
            d.push(format!(
                "--layout-stream {} vs {}",
                self.layout_stream(),
                other.layout_stream()
            ));
        }
        if !self.passes.is_empty() && !other.passes.is_empty() && self.passes != other.passes {
            d.push(format!(
                "--passes {} vs {}",
                self.passes.join(","),
                other.passes.join(",")
            ));
        }
        let render_differs = match (&self.render, &other.render) {
            (Some(a), Some(b)) => {
                let before = d.len();
                d.extend(render_differences(a, b));
                d.len() > before
            }
            _ => false,
        };
        if self.config_hash != other.config_hash && !render_differs && d.is_empty() {
            d.push(format!(
                "the variant config (hash {} vs {})",
                self.config_hash, other.config_hash
            ));
        }
        d.extend(user_materials_differ(
            &self.user_materials,
            other
                .user_materials
                .iter()
                .map(|(n, u)| (n, u.xxh3.as_str())),
        ));
        d
    }

    /// Whether this run's indices and `other`'s share one (same range part and shard).
    pub fn overlaps(&self, other: &Manifest) -> bool {
        let (a, b) = (self.start.max(other.start), self.end.min(other.end));
        a < b
            && (a..b)
                .take(1_000_000)
                .any(|i| self.covers(i) && other.covers(i))
    }

    /// Whether the run's indices include `index` (its range and its shard).
    pub fn covers(&self, index: u64) -> bool {
        let [k, n] = self.shard;
        (self.start..self.end).contains(&index) && index % n.max(1) == k
    }

    /// The indices this manifest's run was asked to make.
    pub fn indices(&self) -> impl Iterator<Item = u64> {
        let [k, n] = self.shard;
        let n = n.max(1);
        let first = if self.start >= self.end {
            self.end
        } else {
            self.start + (k + n - self.start % n) % n
        };
        (first..self.end).step_by(n as usize)
    }
}

/// The user materials whose content hash differs between a run's `mine` and `theirs` (another
/// manifest's, or the name -> hash a sample's metadata records), one phrase each: a material
/// edited between two runs into one folder (a texture changed before a resume) makes other
/// images under the same name, so its hash is a setting like the seed. A name only one side
/// has differs too.
pub fn user_materials_differ<'a>(
    mine: &BTreeMap<String, UserMaterial>,
    theirs: impl IntoIterator<Item = (&'a String, &'a str)>,
) -> Vec<String> {
    let theirs: BTreeMap<&String, &str> = theirs.into_iter().collect();
    let names: std::collections::BTreeSet<&String> =
        mine.keys().chain(theirs.keys().copied()).collect();
    let mut d = Vec::new();
    for name in names {
        let (a, b) = (
            mine.get(name).map(|u| u.xxh3.as_str()),
            theirs.get(name).copied(),
        );
        if a != b {
            d.push(format!(
                "user material `{name}` {} vs {}",
                a.map_or("absent".into(), |h| format!("hash {h}")),
                b.map_or("absent".into(), |h| format!("hash {h}"))
            ));
        }
    }
    d
}

/// Merge ranges `start..end` into sorted, disjoint ones (empty ones left out).
pub fn merge_ranges(mut ranges: Vec<(u64, u64)>) -> Vec<(u64, u64)> {
    ranges.retain(|(a, b)| a < b);
    ranges.sort();
    let mut out: Vec<(u64, u64)> = Vec::new();
    for (a, b) in ranges {
        match out.last_mut() {
            Some(last) if a <= last.1 => last.1 = last.1.max(b),
            _ => out.push((a, b)),
        }
    }
    out
}

/// Whether `i` is in one of the sorted, disjoint `ranges` (from [`merge_ranges`]).
pub fn in_ranges(ranges: &[(u64, u64)], i: u64) -> bool {
    let k = ranges.partition_point(|&(_, b)| b <= i);
    ranges.get(k).is_some_and(|&(a, b)| a <= i && i < b)
}

/// The union of the runs of `manifests`: the indices they were asked to make (every shard of
/// a run together makes its `start..end`), as sorted, disjoint ranges.
pub fn union<'a>(manifests: impl IntoIterator<Item = &'a Manifest>) -> Vec<(u64, u64)> {
    merge_ranges(manifests.into_iter().map(|m| (m.start, m.end)).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_merge_and_hold() {
        let r = merge_ranges(vec![(4, 8), (0, 4), (10, 12), (11, 11)]);
        assert_eq!(r, [(0, 8), (10, 12)]);
        assert!(in_ranges(&r, 0) && in_ranges(&r, 7) && in_ranges(&r, 11));
        assert!(!in_ranges(&r, 8) && !in_ranges(&r, 12) && !in_ranges(&r, u64::MAX));
    }

    #[test]
    fn a_hash_is_read_as_written_and_nothing_else() {
        let h = Xxh3::of(b"clevrtex");
        let text = serde_json::to_string(&FileEntry { size: 8, xxh3: h }).unwrap();
        assert_eq!(
            text,
            format!("{{\"size\":8,\"xxh3\":\"{}\"}}", hash_hex(b"clevrtex"))
        );
        let back: FileEntry = serde_json::from_str(&text).unwrap();
        assert_eq!(back.xxh3, h);
        for bad in [
            "",
            "0123",
            "0123456789ABCDEF",
            "0123456789abcdeg",
            "0123456789abcdef0",
            "\\u001b[31m",
        ] {
            let e =
                serde_json::from_str::<FileEntry>(&format!("{{\"size\":1,\"xxh3\":\"{bad}\"}}"))
                    .unwrap_err()
                    .to_string();
            assert!(
                e.contains("not an xxh3 hash") && !e.contains('\u{1b}'),
                "{bad}: {e}"
            );
        }
    }

    #[test]
    fn duplicate_keys_keep_the_last_value_as_serde_does() {
        let m: BTreeMap<String, u64> = packed_map(&mut serde_json::Deserializer::from_str(
            r#"{"b":1,"a":2,"b":3}"#,
        ))
        .unwrap();
        assert_eq!(
            m.into_iter().collect::<Vec<_>>(),
            [("a".into(), 2), ("b".into(), 3)]
        );
    }
}
