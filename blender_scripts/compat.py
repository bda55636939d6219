"""Blender-version differences, in one place.

The target is Debian's Blender 3.4.1; 4.x is handled where the difference is known. Every
other module calls these helpers instead of testing `bpy.app.version` itself or touching a
setting whose name, place or unit depends on the version: Principled BSDF inputs, the
displacement method, light power, smooth shading, shadow visibility, the output file
format and colour management (view transform and look).
"""

import math
import os

import bpy

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


# Principled BSDF inputs renamed in 4.0, by their 3.x name; None: removed without a
# replacement (4.x scatters the base colour).
_PRINCIPLED_4X = {
    "Subsurface": "Subsurface Weight",
    "Subsurface Color": None,
    "Specular": "Specular IOR Level",
    "Transmission": "Transmission Weight",
    "Coat": "Coat Weight",
    "Clearcoat": "Coat Weight",
    "Clearcoat Roughness": "Coat Roughness",
    "Sheen": "Sheen Weight",
    "Emission": "Emission Color",
}


def principled_input(node, name):
    """A principled BSDF input by its 3.x name, mapped to the 4.x name where it changed;
    None where this version has no such input."""
    if name in node.inputs:
        return node.inputs[name]
    new = _PRINCIPLED_4X.get(name, name)
    return None if new is None else node.inputs[new]


# Principled BSDF v2 (4.0+) rendering as 3.4's v1 (issue 24, docs/notes/performance.md "Blender
# 3.4, 4.5 and 5.0 at parity"). Scene files and material recipes are in 3.x terms; each
# switch below is one difference, on by default (the study script dev/parity_measure.py
# turns them off one at a time with `--parity-off`):
#
# - `coat`: v2's coat is a physical layer of weight w and IOR 1.5; v1's clearcoat was a
#   quarter as strong (0.25 w of an F0 0.04 lobe), so Blender's own versioning of 3.x files
#   multiplies Clearcoat by 0.25 (versioning_400.cc, version_principled_bsdf_coat). At full
#   strength the sharp coats (roughness 0-0.15) of most recipes reflect the small studio
#   lights 4x as brightly: the caustic fireflies of 4.5, and a darker base under the coat.
# - `sheen`: v2's sheen is a microfiber layer; Blender's versioning multiplies a constant
#   Sheen by 0.2 with a white tint (version_principled_bsdf_sheen).
# - `ggx`: v1's default distribution is single-scatter GGX, v2's multiscatter GGX (energy
#   compensated, brighter rough metals); 3.4's is kept.
# - `ior`: v1's specular reflectance comes from `Specular` alone (F0 = 0.08 x Specular);
#   v2's from IOR x `Specular IOR Level`, which equals v1's at IOR 1.5 (4.0-4.1 default
#   1.45): set to 1.5.
# - `layers`: v1 ADDS its specular and clearcoat lobes to the diffuse; v2 layers them, so the
#   diffuse under them loses what they reflect (DiffCol 12% under 3.4's on the bench scenes,
#   the darker 4.x image; Blender has no switch for it). [`principled_output`] builds v1's sum
#   from v2 nodes: the principled node without its specular and coat (diffuse, metal, sheen),
#   plus (1 - metallic) x a GGX lobe of F0 0.08 x Specular, plus the coat weight x a GGX lobe
#   of F0 0.04 (IOR 1.5) on the unbumped normal, as v1's clearcoat.
# - `fresnel`: those added lobes reflect by the Fresnel equations of the IOR of their F0, as
#   v1's do, not by Schlick's approximation (a metal lobe's). Schlick's is 16-22% under the
#   dielectric between 45 and 60 degrees of incidence, where the camera sees the fill and back
#   lights reflected in the backdrop: with it those two lights were 8% darker than on 3.4
#   (measured with dev/area_light_probe.py and parity_measure.py --only-light; the lights'
#   power, `area_light_energy`, is exact at every angle and size).
# - `light_tree`: Cycles 4.0+ picks light samples with its light tree by default (3.4 has
#   none). On the bench scenes (three studio area lights and a sun, sharp coats) it is what is
#   left of 4.x's extra noise once the BSDF matches: relative error at 64 spp 0.451 / 0.143
#   with the tree, 0.262 / 0.093 without, 3.4 0.257 / 0.081 (full / camo). A scene file's
#   `render.light_tree` still wins.
# - `coat_gtr1`: v1's clearcoat is evaluated (and its pdf reported for MIS) with Disney's GTR1
#   distribution of alpha^2 = Clearcoat Roughness^4 (Cycles 3.x bsdf_microfacet.h,
#   `bsdf_clearcoat_D` / `D_GTR1`, masking with a fixed alpha 0.25), whose peak is
#   |ln alpha^2| times lower than GGX's and whose tails are long; 4.x has no GTR1. GTR1 is
#   exactly the mean of GGX distributions whose alpha^2 is log-uniform on [alpha^2, 1]
#   ([`coat_gtr1_lobes`]), so the coat lobe becomes a mix of three GGX lobes fitted to it,
#   weights summing to 1 (GTR1's normalisation). Needs `layers` (the coat is an added lobe).
#   One coat under one light at roughness 0.15-0.3, 4.5 over 3.4: peak 0.80-1.00, energy
#   0.95-1.01 (one GGX lobe: 3.1-6.7x, 1.19-1.44); bench squared error at 64 samples 1.21x /
#   0.98x 3.4's (one lobe: 2.31x / 1.46x), for three more lobes' shading time.
PARITY = {"coat": True, "sheen": True, "ggx": True, "ior": True, "layers": True,
          "fresnel": True, "light_tree": True, "coat_gtr1": True}

# Factor of a 3.x input's constant value for its 4.0+ input, per PARITY switch.
_PRINCIPLED_SCALE = {"Clearcoat": ("coat", 0.25), "Sheen": ("sheen", 0.2)}


def parity_settings():
    """The parity switches in effect on this version (empty before 4.0: nothing to match),
    for the run manifest and the bench."""
    if VERSION < (4, 0, 0):
        return {}
    return dict(PARITY)


def setup_principled(node):
    """Make a new Principled BSDF node render as 3.4's v1 where v2 differs by a setting
    ([`PARITY`]): distribution, IOR, sheen tint. No-op before 4.0."""
    if VERSION < (4, 0, 0):
        return
    if PARITY["ggx"]:
        node.distribution = "GGX"
    if PARITY["ior"] and "IOR" in node.inputs:
        node.inputs["IOR"].default_value = 1.5
    if PARITY["sheen"] and "Sheen Tint" in node.inputs:
        tint = node.inputs["Sheen Tint"]
        if tint.type == "RGBA":
            tint.default_value = (1.0, 1.0, 1.0, 1.0)


def _copy_input(nt, src, dst):
    """Give input socket `dst` what feeds `src`: its link, else its constant."""
    if src.is_linked:
        nt.links.new(src.links[0].from_socket, dst)
    else:
        dst.default_value = src.default_value


def _ior_from_f0(f0):
    """The IOR whose normal-incidence Fresnel reflectance is `f0` (0 <= f0 < 1)."""
    r = math.sqrt(f0)
    return (1.0 + r) / (1.0 - r)


def _solve(a, b):
    """x with a x = b (Gauss-Jordan, partial pivoting); None if singular."""
    n = len(b)
    m = [list(row) + [b[i]] for i, row in enumerate(a)]
    for c in range(n):
        p = max(range(c, n), key=lambda r: abs(m[r][c]))
        m[c], m[p] = m[p], m[c]
        if abs(m[c][c]) < 1e-300:
            return None
        for r in range(n):
            if r != c:
                f = m[r][c] / m[c][c]
                for k in range(c, n + 1):
                    m[r][k] -= f * m[c][k]
    return [m[i][n] / m[i][i] for i in range(n)]


def _mix_fit(bs, ss, target):
    """Weights (summing to 1) of GGX lobes of alpha^2 `bs` whose energy within tan^2 = s of
    the half vector best fits `target` at `ss` (least squares), and the sum of squares
    (penalised where a weight is negative)."""
    k = len(bs)
    cols = [[s / (b + s) for s in ss] for b in bs]
    a = [[sum(x * y for x, y in zip(cols[i], cols[j])) for j in range(k)] + [1.0]
         for i in range(k)]
    a.append([1.0] * k + [0.0])
    sol = _solve(a, [sum(x * t for x, t in zip(cols[i], target)) for i in range(k)] + [1.0])
    if sol is None:
        return None, float("inf")
    w = sol[:k]
    err = sum((sum(w[i] * cols[i][j] for i in range(k)) - t) ** 2
              for j, t in enumerate(target))
    return w, err + 1e3 * sum(-x for x in w if x < 0)


_GTR1_LOBES = {}


def coat_gtr1_lobes(roughness, k=3):
    """[(roughness, weight)] of `k` GGX lobes (4.x roughness: alpha = roughness^2) whose mix
    approximates v1's clearcoat distribution, GTR1 with alpha^2 = a2 = `roughness`^4.

    With s = tan^2 of the half vector's angle, GGX's energy within s (the integral of
    D cos over that cone) is s / (b + s) for its alpha^2 b, and GTR1's is
    ln((a2 + s) / (a2 (1 + s))) / ln(1 / a2): exactly the mean of GGX's over ln b uniform on
    [ln a2, 0]. The fit: least squares on that energy at 80 values of s log-spaced from
    a2 / 100 to 1000 (what a light of each angular size collects), weights summing to 1
    (solved exactly for given lobes), the lobes' ln b by Nelder-Mead from the fractions
    0.86, 0.5, 0.14 of ln a2. For roughness 0.05-0.3 the three lobes sit at fractions
    ~0.85-0.88, 0.5, 0.12-0.15 with weights ~0.3, 0.4, 0.3; RMS energy error 0.006 (0.05) to
    0.0002 (0.3), peak D 0.67-0.99x GTR1's where one GGX lobe's is 4.9-12x. Roughness 0 (a
    mirror) and 1 (GTR1 flat) keep one lobe."""
    if not 0.0 < roughness < 1.0 or k < 2:
        return [(roughness, 1.0)]
    key = (round(roughness, 6), k)
    if key in _GTR1_LOBES:
        return _GTR1_LOBES[key]
    a2 = roughness ** 4
    lo, hi = math.log(a2 * 1e-2), math.log(1e3)
    ss = [math.exp(lo + (hi - lo) * i / 79.0) for i in range(80)]
    target = [math.log((a2 + s) / (a2 * (1.0 + s))) / -math.log(a2) for s in ss]
    top = math.log(a2)
    start = [0.86, 0.5, 0.14] if k == 3 else [1.0 - (i + 0.5) / k for i in range(k)]

    def cost(x):
        if any(v < top or v > 0.0 for v in x):
            return float("inf")
        return _mix_fit([math.exp(v) for v in x], ss, target)[1]

    pts = [[top * f for f in start]]
    pts += [[v + (0.3 if j == i else 0.0) for j, v in enumerate(pts[0])] for i in range(k)]
    vals = [cost(p) for p in pts]
    for _ in range(200):  # Nelder-Mead
        order = sorted(range(k + 1), key=lambda i: vals[i])
        pts, vals = [pts[i] for i in order], [vals[i] for i in order]
        c = [sum(p[j] for p in pts[:-1]) / k for j in range(k)]
        xr = [2.0 * c[j] - pts[-1][j] for j in range(k)]
        fr = cost(xr)
        if fr < vals[0]:
            xe = [3.0 * c[j] - 2.0 * pts[-1][j] for j in range(k)]
            fe = cost(xe)
            pts[-1], vals[-1] = (xe, fe) if fe < fr else (xr, fr)
        elif fr < vals[-2]:
            pts[-1], vals[-1] = xr, fr
        else:
            xc = [0.5 * (c[j] + pts[-1][j]) for j in range(k)]
            fc = cost(xc)
            if fc < vals[-1]:
                pts[-1], vals[-1] = xc, fc
            else:
                for i in range(1, k + 1):
                    pts[i] = [0.5 * (pts[0][j] + pts[i][j]) for j in range(k)]
                    vals[i] = cost(pts[i])
    best = pts[min(range(k + 1), key=lambda i: vals[i])]
    bs = sorted(math.exp(v) for v in best)
    w, _ = _mix_fit(bs, ss, target)
    _GTR1_LOBES[key] = [(b ** 0.25, wi) for b, wi in zip(bs, w)]
    return _GTR1_LOBES[key]


def _lobe(nt, f0, roughness_from, normal_from):
    """A v2 principled node that is one GGX reflection lobe of normal-incidence reflectance
    `f0`, roughness and normal as the given input sockets (None: unbumped normal).

    With `PARITY["fresnel"]` the lobe is a dielectric's: black base (no diffuse, nothing
    transmitted), IOR from `f0`, so its reflectance follows the Fresnel equations as v1's
    specular and clearcoat lobes do (v1 interpolates between F0 and 1 by the dielectric
    Fresnel of the IOR of F0, which with an untinted F0 is that Fresnel exactly). Without it,
    a metal of base colour `f0` (white F82 tint): Schlick's approximation, which is up to 22%
    under the dielectric between 45 and 70 degrees of incidence."""
    n = nt.nodes.new("ShaderNodeBsdfPrincipled")
    n.distribution = "GGX"
    if PARITY["fresnel"]:
        n.inputs["Metallic"].default_value = 0.0
        n.inputs["Base Color"].default_value = (0.0, 0.0, 0.0, 1.0)
        n.inputs["IOR"].default_value = _ior_from_f0(f0)
        n.inputs["Specular IOR Level"].default_value = 0.5
    else:
        n.inputs["Metallic"].default_value = 1.0
        n.inputs["Base Color"].default_value = (f0, f0, f0, 1.0)
    if "Specular Tint" in n.inputs and n.inputs["Specular Tint"].type == "RGBA":
        n.inputs["Specular Tint"].default_value = (1.0, 1.0, 1.0, 1.0)
    if isinstance(roughness_from, (int, float)):
        n.inputs["Roughness"].default_value = roughness_from
    else:
        _copy_input(nt, roughness_from, n.inputs["Roughness"])
    if normal_from is not None and normal_from.is_linked:
        nt.links.new(normal_from.links[0].from_socket, n.inputs["Normal"])
    return n


def _weighted(nt, shader, weight_from=None, weight=None, complement=False):
    """`shader` times a weight (a constant `weight`, or what feeds `weight_from`), or times one
    minus it (`complement`), as a Mix Shader with one input left empty (no light)."""
    mix = nt.nodes.new("ShaderNodeMixShader")
    if weight_from is not None:
        _copy_input(nt, weight_from, mix.inputs["Fac"])
    else:
        mix.inputs["Fac"].default_value = weight
    nt.links.new(shader, mix.inputs[1 if complement else 2])
    return mix.outputs["Shader"]


def principled_output(nt, bsdf):
    """The shader output of principled node `bsdf` (inputs already set in 3.x terms) to link
    to the material output: the node's own output, or on 4.0+ with `PARITY["layers"]` v1's
    sum of lobes built around it (see `PARITY`). Constants and links of the node's Specular,
    Metallic, Roughness, Normal and Coat inputs are carried over to the extra nodes."""
    if VERSION < (4, 0, 0) or not PARITY["layers"]:
        return bsdf.outputs["BSDF"]
    level = bsdf.inputs["Specular IOR Level"]
    out = bsdf.outputs["BSDF"]
    if level.is_linked:
        return out  # not in the recipes: keep v2's layering
    f0 = 0.08 * level.default_value
    level.default_value = 0.0
    if f0 > 0.0:
        spec = _lobe(nt, f0, bsdf.inputs["Roughness"], bsdf.inputs["Normal"])
        add = nt.nodes.new("ShaderNodeAddShader")
        nt.links.new(out, add.inputs[0])
        nt.links.new(_weighted(nt, spec.outputs["BSDF"], weight_from=bsdf.inputs["Metallic"],
                               complement=True), add.inputs[1])
        out = add.outputs["Shader"]
    coat = bsdf.inputs["Coat Weight"]
    if not coat.is_linked and coat.default_value > 0.0:
        weight = coat.default_value
        coat.default_value = 0.0
        rough = bsdf.inputs["Coat Roughness"]
        if PARITY["coat_gtr1"] and not rough.is_linked:
            lobes = coat_gtr1_lobes(rough.default_value)
        else:
            lobes = [(rough, 1.0)]
        for r, w in lobes:
            lobe = _lobe(nt, 0.04, r, None)
            add = nt.nodes.new("ShaderNodeAddShader")
            nt.links.new(out, add.inputs[0])
            nt.links.new(_weighted(nt, lobe.outputs["BSDF"], weight=weight * w), add.inputs[1])
            out = add.outputs["Shader"]
    return out


def principled_value(name, value):
    """The value to give the input named `name` (3.x name) for a 3.x constant `value`: scaled
    where v2's input is stronger ([`PARITY`]); anything but a number is returned as is (the
    recipes give coat and sheen as numbers)."""
    if VERSION < (4, 0, 0) or not isinstance(value, (int, float)):
        return value
    switch, factor = _PRINCIPLED_SCALE.get(name, (None, 1.0))
    if switch is not None and PARITY[switch]:
        return value * factor
    return value


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
            cycles.denoising_use_gpu = False


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
