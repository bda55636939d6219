//! The code's shape (issue 36): no Rust or Python source file over 700 lines outside tests and
//! `dev/` probes, and no circle of files inside a crate (file A naming file B's module through
//! `crate::` or `super::`, and B naming A's, directly or around a longer loop). Pure reading of
//! the sources; no tool needed.
//!
//! The module tree of each crate is followed from its root (`lib.rs`, `main.rs`) through its
//! `mod name;` declarations (with `#[path]`), so a file's module is the one rustc gives it.
//! A reference links to the deepest module on its path that is a file of its own
//! (`crate::dataset::splits` -> `dataset.rs`, `super::Item` in `report/summary.rs` ->
//! `report/mod.rs`); the crate root is left out (every file may use what it declares).
//! Comments, strings and character literals are skipped, and `super` inside an inline
//! `mod tests { .. }` is the file's own module. Test code (`#[cfg(test)]`) links nothing: a
//! test may use any module of its crate.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use crate::util::repo_root;

/// Most lines a source file may have (issue 36).
const MAX_LINES: usize = 700;

/// Folders whose `.rs` and `.py` files are counted.
const SOURCE_DIRS: [&str; 4] = ["crates", "blender_scripts", "scripts", "examples"];

/// Whether `rel` (relative to the repository) is test code or a development probe: under a
/// `tests/` or `dev/` folder, or named `tests.rs`, `*_tests.rs` or `test_*.py`.
fn exempt(rel: &Path) -> bool {
    let mut parts: Vec<String> = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    let name = parts.pop().unwrap_or_default();
    parts.iter().any(|p| p == "tests" || p == "dev")
        || name == "tests.rs"
        || name.ends_with("_tests.rs")
        || (name.starts_with("test_") && name.ends_with(".py"))
}

/// Every `.rs` and `.py` file under `dir`, links not followed, build outputs (`target/`),
/// hidden folders (virtual environments) and caches left out.
fn source_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return;
    };
    let mut entries: Vec<_> = rd.flatten().collect();
    entries.sort_by_key(|e| e.file_name());
    for e in entries {
        let name = e.file_name().to_string_lossy().into_owned();
        let Ok(kind) = e.file_type() else { continue };
        if kind.is_dir() {
            if name != "target" && name != "__pycache__" && !name.starts_with('.') {
                source_files(&e.path(), out);
            }
        } else if kind.is_file() && (name.ends_with(".rs") || name.ends_with(".py")) {
            out.push(e.path());
        }
    }
}

/// The source files over [`MAX_LINES`] lines under `root`'s [`SOURCE_DIRS`], as
/// `(path relative to root, lines)`, and how many files were counted.
fn long_files(root: &Path) -> (Vec<(PathBuf, usize)>, usize) {
    let mut files = Vec::new();
    for d in SOURCE_DIRS {
        source_files(&root.join(d), &mut files);
    }
    let mut counted = 0;
    let mut long = Vec::new();
    for f in files {
        let rel = f.strip_prefix(root).unwrap_or(&f).to_path_buf();
        if exempt(&rel) {
            continue;
        }
        counted += 1;
        let text = std::fs::read(&f).unwrap_or_default();
        let lines = String::from_utf8_lossy(&text).lines().count();
        if lines > MAX_LINES {
            long.push((rel, lines));
        }
    }
    (long, counted)
}

#[test]
fn no_source_file_over_700_lines() {
    let (long, counted) = long_files(&repo_root());
    eprintln!("{counted} source files counted (tests and dev/ probes left out)");
    let list: Vec<String> = long
        .iter()
        .map(|(p, n)| format!("  {}: {n} lines", p.display()))
        .collect();
    assert!(
        long.is_empty(),
        "{} source file(s) over {MAX_LINES} lines:\n{}\nhint: split the file by concern, or move its inline `#[cfg(test)] mod tests` to a sibling file (`#[path = \"<name>_tests.rs\"] mod tests;`)",
        long.len(),
        list.join("\n")
    );
}

/// Issue 49: the map of the code (`crates/README.md`) stays readable in a terminal and a diff:
/// no line over 300 characters (a table row that grows past it loses its detail to the file's
/// own list below).
#[test]
fn the_crates_map_has_no_line_over_300_characters() {
    let map = std::fs::read_to_string(repo_root().join("crates/README.md")).unwrap();
    let long: Vec<String> = map
        .lines()
        .enumerate()
        .filter(|(_, l)| l.chars().count() > 300)
        .map(|(i, l)| {
            format!(
                "  crates/README.md:{}: {} characters",
                i + 1,
                l.chars().count()
            )
        })
        .collect();
    assert!(
        long.is_empty(),
        "{} line(s) of the map over 300 characters:\n{}\nhint: keep a row to the files to open; details go in the crate's file list",
        long.len(),
        long.join("\n")
    );
}

/// A token of Rust source, comments and literals already dropped (but a string's text kept:
/// `#[path = "..."]` needs it).
#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Ident(String),
    Str(String),
    /// `::`
    PathSep,
    Punct(char),
}

/// The tokens of `src` with their line numbers (1-based). Rough, but right about what
/// matters here: comments (nested block comments too), strings (raw, byte), characters and
/// lifetimes never produce identifiers.
fn lex(src: &str) -> Vec<(Tok, usize)> {
    let c: Vec<char> = src.chars().collect();
    let mut out = Vec::new();
    let (mut i, mut line) = (0, 1);
    let ident_start = |ch: char| ch == '_' || ch.is_alphabetic();
    let ident_cont = |ch: char| ch == '_' || ch.is_alphanumeric();
    while i < c.len() {
        let ch = c[i];
        let next = c.get(i + 1).copied();
        if ch == '\n' {
            line += 1;
            i += 1;
        } else if ch.is_whitespace() {
            i += 1;
        } else if ch == '/' && next == Some('/') {
            while i < c.len() && c[i] != '\n' {
                i += 1;
            }
        } else if ch == '/' && next == Some('*') {
            let mut depth = 0;
            while i < c.len() {
                if c[i] == '/' && c.get(i + 1) == Some(&'*') {
                    depth += 1;
                    i += 2;
                } else if c[i] == '*' && c.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    if c[i] == '\n' {
                        line += 1;
                    }
                    i += 1;
                }
            }
        } else if let Some(len) = raw_string_start(&c[i..]) {
            // r"..", r#".."#, br#".."#: ends at the quote followed by as many `#`.
            let hashes = c[i..i + len].iter().filter(|&&h| h == '#').count();
            let start_line = line;
            i += len;
            let mut text = String::new();
            while i < c.len() {
                if c[i] == '"' && (1..=hashes).all(|k| c.get(i + k) == Some(&'#')) {
                    i += 1 + hashes;
                    break;
                }
                if c[i] == '\n' {
                    line += 1;
                }
                text.push(c[i]);
                i += 1;
            }
            out.push((Tok::Str(text), start_line));
        } else if ch == '"' || (ch == 'b' && next == Some('"')) {
            let start_line = line;
            i += if ch == 'b' { 2 } else { 1 };
            let mut text = String::new();
            while i < c.len() && c[i] != '"' {
                if c[i] == '\\' {
                    text.push(c[i]);
                    i += 1;
                }
                if let Some(&x) = c.get(i) {
                    if x == '\n' {
                        line += 1;
                    }
                    text.push(x);
                }
                i += 1;
            }
            i += 1;
            out.push((Tok::Str(text), start_line));
        } else if ch == '\'' || (ch == 'b' && next == Some('\'')) {
            // A character literal ('x', '\n', '\u{1F600}', b'x'), else a lifetime or label.
            let j = if ch == 'b' { i + 1 } else { i };
            if c.get(j + 1) == Some(&'\\') {
                let mut k = j + 2;
                while k < c.len() && c[k] != '\'' {
                    k += 1;
                }
                i = k + 1;
            } else if c.get(j + 2) == Some(&'\'') {
                i = j + 3;
            } else {
                i = j + 1;
            }
        } else if ident_start(ch) {
            let s = i;
            while i < c.len() && ident_cont(c[i]) {
                i += 1;
            }
            out.push((Tok::Ident(c[s..i].iter().collect()), line));
        } else if ch.is_ascii_digit() {
            while i < c.len() && (ident_cont(c[i]) || c[i] == '.') {
                // `1..n`: a range, not a float.
                if c[i] == '.' && c.get(i + 1) == Some(&'.') {
                    break;
                }
                i += 1;
            }
        } else if ch == ':' && next == Some(':') {
            out.push((Tok::PathSep, line));
            i += 2;
        } else {
            out.push((Tok::Punct(ch), line));
            i += 1;
        }
    }
    out
}

/// The length of a raw string's opening (`r"`, `r#"`, `br##"`, ...) at the start of `c`.
fn raw_string_start(c: &[char]) -> Option<usize> {
    let mut i = 0;
    if c.first() == Some(&'b') {
        i += 1;
    }
    if c.get(i) != Some(&'r') {
        return None;
    }
    i += 1;
    while c.get(i) == Some(&'#') {
        i += 1;
    }
    (c.get(i) == Some(&'"')).then_some(i + 1)
}

/// The paths a use tree or path starting at `toks[i]` (just after `crate::` or the last
/// `super::`) names, each as its segments; `self` in a group is the group's prefix.
fn paths_at(toks: &[(Tok, usize)], i: &mut usize, prefix: &[String], out: &mut Vec<Vec<String>>) {
    match toks.get(*i).map(|t| &t.0) {
        Some(Tok::Punct('{')) => {
            *i += 1;
            loop {
                match toks.get(*i).map(|t| &t.0) {
                    None => return,
                    Some(Tok::Punct('}')) => {
                        *i += 1;
                        return;
                    }
                    Some(Tok::Punct(',')) => *i += 1,
                    Some(Tok::Ident(a)) if a == "as" => *i += 2,
                    _ => {
                        let before = *i;
                        paths_at(toks, i, prefix, out);
                        if *i == before {
                            *i += 1;
                        }
                    }
                }
            }
        }
        Some(Tok::Ident(name)) if name == "self" => {
            *i += 1;
            out.push(prefix.to_vec());
        }
        Some(Tok::Ident(name)) => {
            let mut p = prefix.to_vec();
            p.push(name.clone());
            *i += 1;
            if toks.get(*i).map(|t| &t.0) == Some(&Tok::PathSep) {
                *i += 1;
                paths_at(toks, i, &p, out);
            } else {
                out.push(p);
            }
        }
        Some(Tok::Punct('*')) => {
            *i += 1;
            out.push(prefix.to_vec());
        }
        _ => out.push(prefix.to_vec()),
    }
}

/// One source file of a crate: its module path and its tokens.
struct File {
    module: Vec<String>,
    toks: Vec<(Tok, usize)>,
}

/// The files of the crate whose root is `root`, keyed by path, following `mod name;` (and
/// `#[path = ".."] mod name;`) from the root.
fn crate_files(root: &Path) -> BTreeMap<PathBuf, File> {
    let mut files = BTreeMap::new();
    let mut todo = vec![(root.to_path_buf(), Vec::<String>::new(), true)];
    while let Some((path, module, mod_rs)) = todo.pop() {
        if files.contains_key(&path) {
            continue;
        }
        let Ok(src) = std::fs::read_to_string(&path) else {
            continue;
        };
        let toks = lex(&src);
        let dir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
        let own_dir = if mod_rs {
            dir.clone()
        } else {
            dir.join(path.file_stem().unwrap_or_default())
        };
        let mut inline: Vec<(String, usize)> = Vec::new();
        let mut depth = 0;
        let mut attr_path: Option<String> = None;
        let mut k = 0;
        while k < toks.len() {
            let t = &toks[k].0;
            let at = |n: usize| toks.get(k + n).map(|t| &t.0);
            match t {
                Tok::Punct('#') if at(1) == Some(&Tok::Punct('[')) => {
                    if let (Some(Tok::Ident(a)), Some(Tok::Punct('=')), Some(Tok::Str(p))) =
                        (at(2), at(3), at(4))
                    {
                        if a == "path" {
                            attr_path = Some(p.clone());
                        }
                    }
                    // Skip the attribute, brackets balanced.
                    let mut d = 0;
                    while k < toks.len() {
                        match toks[k].0 {
                            Tok::Punct('[') => d += 1,
                            Tok::Punct(']') => {
                                d -= 1;
                                if d == 0 {
                                    break;
                                }
                            }
                            _ => {}
                        }
                        k += 1;
                    }
                }
                Tok::Ident(m) if m == "mod" => {
                    if let Some(Tok::Ident(name)) = at(1) {
                        let names: Vec<String> = inline.iter().map(|(n, _)| n.clone()).collect();
                        let mut child = module.clone();
                        child.extend(names.iter().cloned());
                        child.push(name.clone());
                        match at(2) {
                            Some(Tok::Punct(';')) => {
                                let base = names.iter().fold(own_dir.clone(), |d, n| d.join(n));
                                let (file, is_mod_rs) = match attr_path.take() {
                                    Some(p) => (dir.join(p), true),
                                    None if base.join(format!("{name}.rs")).is_file() => {
                                        (base.join(format!("{name}.rs")), false)
                                    }
                                    None => (base.join(name).join("mod.rs"), true),
                                };
                                todo.push((file, child, is_mod_rs));
                            }
                            Some(Tok::Punct('{')) => {
                                inline.push((name.clone(), depth + 1));
                            }
                            _ => {}
                        }
                    }
                }
                Tok::Punct('{') => {
                    depth += 1;
                    attr_path = None;
                }
                Tok::Punct('}') => {
                    if inline.last().is_some_and(|&(_, d)| d == depth) {
                        inline.pop();
                    }
                    depth -= 1;
                    attr_path = None;
                }
                Tok::Punct(';') => attr_path = None,
                _ => {}
            }
            k += 1;
        }
        files.insert(path, File { module, toks });
    }
    files
}

/// One link of a file to another: the referenced file, and where (line, path as written).
type Links = BTreeMap<PathBuf, BTreeMap<PathBuf, (usize, String)>>;

/// The links between the files of one crate: each `crate::` and `super::` reference (a `use`
/// or a path in code), resolved to the deepest module on its path that is a file, when that is
/// neither the crate root nor the referring file. Test code (`#[cfg(test)]` items, inline
/// test modules) is left out: a test may use any module of its crate.
fn links(files: &BTreeMap<PathBuf, File>) -> Links {
    let by_module: BTreeMap<&[String], &PathBuf> = files
        .iter()
        .map(|(p, f)| (f.module.as_slice(), p))
        .collect();
    let mut out: Links = BTreeMap::new();
    for (path, f) in files {
        let toks = &f.toks;
        let mut inline: Vec<(String, usize)> = Vec::new();
        let mut depth = 0;
        // Test code links nothing: after `#[cfg(test)]`, the item up to its `;` or through
        // its braces (`test_from`: the depth its block opened at).
        let mut cfg_test = false;
        let mut test_from: Option<usize> = None;
        let mut k = 0;
        while k < toks.len() {
            let prev_dollar = k > 0 && toks[k - 1].0 == Tok::Punct('$');
            let prev_sep = k > 0 && toks[k - 1].0 == Tok::PathSep;
            let in_test = cfg_test || test_from.is_some();
            let is = |n: usize, t: &Tok| toks.get(k + n).map(|t| &t.0) == Some(t);
            match &toks[k].0 {
                Tok::Punct('#')
                    if is(1, &Tok::Punct('['))
                        && is(2, &Tok::Ident("cfg".into()))
                        && is(3, &Tok::Punct('('))
                        && is(4, &Tok::Ident("test".into()))
                        && is(5, &Tok::Punct(')')) =>
                {
                    cfg_test = test_from.is_none();
                    k += 1;
                }
                Tok::Punct(';') => {
                    cfg_test = false;
                    k += 1;
                }
                Tok::Ident(m) if m == "mod" => {
                    if let (Some(Tok::Ident(name)), Some(Tok::Punct('{'))) =
                        (toks.get(k + 1).map(|t| &t.0), toks.get(k + 2).map(|t| &t.0))
                    {
                        inline.push((name.clone(), depth + 1));
                    }
                    k += 1;
                }
                Tok::Punct('{') => {
                    depth += 1;
                    if cfg_test {
                        cfg_test = false;
                        test_from = Some(depth);
                    }
                    k += 1;
                }
                Tok::Punct('}') => {
                    if inline.last().is_some_and(|&(_, d)| d == depth) {
                        inline.pop();
                    }
                    if test_from == Some(depth) {
                        test_from = None;
                    }
                    depth -= 1;
                    k += 1;
                }
                Tok::Ident(kw)
                    if (kw == "crate" || kw == "super")
                        && !in_test
                        && !prev_dollar
                        && !prev_sep
                        && toks.get(k + 1).map(|t| &t.0) == Some(&Tok::PathSep) =>
                {
                    let line = toks[k].1;
                    let mut base: Vec<String> = Vec::new();
                    let mut written = String::new();
                    if kw == "crate" {
                        written.push_str("crate::");
                        k += 2;
                    } else {
                        base = f.module.clone();
                        base.extend(inline.iter().map(|(n, _)| n.clone()));
                        while toks.get(k).map(|t| &t.0) == Some(&Tok::Ident("super".into()))
                            && toks.get(k + 1).map(|t| &t.0) == Some(&Tok::PathSep)
                        {
                            base.pop();
                            written.push_str("super::");
                            k += 2;
                        }
                    }
                    let mut paths = Vec::new();
                    paths_at(toks, &mut k, &base, &mut paths);
                    for p in paths {
                        let target = (1..=p.len())
                            .rev()
                            .find_map(|n| by_module.get(&p[..n]).copied());
                        let Some(target) = target else { continue };
                        if target == path || files[target].module.is_empty() {
                            continue;
                        }
                        let shown = format!("{written}{}", p[base.len().min(p.len())..].join("::"));
                        out.entry(path.clone())
                            .or_default()
                            .entry(target.clone())
                            .or_insert((line, shown));
                    }
                }
                _ => k += 1,
            }
        }
    }
    out
}

/// The circles of `links`: every strongly connected set of more than one file (each file
/// reaches each other through links), with one shortest loop through its first file, as the
/// files in order (the first repeated at the end).
fn circles(links: &Links) -> Vec<(BTreeSet<PathBuf>, Vec<PathBuf>)> {
    let nodes: BTreeSet<&PathBuf> = links
        .iter()
        .flat_map(|(a, bs)| std::iter::once(a).chain(bs.keys()))
        .collect();
    let reach = |from: &PathBuf| -> BTreeSet<PathBuf> {
        let mut seen = BTreeSet::new();
        let mut todo = vec![from.clone()];
        while let Some(n) = todo.pop() {
            for m in links.get(&n).into_iter().flat_map(|bs| bs.keys()) {
                if seen.insert(m.clone()) {
                    todo.push(m.clone());
                }
            }
        }
        seen
    };
    let reaches: BTreeMap<&PathBuf, BTreeSet<PathBuf>> =
        nodes.iter().map(|&n| (n, reach(n))).collect();
    let mut done: BTreeSet<PathBuf> = BTreeSet::new();
    let mut out = Vec::new();
    for &n in &nodes {
        if done.contains(n) || !reaches[n].contains(n) {
            continue;
        }
        // The set: every file reachable from n that reaches n back.
        let set: BTreeSet<PathBuf> = reaches[n]
            .iter()
            .filter(|m| reaches[*m].contains(n))
            .cloned()
            .collect();
        done.extend(set.iter().cloned());
        // One shortest loop from n back to n inside the set (breadth first).
        let mut prev: BTreeMap<PathBuf, PathBuf> = BTreeMap::new();
        let mut queue = std::collections::VecDeque::from([n.clone()]);
        'search: while let Some(a) = queue.pop_front() {
            for b in links.get(&a).into_iter().flat_map(|bs| bs.keys()) {
                if !set.contains(b) || prev.contains_key(b) {
                    continue;
                }
                prev.insert(b.clone(), a.clone());
                if b == n {
                    break 'search;
                }
                queue.push_back(b.clone());
            }
        }
        let mut lp = vec![n.clone()];
        let mut at = prev[n].clone();
        while &at != n {
            lp.push(at.clone());
            at = prev[&at].clone();
        }
        lp.push(n.clone());
        lp.reverse();
        out.push((set, lp));
    }
    out
}

/// The roots of the crates under `crates_dir`: `<crate>/src/lib.rs`, `<crate>/src/main.rs`,
/// and `<crate>/main.rs` (the binary in `crates/core`).
fn crate_roots(crates_dir: &Path) -> Vec<PathBuf> {
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(crates_dir)
        .map(|rd| {
            rd.flatten()
                .map(|e| e.path())
                .filter(|p| p.is_dir())
                .collect()
        })
        .unwrap_or_default();
    dirs.sort();
    let mut roots = Vec::new();
    for d in dirs {
        for rel in ["src/lib.rs", "src/main.rs", "lib.rs", "main.rs"] {
            if d.join(rel).is_file() {
                roots.push(d.join(rel));
            }
        }
    }
    roots
}

/// Every circle in every crate under `crates_dir`, each as lines naming its files, one loop
/// through them and every link among them (file, line, the path as written, the file it
/// names); and per crate root, how many files it has.
fn crate_circles(crates_dir: &Path) -> (Vec<String>, Vec<(PathBuf, usize)>) {
    let show = |p: &Path| {
        p.strip_prefix(crates_dir)
            .unwrap_or(p)
            .display()
            .to_string()
    };
    let mut found = Vec::new();
    let mut sizes = Vec::new();
    for root in crate_roots(crates_dir) {
        let files = crate_files(&root);
        sizes.push((root.clone(), files.len()));
        let links = links(&files);
        for (set, lp) in circles(&links) {
            let names: Vec<String> = set.iter().map(|p| show(p)).collect();
            let lp: Vec<String> = lp.iter().map(|p| show(p)).collect();
            let mut text = format!(
                "{} files in a circle: {}\n  e.g. {}\n  their links:",
                set.len(),
                names.join(", "),
                lp.join(" -> ")
            );
            for (a, bs) in links.iter().filter(|(a, _)| set.contains(*a)) {
                for (b, (line, written)) in bs.iter().filter(|(b, _)| set.contains(*b)) {
                    text.push_str(&format!(
                        "\n    {}:{line} `{written}` -> {}",
                        show(a),
                        show(b)
                    ));
                }
            }
            found.push(text);
        }
    }
    (found, sizes)
}

#[test]
fn no_circle_of_files_inside_a_crate() {
    let crates_dir = repo_root().join("crates");
    let (found, sizes) = crate_circles(&crates_dir);
    for (root, n) in &sizes {
        eprintln!("{}: {n} files", root.display());
    }
    assert!(sizes.len() >= 8, "crate roots not found: {sizes:?}");
    assert!(
        found.is_empty(),
        "{} circle(s) of files:\n{}\nhint: let the lower file take the value as an argument (or its own options struct) instead of importing the file that calls it",
        found.len(),
        found.join("\n")
    );
}

/// The checker itself, on a small crate written here: a circle through `crate::` paths (in a
/// group, over two lines), `super::` and a `#[path]` module is found with the line of each
/// link; the same names in comments, strings, a raw string, a macro's `$crate`, an inline
/// test module's `super::*` and `#[cfg(test)]` code (which would close a second circle) link
/// nothing; a file over the limit is listed, one under a `dev/`
/// folder or named `*_tests.rs` is not.
#[test]
fn the_checks_find_circles_and_long_files_and_nothing_else() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("crates/demo/src");
    std::fs::create_dir_all(src.join("outer")).unwrap();
    let write = |rel: &str, text: &str| std::fs::write(src.join(rel), text).unwrap();
    write(
        "lib.rs",
        "mod a;\nmod b;\nmod outer;\nmod quiet;\n#[cfg(test)]\n#[path = \"a_tests.rs\"]\nmod tests;\npub struct Root;\n",
    );
    write(
        "a.rs",
        "use crate::{\n    b::{self, B},\n    Root,\n};\npub struct A;\n#[cfg(test)]\nmod tests {\n    use super::*;\n}\n",
    );
    write(
        "b.rs",
        "pub struct B;\nfn f() -> crate::outer::inner::I { todo!() }\n",
    );
    write("outer.rs", "mod inner;\n");
    write(
        "outer/inner.rs",
        "pub struct I;\nfn g() { let _ = super::super::a::A; }\n",
    );
    write(
        "quiet.rs",
        "// crate::a::A\n/* crate::b /* nested */ crate::a */\nconst S: &str = \"crate::a::A\";\nconst R: &str = r#\"super::a \" crate::b\"#;\nconst C: char = '\"';\nmacro_rules! m { () => { $crate::a::A }; }\npub struct Q;\nfn q() { let _ = crate::b::B; }\nfn h<'a>(x: &'a str) -> &'a str { x }\n",
    );
    write("a_tests.rs", "use super::a::A;\nuse crate::b::B;\n");

    let (found, sizes) = crate_circles(&dir.path().join("crates"));
    assert_eq!(sizes.len(), 1, "{sizes:?}");
    assert_eq!(sizes[0].1, 7, "every file of the module tree: {sizes:?}");
    assert_eq!(found.len(), 1, "{found:#?}");
    let c = &found[0];
    assert!(
        c.starts_with("3 files in a circle: demo/src/a.rs, demo/src/b.rs, demo/src/outer/inner.rs\n  e.g. demo/src/a.rs -> demo/src/b.rs -> demo/src/outer/inner.rs -> demo/src/a.rs"),
        "{c}"
    );
    assert!(
        c.contains("demo/src/a.rs:1 `crate::b` -> demo/src/b.rs"),
        "{c}"
    );
    assert!(
        c.contains("demo/src/b.rs:2 `crate::outer::inner::I` -> demo/src/outer/inner.rs"),
        "{c}"
    );
    assert!(
        c.contains("demo/src/outer/inner.rs:2 `super::super::a::A` -> demo/src/a.rs"),
        "{c}"
    );
    assert_eq!(
        c.matches(" -> ").count(),
        3 + 3,
        "the loop and three links: {c}"
    );
    assert!(!c.contains("quiet") && !c.contains("a_tests"), "{c}");

    // Without the link back, no circle.
    write("outer/inner.rs", "pub struct I;\n");
    let (found, _) = crate_circles(&dir.path().join("crates"));
    assert!(found.is_empty(), "{found:#?}");

    let many = "x = 1\n".repeat(MAX_LINES + 1);
    std::fs::create_dir_all(dir.path().join("scripts/dev")).unwrap();
    std::fs::write(dir.path().join("scripts/big.py"), &many).unwrap();
    std::fs::write(dir.path().join("scripts/dev/probe.py"), &many).unwrap();
    std::fs::write(dir.path().join("scripts/test_big.py"), &many).unwrap();
    std::fs::write(src.join("big_tests.rs"), &many).unwrap();
    std::fs::write(
        dir.path().join("scripts/ok.py"),
        "x = 1\n".repeat(MAX_LINES),
    )
    .unwrap();
    let (long, counted) = long_files(dir.path());
    assert_eq!(long, [(PathBuf::from("scripts/big.py"), MAX_LINES + 1)]);
    assert_eq!(
        counted, 8,
        "6 crate files (not a_tests.rs, big_tests.rs), big.py and ok.py"
    );
}
