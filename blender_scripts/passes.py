"""The one table of render passes on the Blender side.

Keys are the pass names of the scene file (the Rust `Pass` enum, which a Rust test checks
against this table); values are the view-layer `use_pass_*` flags the pass needs. Adding a
pass is one line here plus one variant there. Keep it a plain literal, one pass per line.
"""

PASSES = {
    "rgb": ["use_pass_combined"],
    "mask": ["use_pass_object_index"],
    "depth": ["use_pass_z"],
    "normal": ["use_pass_normal"],
    "albedo": ["use_pass_diffuse_color"],
    "shadow": ["use_pass_diffuse_direct", "use_pass_diffuse_color", "use_pass_glossy_direct", "use_pass_glossy_color"],
}

# Passes whose data lives in the multilayer `passes.exr` (rgb goes to `rgb.png` instead).
EXR_PASSES = ("mask", "depth", "normal", "albedo", "shadow")


def all_flags():
    flags = set()
    for needed in PASSES.values():
        flags.update(needed)
    return sorted(flags)


def enable(view_layer, pass_names):
    """Enable exactly the view-layer passes `pass_names` need; disable every other one."""
    unknown = [name for name in pass_names if name not in PASSES]
    if unknown:
        raise ValueError("unknown pass `%s`; known: %s" % (unknown[0], ", ".join(PASSES)))
    wanted = set()
    for name in pass_names:
        wanted.update(PASSES[name])
    for flag in all_flags():
        # Combined cannot really be skipped by Cycles; leaving it on costs nothing extra.
        setattr(view_layer, flag, flag in wanted or flag == "use_pass_combined")
