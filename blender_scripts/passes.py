"""The one table of render passes on the Blender side.

Keys are the pass names of the scene file; values give the view-layer `use_pass_*` flags the
pass needs (`flags`) and the layers it puts into the multilayer `passes.exr` as
{layer: channel letters} (`exr`; the files hold `ViewLayer.<layer>.<letter>`). The Rust pass
table (`crates/scene/src/passes.rs`) lists the same passes with the same EXR layers; the test
`generate::pass_table_rust_and_bridge_agree` checks both, in Blender's own Python. Adding a
pass is one entry here plus one there. Keep it a plain literal. `aovs` names the view layer's
AOVs (name: type) a pass needs; they exist only while such a pass is requested. `render` says which render
makes the pass: `final` (the default) or `shadow` (the shadow pass's own renders, whose
files hold the pass's layers instead of `passes.exr`).
"""

PASSES = {
    "rgb": {"flags": ["use_pass_combined"], "exr": {}},
    "mask": {"flags": ["use_pass_object_index"], "exr": {"IndexOB": "X"}},
    "depth": {"flags": ["use_pass_z"], "exr": {"Depth": "Z"}},
    "normal": {"flags": ["use_pass_normal"], "exr": {"Normal": "XYZ"}},
    # The material's base colour (metals: their colour), from a colour AOV that every
    # catalogue material writes when this pass is requested (materials.build_material with
    # context["albedo"]); not Cycles' diffuse colour, which is black on metals and white
    # under sheen.
    "albedo": {"flags": [], "aovs": {"BaseCol": "COLOR"}, "exr": {"BaseCol": "RGB"}},
    # From its own render (`shadow.exr`, builder.OneRenderShadow: red without object
    # shadows, green with), not the final render.
    "shadow": {"flags": ["use_pass_diffuse_direct"], "exr": {"DiffDir": "RGB"},
               "render": "shadow"},
}

# Passes whose data lives in the multilayer `passes.exr` of the final render (rgb goes to
# `rgb.png` instead, shadow to its own renders).
EXR_PASSES = tuple(name for name, p in PASSES.items()
                   if p["exr"] and p.get("render", "final") == "final")


def final_passes(pass_names):
    """The passes of `pass_names` that the final render makes (all but shadow)."""
    return [n for n in pass_names if PASSES[n].get("render", "final") == "final"]


def all_flags():
    flags = set()
    for p in PASSES.values():
        flags.update(p["flags"])
    return sorted(flags)


def enable(view_layer, pass_names):
    """Enable exactly the view-layer passes `pass_names` need; disable every other one."""
    unknown = [name for name in pass_names if name not in PASSES]
    if unknown:
        raise ValueError("unknown pass `%s`; known: %s" % (unknown[0], ", ".join(PASSES)))
    wanted = set()
    for name in pass_names:
        wanted.update(PASSES[name]["flags"])
    for flag in all_flags():
        # Combined cannot really be skipped by Cycles; leaving it on costs nothing extra.
        setattr(view_layer, flag, flag in wanted or flag == "use_pass_combined")
    aovs = {}
    for name in pass_names:
        aovs.update(PASSES[name].get("aovs", {}))
    import compat  # here, not at the top: this module is also read outside Blender

    for i in reversed(range(len(view_layer.aovs))):
        if view_layer.aovs[i].name not in aovs:
            compat.remove_aov(view_layer, i)
    have = set(a.name for a in view_layer.aovs)
    for name, kind in sorted(aovs.items()):
        if name not in have:
            aov = view_layer.aovs.add()
            aov.name = name
            aov.type = kind
