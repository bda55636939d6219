//! Trust boundaries on the write side (issue 21, docs/security.md): a value read from a scene
//! file never becomes a path outside `--out`, and no command deletes what its run did not
//! create.

use std::path::Path;

use crate::util::{clevrtex, fake_blender, text};

/// `clevrtex sample` of one `clevr` scene into `dir/scenes`; the path of its scene file.
fn one_scene(dir: &Path) -> std::path::PathBuf {
    let scenes = dir.join("scenes");
    let out = clevrtex()
        .args(["sample", "--variant", "clevr", "-n", "1", "--out"])
        .arg(&scenes)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let mut found = Vec::new();
    let mut stack = vec![scenes];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(d).unwrap().flatten() {
            if e.path().is_dir() {
                stack.push(e.path());
            } else if e.path().extension().is_some_and(|x| x == "json") {
                found.push(e.path());
            }
        }
    }
    assert_eq!(found.len(), 1, "{found:?}");
    found.pop().unwrap()
}

/// Set `key` of the scene file at `path` to `value`.
fn edit(path: &Path, key: &str, value: serde_json::Value) {
    let mut scene: serde_json::Value =
        serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
    scene[key] = value;
    std::fs::write(path, scene.to_string()).unwrap();
}

/// A scene file whose `stem` or `variant` is a path (absolute, or with `..`) is refused before
/// anything is written or removed: before the check, `"stem": "<dir>/victim/x"` wrote outside
/// `--out` and the job's clean-up deleted a pre-existing `x-0/` folder of the user's there.
#[test]
fn render_refuses_scene_names_that_are_paths_and_deletes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let scene = one_scene(dir.path());
    let victim = dir.path().join("victim");
    for (key, value) in [
        ("stem", format!("{}/x", victim.display())),
        ("stem", "../../victim/x".to_string()),
        ("stem", "CLEVRTEX_clevr_000001".to_string()),
        ("variant", format!("{}", victim.display())),
        ("variant", "..".to_string()),
        ("split", "../train".to_string()),
    ] {
        // The user's own files, which nothing may touch: a folder named like the job's work
        // folder, and one named like the sample's.
        for sub in ["x-0", "x-1", "clevrtex_clevr/0"] {
            std::fs::create_dir_all(victim.join(sub)).unwrap();
            std::fs::write(victim.join(sub).join("keep.txt"), b"mine").unwrap();
        }
        let original = std::fs::read(&scene).unwrap();
        edit(&scene, key, serde_json::Value::String(value.clone()));
        let out_dir = dir.path().join("out");
        let out = clevrtex()
            .env("FAKE_BLENDER_MODE", "crash")
            .env_remove("CLEVRTEX_BLENDER")
            .env("TMPDIR", &victim)
            .args(["render", "--workers", "1", "--retries", "0", "--blender"])
            .arg(fake_blender())
            .arg("--out")
            .arg(&out_dir)
            .arg(&scene)
            .output()
            .unwrap();
        let t = text(&out);
        assert_eq!(out.status.code(), Some(1), "{key} = {value}: {t}");
        assert!(
            t.contains(&format!("`{key}`")) && t.contains(&scene.display().to_string()),
            "{key} = {value}: the message names the file and the key: {t}"
        );
        for sub in ["x-0", "x-1", "clevrtex_clevr/0"] {
            assert!(
                victim.join(sub).join("keep.txt").exists(),
                "{key} = {value}: {sub}/keep.txt was deleted: {t}"
            );
        }
        let mut outside = Vec::new();
        for e in std::fs::read_dir(&victim).unwrap().flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            if !["x-0", "x-1", "clevrtex_clevr"].contains(&name.as_str()) {
                outside.push(name);
            }
        }
        assert!(
            outside.is_empty(),
            "{key} = {value}: written outside --out: {outside:?}"
        );
        std::fs::write(&scene, original).unwrap();
    }
}
