"""Blender-version differences, in one place.

The target is Debian's Blender 3.4.1; 4.x is handled where the difference is known. Every
other module calls these helpers instead of testing `bpy.app.version` itself or touching a
setting whose name, place or unit depends on the version: Principled BSDF inputs, the
displacement method, light power, smooth shading, shadow visibility, the output file
format and colour management (view transform and look). The Principled BSDF's differences
(inputs renamed in 4.0, the v2 node rendered as 3.4's v1) are in `compat_principled.py`, one
concern of its own, and re-exported here: callers use `compat.principled_input` etc.
"""

import math
import os

import bpy

from compat_principled import (  # noqa: F401 (re-exported: callers use compat.*)
    PARITY,
    coat_gtr1_lobes,
    coat_mis_shares,
    coat_v1_lobes,
    disney_diffuse,
    parity_settings,
    principled_input,
    principled_output,
    principled_value,
    setup_principled,
)

VERSION = bpy.app.version


def version_string():
    return bpy.app.version_string.split(" ")[0]


def is_module():
    """Whether bpy runs as a Python module (PyPI's `bpy` wheel) rather than inside Blender."""
    return bool(getattr(bpy.app, "is_module", False)) or not bpy.app.binary_path


def factory_startup():
    """What `blender --factory-startup` gives, for bpy as a module (which has no command
    line): factory preferences (no user add-ons, default Cycles settings) and the factory
    startup scene, which the builder clears like Blender's."""
    bpy.ops.wm.read_factory_settings(use_empty=False)


def set_view_look(view_settings, view_transform, look):
    """Set the view transform and look.

    3.x spells looks without the view prefix (`Very High Contrast`); 4.x prefixes them with
    the view (`Filmic - Very High Contrast`, `AgX - Very High Contrast`). Scene files use the
    3.x spelling.
    """
    view_settings.view_transform = view_transform
    if look in ("", "None", "NONE"):
        view_settings.look = "None"
        return
    candidates = [look, "%s - %s" % (view_transform, look)]
    errors = []
    for name in candidates:
        try:
            view_settings.look = name
            return
        except TypeError as exc:
            errors.append(str(exc))
    raise ValueError(
        "look `%s` is not available for view transform `%s` in Blender %s: %s"
        % (look, view_transform, version_string(), errors[-1])
    )


def set_color_management(scene, view_transform, look, exposure, gamma):
    """The scene's colour management: sRGB display and sequencer, the view transform and look
    ([`set_view_look`]), exposure and gamma, no curves. The colour-space names are those of
    the 3.x and 4.x OpenColorIO configs."""
    scene.display_settings.display_device = "sRGB"
    set_view_look(scene.view_settings, view_transform, look)
    scene.view_settings.exposure = exposure
    scene.view_settings.gamma = gamma
    scene.view_settings.use_curve_mapping = False
    scene.sequencer_colorspace_settings.name = "sRGB"


def area_light_energy(watts):
    """Area-light power in Blender's unit for the scene file's watts, which are 3.x watts.

    Blender 4.0 changed how an area light's power spreads: the same `energy` lights a diffuse
    plane 4/pi brighter (measured: 0.8601 vs 0.6763 mean radiance under one 1 m square light,
    ratio 1.272, with sun and point lights equal to 0.3%). So 4.0+ gets pi/4 of the watts.
    """
    if VERSION >= (4, 0, 0):
        return watts * math.pi / 4.0
    return watts


def sun_strength(irradiance):
    """Sun-light strength in Blender's unit for the scene file's W/m^2 (same in 3.x and 4.x)."""
    return irradiance


def _set_media_type(image_settings, media_type):
    """Blender 5.0 splits the output format into a media type (`IMAGE`,
    `VIDEO`) and a file format: `OPEN_EXR_MULTILAYER` is only offered once the media type is
    `MULTI_LAYER_IMAGE` (measured on bpy 5.0). Returns whether this Blender has media
    types."""
    if hasattr(image_settings, "media_type"):
        image_settings.media_type = media_type
        return True
    return False


def set_png_output(image_settings, compression=None):
    """Save renders as 8-bit RGB PNG (`compression` in percent; None keeps Blender's)."""
    _set_media_type(image_settings, "IMAGE")
    image_settings.file_format = "PNG"
    image_settings.color_mode = "RGB"
    image_settings.color_depth = "8"
    if compression is not None:
        image_settings.compression = compression


def set_exr_multilayer_output(image_settings, codec):
    """Save renders as 32-bit float RGBA multilayer OpenEXR with `codec` (e.g. `RLE`)."""
    _set_media_type(image_settings, "MULTI_LAYER_IMAGE")
    image_settings.file_format = "OPEN_EXR_MULTILAYER"
    image_settings.color_mode = "RGBA"
    image_settings.color_depth = "32"
    image_settings.exr_codec = codec


def setup_bump(node):
    """Make a Bump node behave as in 3.x: 4.4 added a `Filter Width` input (in pixels) whose
    default 0.1 gives a sharper, noisier bump than before; 1.0 is the earlier fixed width
    (what Blender itself sets when it opens an older file)."""
    width = node.inputs.get("Filter Width")
    if width is not None:
        width.default_value = 1.0


def shade_smooth(mesh):
    """Smooth-shade every face (4.1 has a dedicated call; setting the flag works everywhere).

    4.1 also removed `Mesh.use_auto_smooth` (auto smooth became a modifier); the bridge never
    uses it: every mesh is either all smooth or all flat."""
    if hasattr(mesh, "shade_smooth"):
        mesh.shade_smooth()
    else:
        for poly in mesh.polygons:
            poly.use_smooth = True


def displacement_method(mat):
    """`BUMP`, `DISPLACEMENT` or `BOTH`: on `mat.cycles` up to 4.0, on the material since 4.1."""
    if hasattr(mat, "displacement_method"):
        return mat.displacement_method
    return mat.cycles.displacement_method


def set_displacement_method(mat, method):
    """Set what [`displacement_method`] reads."""
    if hasattr(mat, "displacement_method"):
        mat.displacement_method = method
    else:
        mat.cycles.displacement_method = method


def true_displacement_method():
    """The displacement method of a material that displaces, rendering as 3.4's `BOTH`.

    3.4's `BOTH` is true displacement plus a bump that Cycles derives from the displacement
    output itself, mostly a mild one there (`BOTH` 0.5-4% darker than `DISPLACEMENT` on the
    three materials below). Cycles 4.x computes that derived bump with the undisplaced surface's
    full differentials instead of 3.4's compact ones (kernel `svm_node_set_bump`, Blender
    issue 111588) and a filter width of its own, and the same `BOTH` shades much rougher:
    backdrops 12-27% darker on bpy 4.5 (`jagged_cliff_rock` -26.5%, `copper_chainmail` -14%,
    `corrugated_iron` -12%; a white diffuse surface on the displaced rock -21%), with the
    same geometry (depth of backdrop pixels equal to 0.01%). Without the derived bump
    (`DISPLACEMENT`) 4.5 is within 1.1% of 3.4's `BOTH` on those three, and the material's
    own Bump node (`setup_bump`) still carries its fine relief. Not every material: 3.4's
    derived bump darkens `gold_chainmail` by 17%, so there 4.5 is +10.7% (+7.3% with
    `BOTH`; `woven_steel` +9.8%, -0.0% with `BOTH`); over the 51 displacing materials 38
    are within 3% (7 with `BOTH`); no Bump node rebuilds 3.4's derived bump. Measured with
    `dev/displace_parity_probe.py`, docs/notes/materials.md "Displaced surfaces on 3.4 and
    4.5"; measured on 4.5 only, applied from 4.0 (issue 111588's change)."""
    return "BOTH" if VERSION < (4, 0, 0) else "DISPLACEMENT"


def set_adaptive_subdivision(obj, modifier, enabled):
    """Adaptive subdivision (true displacement) of `obj`, whose last modifier `modifier` is a
    subdivision modifier (None when disabled and absent). Up to 4.5 a Cycles object setting
    (the scene's `dicing_rate` applies); 5.0 moved it onto the modifier, in pixels, set to
    the same rate."""
    if modifier is not None and hasattr(modifier, "use_adaptive_subdivision"):
        modifier.use_adaptive_subdivision = enabled
        if enabled:
            modifier.adaptive_space = "PIXEL"
            modifier.adaptive_pixel_size = bpy.context.scene.cycles.dicing_rate
    elif hasattr(obj.cycles, "use_adaptive_subdivision"):
        obj.cycles.use_adaptive_subdivision = enabled


def set_experimental_features(scene, enabled):
    """Cycles' experimental feature set (adaptive subdivision needs it up to 4.5; 5.0 made
    adaptive subdivision a regular feature and removed the setting)."""
    if hasattr(scene.cycles, "feature_set"):
        scene.cycles.feature_set = "EXPERIMENTAL" if enabled else "SUPPORTED"


def apply_levers(cycles, r):
    """Cycles 4.x levers from a scene file's `render` (absent: this version's default, and
    ignored where this build lacks them, as 3.4 lacks all four):

    - `light_tree` (4.0+): `use_light_tree` (absent: off while `PARITY["light_tree"]`, as
      3.4 renders);
    - `path_guiding` (CPU only, builds with it): surface guiding;
    - `blue_noise` (4.2+): `BLUE_NOISE` pattern when true, `TABULATED_SOBOL` when false;
    - `denoise`: OpenImageDenoise on the combined (RGB) pass only: Cycles never denoises
      the index, depth, normal or colour passes, so masks, depth and normals are unchanged.
    """
    # The scene (and its Cycles settings) outlives one scene file: an absent lever is reset
    # to the version's default, never left as the previous file set it.
    def default(name):
        return cycles.bl_rna.properties[name].default

    if hasattr(cycles, "use_light_tree"):
        light_tree = r.get("light_tree")
        if light_tree is None:
            light_tree = False if PARITY["light_tree"] else default("use_light_tree")
        cycles.use_light_tree = light_tree
    if hasattr(cycles, "use_guiding"):
        guiding = r.get("path_guiding")
        cycles.use_guiding = default("use_guiding") if guiding is None else guiding
        cycles.use_surface_guiding = default("use_surface_guiding") if guiding is None else guiding
        cycles.use_volume_guiding = default("use_volume_guiding") if guiding is None else False
    if hasattr(cycles, "sampling_pattern"):
        blue = r.get("blue_noise")
        try:
            if blue is None:
                cycles.sampling_pattern = default("sampling_pattern") or "AUTOMATIC"
            else:
                cycles.sampling_pattern = "BLUE_NOISE" if blue else "TABULATED_SOBOL"
        except TypeError:  # before 4.2: no such patterns
            pass
    if r.get("denoise") and features()["oidn"]:
        cycles.use_denoising = True
        cycles.denoiser = "OPENIMAGEDENOISE"
        cycles.denoising_input_passes = "RGB_ALBEDO_NORMAL"
        if hasattr(cycles, "denoising_use_gpu"):
            cycles.denoising_use_gpu = denoise_on_gpu()


def denoise_on_gpu():
    """Whether OpenImageDenoise runs on this worker's GPU (4.1+, `denoising_use_gpu`): on a
    GPU worker yes, so the denoiser does not take the host cores its scene builds need (Cycles
    falls back to the CPU where OIDN does not support the GPU); on a CPU worker no. OIDN on
    either: the same denoiser as the CPU's, not OptiX's, so a GPU run's images match a CPU
    run's within the denoiser's own rounding."""
    return DEVICE[0] != "CPU"


def set_cast_shadow(obj, enabled):
    """Whether an object casts shadows in Cycles (`visible_shadow` since 3.0)."""
    if hasattr(obj, "visible_shadow"):
        obj.visible_shadow = enabled
    else:
        obj.cycles_visibility.shadow = enabled


def light_mis(light, enabled=None):
    """A light's multiple importance sampling (`light.cycles.use_multiple_importance_sampling`
    up to 4.5 at least; `light.use_multiple_importance_sampling` where Cycles' settings moved
    onto the light): returns the old value, sets `enabled` unless None."""
    owner = light.cycles if hasattr(getattr(light, "cycles", None),
                                    "use_multiple_importance_sampling") else light
    old = owner.use_multiple_importance_sampling
    if enabled is not None:
        owner.use_multiple_importance_sampling = enabled
    return old


def cycles_devices():
    """Names of the Cycles device types compiled in (always includes CPU)."""
    devices = ["CPU"]
    try:
        prefs = bpy.context.preferences.addons["cycles"].preferences
        for item in prefs.get_device_types(bpy.context):
            if item[0] not in ("NONE", "CPU") and item[0] not in devices:
                devices.append(item[0])
    except Exception:  # device probing is informational only
        pass
    return devices


def cycles_gpus():
    """The GPUs Cycles can render on: `[{"kind": "CUDA"|"OPTIX"|"HIP"|..., "name", "id"}]`, in
    the order Cycles lists them (the index a worker is pinned to counts within one kind)."""
    out = []
    try:
        prefs = bpy.context.preferences.addons["cycles"].preferences
        for kind in cycles_devices():
            if kind == "CPU":
                continue
            for dev in prefs.get_devices_for_type(kind):
                if dev.type != "CPU":
                    out.append({"kind": kind, "name": dev.name, "id": dev.id})
    except Exception:  # device probing is informational only
        pass
    return out


def cuda_kernels(lib=None):
    """The CUDA kernels this build's Cycles ships (`lib/kernel_sm_XY.cubin*` and
    `lib/kernel_compute_XY.ptx*` beside the Cycles add-on, or in `lib`), as compute capabilities
    10 x major + minor: `{"cubin": [50, ..., 89, 120], "ptx": [75], "prepared": []}`; empty
    lists where the build has none (Debian's Blender). Cycles loads the cubin made for the GPU's
    exact compute capability, else has the driver compile the nearest older PTX at the first
    render, which takes minutes (the `--device` docs). `prepared`: the cubins that
    `scripts/cuda_kernels.py` compiled ahead of time and listed in `lib/clevrtex-prepared.json`
    (also in `cubin`: Cycles loads them as its own)."""
    out = {"cubin": [], "ptx": [], "prepared": []}
    try:
        if lib is None:
            import sys

            cycles = sys.modules.get("cycles")
            lib = os.path.join(os.path.dirname(cycles.__file__), "lib")
        for name in sorted(os.listdir(lib)):
            for kind, prefix, ext in (("cubin", "kernel_sm_", ".cubin"),
                                      ("ptx", "kernel_compute_", ".ptx")):
                rest = name[len(prefix):] if name.startswith(prefix) else ""
                digits = rest.split(".")[0]
                if digits.isdigit() and rest[len(digits):].startswith(ext):
                    out[kind].append(int(digits))
    except Exception:  # informational only: a build without the folder ships none
        pass
    try:
        import json

        with open(os.path.join(lib, "clevrtex-prepared.json")) as f:
            listed = json.load(f).get("kernels", [])
        out["prepared"] = [int(k["sm"]) for k in listed if int(k["sm"]) in out["cubin"]]
    except Exception:  # informational only: none prepared
        pass
    for kind in out:
        out[kind] = sorted(set(out[kind]))
    return out


def features():
    """What this build offers beyond 3.4's Cycles: OpenImageDenoise, path guiding (CPU only),
    the light tree (4.0+) and the sampling patterns (names)."""
    out = {"oidn": False, "path_guiding": False}
    try:
        import _cycles

        out["oidn"] = bool(getattr(_cycles, "with_openimagedenoise", False))
        out["path_guiding"] = bool(getattr(_cycles, "with_path_guiding", False))
    except Exception:  # informational only
        pass
    cycles = bpy.context.scene.cycles
    out["light_tree"] = hasattr(cycles, "use_light_tree")
    try:
        out["sampling_patterns"] = [
            item.identifier for item in cycles.bl_rna.properties["sampling_pattern"].enum_items
        ]
    except Exception:
        out["sampling_patterns"] = []
    return out


# The device this worker renders on: ("CPU", 0) or (GPU kind, index within it); set once by
# the worker from its `--device` argument.
DEVICE = ("CPU", 0)


def apply_device(scene):
    """Render `scene` on this worker's [`DEVICE`] ([`use_device`])."""
    use_device(scene, DEVICE[0], DEVICE[1])


def use_device(scene, kind, index):
    """Render `scene` on device `kind` (`CPU`, `CUDA`, `OPTIX`, `HIP`, ...): for a GPU, enable
    exactly the `index`-th GPU of that kind (one worker per GPU) and nothing else."""
    if kind == "CPU":
        scene.cycles.device = "CPU"
        return
    prefs = bpy.context.preferences.addons["cycles"].preferences
    prefs.compute_device_type = kind
    gpus = [d for d in prefs.get_devices_for_type(kind) if d.type != "CPU"]
    if not 0 <= index < len(gpus):
        raise ValueError("no %s device %d (this worker sees %d)" % (kind, index, len(gpus)))
    for d in prefs.get_devices_for_type(kind):
        d.use = False
    gpus[index].use = True
    scene.cycles.device = "GPU"


TEAPOT_MESH = os.path.join(os.path.dirname(os.path.abspath(__file__)), "teapot_mesh.json")


def teapot_mesh():
    """The Utah teapot's vertices and faces, as Blender 3.4's bundled "extra objects" add-on
    makes them (`make_teapot("1", 6)`), from `teapot_mesh.json`.

    Blender 4.2+ moved that add-on to the online extensions platform (absent from PyPI's
    `bpy` and from offline installs), and Debian's build cannot enable it headless; the mesh
    is stored once instead (regenerate with `dev/dump_teapot.py`), which also makes the
    teapot the same vertex for vertex on every Blender version.
    """
    import json

    with open(TEAPOT_MESH, "r", encoding="utf-8") as f:
        doc = json.load(f)
    return [tuple(v) for v in doc["verts"]], [tuple(f) for f in doc["faces"]]


def set_aov_name(node, name):
    """Name the AOV an AOV Output node writes: `aov_name` since 4.0, `name` in 3.x."""
    if hasattr(node, "aov_name"):
        node.aov_name = name
    else:
        node.name = name


def remove_aov(view_layer, index):
    """Remove the view layer's AOV number `index`: `aovs.remove` where it exists (4.x);
    3.x has only the operator, which removes the active AOV of the context's view layer."""
    aovs = view_layer.aovs
    if hasattr(aovs, "remove"):
        aovs.remove(aovs[index])
        return
    view_layer.active_aov_index = index
    bpy.ops.scene.view_layer_remove_aov()


def add_group_output(ng, name, socket_type):
    """Add an output socket `name` of `socket_type` (e.g. `NodeSocketColor`) to node group
    `ng`: `ng.outputs.new` in 3.x, `ng.interface.new_socket` since 4.0."""
    if hasattr(ng, "interface"):
        return ng.interface.new_socket(name, in_out="OUTPUT", socket_type=socket_type)
    return ng.outputs.new(socket_type, name)
