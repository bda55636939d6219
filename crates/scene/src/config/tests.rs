use super::*;

#[test]
fn material_set_replaces_only_textured_lists() {
    use clevrtex_materials::Set;
    let cat = Catalogue::builtin().unwrap();
    let ood = cat.names(Set::Ood);
    let mut full = Config::builtin("full").unwrap();
    assert!(full.use_material_set(&cat, Set::Ood).unwrap());
    assert_eq!(full.objects.materials, ood);
    assert_eq!(full.background.materials, ood);
    // vbg: rubber/metal objects stay, the textured backdrop changes.
    let mut vbg = Config::builtin("vbg").unwrap();
    let objects = vbg.objects.materials.clone();
    assert!(vbg.use_material_set(&cat, Set::Ood).unwrap());
    assert_eq!(vbg.objects.materials, objects);
    assert_eq!(vbg.background.materials, ood);
    // clevr and grassbg's grass: nothing textured to replace, or only the objects.
    let mut clevr = Config::builtin("clevr").unwrap();
    assert!(!clevr.use_material_set(&cat, Set::Ood).unwrap());
    let mut grass = Config::builtin("grassbg").unwrap();
    assert!(grass.use_material_set(&cat, Set::Ood).unwrap());
    assert_eq!(grass.background.materials, ["mossy_forest_grass"]);
    // An empty set (no `--materials`) is an error.
    assert!(full.use_material_set(&cat, Set::User).is_err());
}

#[test]
fn every_builtin_variant_loads() {
    for name in Config::variant_names() {
        let c = Config::builtin(name).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(c.name, name);
    }
}

#[test]
fn base_scene_overrides_merge_over_the_builtin() {
    let text = include_str!("../../../../configs/camo.json").replacen(
        "{",
        r#"{"base_scene": {"render": {"samples": 7}, "placement": {"margin": 0.1}},"#,
        1,
    );
    let c = Config::from_json_str(&text, "my.json").unwrap();
    assert_eq!(c.base.render.samples, 7);
    assert_eq!(c.base.render.width, 320);
    assert_eq!(c.base.placement.margin, 0.1);
    assert_eq!(c.base.placement.min_dist, 0.25);
}

#[test]
fn shadow_samples_come_from_the_config_and_zero_is_refused() {
    let with = |v: &str| {
        include_str!("../../../../configs/full.json").replacen(
            "{",
            &format!(r#"{{"base_scene": {{"render": {{"shadow_samples": {v}}}}},"#),
            1,
        )
    };
    let c = Config::from_json_str(&with("32"), "my.json").unwrap();
    assert_eq!(c.base.render.shadow_samples, Some(32));
    assert_eq!(
        Config::builtin("full").unwrap().base.render.shadow_samples,
        None
    );
    let e = Config::from_json_str(&with("0"), "my.json")
        .unwrap_err()
        .to_string();
    assert!(e.contains("base_scene.render.shadow_samples"), "{e}");
}

#[test]
fn unknown_key_names_file_and_key() {
    let text = include_str!("../../../../configs/full.json").replacen(
        "\"shapes\"",
        "\"shapez\": [], \"shapes\"",
        1,
    );
    let e = Config::from_json_str(&text, "my.json").unwrap_err();
    assert_eq!(e.file, "my.json");
    assert_eq!(e.key, "objects.shapez");
    assert!(e.problem.contains("shapez"), "{e}");
    let text = include_str!("../../../../configs/full.json").replacen(
        "{",
        r#"{"base_scene": {"camera": {"fov": 1}},"#,
        1,
    );
    let e = Config::from_json_str(&text, "my.json").unwrap_err();
    assert_eq!(e.key, "base_scene.camera.fov");
    assert!(e.problem.contains("fov"), "{e}");
}

#[test]
fn unknown_names_and_empty_lists_are_errors() {
    let full = include_str!("../../../../configs/full.json");
    let e =
        Config::from_json_str(&full.replacen("\"monkey\"", "\"donkey\"", 1), "f.json").unwrap_err();
    assert_eq!(e.key, "objects.shapes[3]");
    assert_eq!(e.value.as_deref(), Some("donkey"));
    let e = Config::from_json_str(
        &full.replacen(
            "\"sets\": [\n        \"main\"\n      ]",
            "\"include\": [\"velvet\"]",
            1,
        ),
        "f.json",
    )
    .unwrap_err();
    assert_eq!(e.key, "objects.materials.include[0]", "{e}");
    let e = Config::from_json_str(
        &full.replacen("\"sets\": [\n        \"main\"\n      ]", "\"sets\": []", 1),
        "f.json",
    )
    .unwrap_err();
    assert_eq!(e.key, "objects.materials", "{e}");
    assert!(e.to_string().contains("\nhint: "));
}

/// The public generator's configs exclude its CLEVR base materials (`"exclude":
/// ["tabularasa", "rubber", "mymetal"]`), which `--materials` never adds: accepted.
/// Including one names the built-in that plays its part.
#[test]
fn the_generators_clevr_base_names_may_be_excluded_not_included() {
    let full = include_str!("../../../../configs/full.json");
    let main = "\"sets\": [\n        \"main\"\n      ]";
    let with = |sel: &str| full.replacen(main, sel, 1);
    let c = Config::from_json_str(
        &with(r#""sets": ["main"], "exclude": ["tabularasa", "rubber", "mymetal"]"#),
        "f.json",
    )
    .unwrap();
    assert_eq!(c.objects.materials.len(), 61);
    let e = Config::from_json_str(&with(r#""include": ["tabularasa"]"#), "f.json").unwrap_err();
    assert_eq!(e.key, "objects.materials.include[0]", "{e}");
    assert!(e.hint.contains("built-in `plain`"), "{e}");
}

#[test]
fn srgb_to_linear() {
    let c = ColorRule {
        name: "x".into(),
        srgb: [0, 255, 128],
    };
    let l = c.linear();
    assert_eq!(l[0], 0.0);
    assert!((l[1] - 1.0).abs() < 1e-12);
    assert!((l[2] - 0.2158605).abs() < 1e-6);
}
