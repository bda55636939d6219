"""The Principled BSDF across versions, part of `compat` (import it through `compat`, the
one home of Blender-version differences): its inputs by their 3.x names, and the v2 node of
4.0+ made to render as 3.4's v1 (the `PARITY` switches, `principled_output`).
"""

import math

import bpy

VERSION = bpy.app.version

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
# - `sheen`: v2's sheen is a microfiber layer, v1's a Schlick-Fresnel lobe added to the
#   diffuse; v2 is set a constant Sheen x 0.04 with a white tint. Blender's versioning of 3.x
#   files uses 0.2 (version_principled_bsdf_sheen), which on the studio lights adds ~4x what
#   v1's sheen adds: the dark fabrics `rhombus_carpet` and `pyramid_upholstery` (Sheen 0.7-0.8)
#   rendered 12-14% brighter than on 3.4. 0.04 puts every material with sheen within 2% in
#   both roles (`clevrtex materials parity`, docs/notes/materials.md).
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
# - `coat_mis`: what 3.4 renders of its clearcoat is not GTR1 alone. It samples the coat with
#   GGX (alpha^2 = Roughness^4) but evaluates it, and reports its pdf to multiple importance
#   sampling, with GTR1 (Cycles 3.x bsdf_microfacet.h: D cancels in a BSDF sample's weight).
#   So a BSDF-sampled light counts GGX's reflection, weighted by the power heuristic of
#   GTR1's pdf against the light's, and a light-sampled one GTR1's, weighted by the light's
#   pdf: where GTR1's pdf beats the light's (a sharp coat's peak) 3.4 shows GGX, elsewhere
#   GTR1's long tails, and the two add up to more than the coat's energy (~1.6x at Roughness
#   0.05; 3.4's sharp coats reflect the studio lights "about twice as brightly").
#   [`coat_v1_lobes`] gives the coat that sum for a light pdf [`COAT_LIGHT_PDF`] (D units,
#   fitted to `onyx_tiles`): a GGX lobe of the coat's roughness weighted by its share, plus
#   [`coat_gtr1_lobes`] weighted by GTR1's. Needs `coat_gtr1`.
# - `disney_diffuse`: v1's diffuse is Disney's, Lambert's times
#   g(F_L) g(F_V), g(F) = 1 + (F_D90 - 1) F, F = (1 - cos)^5 of the light (L) and view (V)
#   angles, F_D90 = 0.5 + 2 Roughness cos^2 theta_d (theta_d: between light and half
#   vector; Cycles 3.x bsdf_principled_diffuse.h): darker than Lambert at grazing angles when
#   smooth, brighter when rough. v2's diffuse is Lambert's (4.3+'s Diffuse Roughness is
#   another model, Oren-Nayar; it was measured and does not match, docs/notes/materials.md).
#   Measured on a flat backdrop, diffuse only, 3.4 over 4.5: 0.972 at Roughness 0, 1.015 at
#   0.5, 1.060 at 1; on curved objects 0.947, 1.009, 1.074: the rough dielectrics (bricks,
#   clay, rubber, drywall) rendered 3-6% darker on 4.5. [`disney_diffuse`] multiplies
#   the base colour of the diffuse by v1's factor with the view term exact per shading point
#   (Layer Weight's Facing is 1 - cos theta_V) and the light term and cos^2 theta_d at the
#   studio lights' typical values ([`DISNEY_LIGHT_F`], [`DISNEY_COS2_D`], fitted to those
#   measurements); metals keep their colour.
# - `metal_fresnel`: v1's metal is its specular lobe with F0 = the base colour, reflecting by
#   `interpolate_fresnel_color`: F = c + (1 - c) FH, FH the dielectric Fresnel of the IOR of
#   0.08 x Specular (1.5 at 0.5) at the microfacet's angle, normalised to 0 at normal
#   incidence (Cycles 3.x bsdf_util.h). v2's metal is Schlick's F82-tint model, whose
#   (1 - cos)^5 is up to 22% under FH between 45 and 70 degrees: metal objects rendered
#   3.1-4.6% darker on 4.5 at 1024 samples. v2's dielectric specular layer reflects
#   F = f0 + (1 - f0) FH with the same FH (its generalised Schlick of exponent -IOR,
#   svm/closure.h) and f0 = F0(IOR) x Specular Tint, the tint not clamped above 1, so
#   [`principled_output`] makes the metal a dielectric lobe of black base, that IOR and
#   Specular Tint = colour / F0(IOR): exactly v1's metal Fresnel, at every angle. Weighted by
#   Metallic, the principled node (diffuse, sheen) by 1 - Metallic, as v1's sum. (A correction
#   of the metal colour by the view angle, tried first, fixed objects but overdid backdrops,
#   where the half vector is far nearer the normal than the view: docs/notes/materials.md.)
#   Needs `layers` and `fresnel`.
PARITY = {"coat": True, "sheen": True, "ggx": True, "ior": True, "layers": True,
          "fresnel": True, "light_tree": True, "coat_gtr1": True, "disney_diffuse": True,
          "metal_fresnel": True, "coat_mis": True}

# v1's Disney diffuse on 4.x ([`disney_diffuse`]): the light term's F_L = (1 - cos theta_L)^5
# and cos^2 theta_d taken at these values, fitted to 3.4's diffuse-only renders of `rubber`
# (Roughness 0.9) and `plain` (0.5) as backdrop and on the objects under the studio lights
# (dev/displace_parity_probe.py `--set glossy=0 --set disney=D,X`; all four within 0.6%;
# docs/notes/materials.md, "Disney diffuse and the sheen factor on 4.x").
DISNEY_LIGHT_F = 0.02
DISNEY_COS2_D = 0.7

# Factor of a 3.x input's constant value for its 4.0+ input, per PARITY switch.
_PRINCIPLED_SCALE = {"Clearcoat": ("coat", 0.25), "Sheen": ("sheen", 0.04)}


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


def disney_diffuse(g, color, rough, metal):
    """The base colour to give a Principled BSDF (material_nodes.Graph `g`; `color`,
    `rough`, `metal` sockets or constants) so that 4.0+'s Lambert diffuse renders as v1's
    Disney diffuse ([`PARITY`] `disney_diffuse`): `color` times
    k = (1 + s F_V)(1 + s F_L), s = 2 cos^2 theta_d Roughness - 0.5, F_V = Facing^5 per
    shading point. Where the metal is the principled node's own (the `metal_fresnel` or
    `layers` switch off) k's excess is faded out by Metallic (a metal's colour is its
    reflectance, not a diffuse albedo); with them the node's colour is the diffuse's alone.
    `color` itself before 4.0 or with the switch off."""
    if VERSION < (4, 0, 0) or not PARITY["disney_diffuse"]:
        return color
    lw = g.node("ShaderNodeLayerWeight")
    lw.inputs["Blend"].default_value = 0.5
    fv = g.pow(lw.outputs["Facing"], 5.0)
    s = g.madd(rough, 2.0 * DISNEY_COS2_D, -0.5)
    k = g.mul(g.madd(s, fv, 1.0), g.madd(s, DISNEY_LIGHT_F, 1.0))
    if _is_nonzero(metal) and not _metal_lobe_on():
        k = g.madd(g.sub(1.0, k), metal, k)
    if isinstance(color, (int, float)):
        color = (color, color, color)
    elif isinstance(color, (tuple, list)):
        color = tuple(color)[:3]  # RGBA constants: the vector math takes RGB
    return g.vscale(color, k)


def _metal_lobe_on():
    """Whether [`principled_output`] takes the metal out of the principled node (4.0+)."""
    return (VERSION >= (4, 0, 0) and PARITY["layers"] and PARITY["fresnel"]
            and PARITY["metal_fresnel"])


def _is_nonzero(x):
    """Whether `x` (a socket or a constant) may be other than 0."""
    return not isinstance(x, (int, float)) or x != 0.0


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

# The light's pdf against which 3.4's clearcoat weighs GTR1's (`coat_mis`), in units of the
# microfacet distribution D (the BSDF's pdf of a reflection is about D / (4 cos theta_o)):
# fitted to 3.4's `onyx_tiles` backdrop (docs/notes/materials.md, "The clearcoat's multiple
# importance sampling"); the studio lights span ~30 (the back light and the sun) to ~800
# (the small fill light).
COAT_LIGHT_PDF = 100.0

_COAT_SHARES = {}


def coat_mis_shares(roughness, light_pdf=None):
    """(GGX's share, GTR1's share) of what 3.4 renders of a clearcoat of `roughness`
    ([`PARITY`] `coat_mis`): the energy of GGX (alpha^2 = a2 = `roughness`^4) weighted by the
    power heuristic w_B = D^2 / (D^2 + T^2), and of GTR1 (of a2) by 1 - w_B, D = GTR1's
    distribution at each half-vector angle and T = `light_pdf` ([`COAT_LIGHT_PDF`]).
    Integrated over s = tan^2 of the half vector's angle (log-spaced, a2 / 1e4 to 1e4):
    GGX's energy density in s is a2 / (a2 + s)^2, GTR1's (1 / (a2 + s) - 1 / (1 + s)) /
    ln(1 / a2), and D = (1 - a2)(1 + s) / (pi ln(1 / a2)(s + a2)). At Roughness 0.05 the sum
    is 1.56-1.67 for T from 30 to 1000; at 0.2 and T >= 100 GTR1's alone (1.00)."""
    t = COAT_LIGHT_PDF if light_pdf is None else light_pdf
    if not 0.0 < roughness < 1.0:
        return (0.0, 1.0)
    key = (round(roughness, 6), round(t, 6))
    if key in _COAT_SHARES:
        return _COAT_SHARES[key]
    a2 = roughness ** 4
    ln = math.log(1.0 / a2)
    n = 2000
    lo, hi = math.log(a2 * 1e-4), math.log(1e4)
    step = (hi - lo) / n
    eg = et = 0.0
    for i in range(n):
        s = math.exp(lo + (i + 0.5) * step)
        d = (1.0 - a2) * (1.0 + s) / (math.pi * ln * (s + a2))
        wb = d * d / (d * d + t * t)
        eg += a2 / (a2 + s) ** 2 * wb * s * step
        et += (1.0 / (a2 + s) - 1.0 / (1.0 + s)) / ln * (1.0 - wb) * s * step
    _COAT_SHARES[key] = (eg, et)
    return eg, et


def coat_v1_lobes(roughness):
    """[(roughness, weight)] of the GGX lobes that render a clearcoat of `roughness` (weight 1)
    as 3.4 does: with `coat_mis`, a GGX lobe of that roughness weighted by GGX's share (left
    out under 1%) plus [`coat_gtr1_lobes`] times GTR1's ([`coat_mis_shares`]); else GTR1's
    lobes alone."""
    lobes = coat_gtr1_lobes(roughness)
    if not PARITY["coat_mis"]:
        return lobes
    eg, et = coat_mis_shares(roughness)
    out = [(r, w * et) for r, w in lobes]
    if eg >= 0.01:
        out.insert(0, (roughness, eg))
    return out


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


def _scaled_color(nt, color, k):
    """`color` (a socket, an RGB(A) tuple or a number) times `k`, as a constant or a socket."""
    if isinstance(color, (int, float)):
        return (color * k, color * k, color * k, 1.0)
    if isinstance(color, (tuple, list)):
        r, gr, b = tuple(color)[:3]
        return (r * k, gr * k, b * k, 1.0)
    vm = nt.nodes.new("ShaderNodeVectorMath")
    vm.operation = "SCALE"
    nt.links.new(color, vm.inputs[0])
    vm.inputs["Scale"].default_value = k
    return vm.outputs["Vector"]


def _lobe(nt, f0, roughness_from, normal_from, tint=None):
    """A v2 principled node that is one GGX reflection lobe of normal-incidence reflectance
    `f0`, roughness and normal as the given input sockets (None: unbumped normal).

    With `PARITY["fresnel"]` the lobe is a dielectric's: black base (no diffuse, nothing
    transmitted), IOR from `f0`, so its reflectance follows the Fresnel equations as v1's
    specular and clearcoat lobes do (v1 interpolates between F0 and 1 by the dielectric
    Fresnel of the IOR of F0, which with an untinted F0 is that Fresnel exactly). Without it,
    a metal of base colour `f0` (white F82 tint): Schlick's approximation, which is up to 22%
    under the dielectric between 45 and 70 degrees of incidence. `tint` (a colour constant or
    socket) multiplies the dielectric's F0: v1's metal ([`PARITY`] `metal_fresnel`)."""
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
    if tint is not None:
        if isinstance(tint, tuple):
            n.inputs["Specular Tint"].default_value = tint
        else:
            nt.links.new(tint, n.inputs["Specular Tint"])
    elif "Specular Tint" in n.inputs and n.inputs["Specular Tint"].type == "RGBA":
        n.inputs["Specular Tint"].default_value = (1.0, 1.0, 1.0, 1.0)
    if isinstance(roughness_from, (int, float)):
        n.inputs["Roughness"].default_value = roughness_from
    else:
        _copy_input(nt, roughness_from, n.inputs["Roughness"])
    if normal_from is not None and normal_from.is_linked:
        nt.links.new(normal_from.links[0].from_socket, n.inputs["Normal"])
    return n


def _weighted(nt, shader, label, weight_from=None, weight=None, complement=False):
    """`shader` times a weight (a constant `weight`, or what feeds `weight_from`), or times one
    minus it (`complement`), as a Mix Shader with one input left empty (no light), labelled
    `label` (which lobe it weighs: "metal", "specular", "coat"; the dev probes find them so)."""
    mix = nt.nodes.new("ShaderNodeMixShader")
    mix.label = label
    if weight_from is not None:
        _copy_input(nt, weight_from, mix.inputs["Fac"])
    else:
        mix.inputs["Fac"].default_value = weight
    nt.links.new(shader, mix.inputs[1 if complement else 2])
    return mix.outputs["Shader"]


def principled_output(nt, bsdf, color=None):
    """The shader output of principled node `bsdf` (inputs already set in 3.x terms) to link
    to the material output: the node's own output, or on 4.0+ with `PARITY["layers"]` v1's
    sum of lobes built around it (see `PARITY`). Constants and links of the node's Specular,
    Metallic, Roughness, Normal and Coat inputs are carried over to the extra nodes. `color`
    is the material's base colour (a socket or a constant) before `disney_diffuse`: the
    metal lobe's ([`PARITY`] `metal_fresnel`); None keeps the metal in the node."""
    if VERSION < (4, 0, 0) or not PARITY["layers"]:
        return bsdf.outputs["BSDF"]
    level = bsdf.inputs["Specular IOR Level"]
    out = bsdf.outputs["BSDF"]
    if level.is_linked:
        return out  # not in the recipes: keep v2's layering
    f0 = 0.08 * level.default_value
    level.default_value = 0.0
    metal = bsdf.inputs["Metallic"]
    if (_metal_lobe_on() and color is not None and f0 > 0.0
            and (metal.is_linked or metal.default_value > 0.0)):
        lobe = _lobe(nt, f0, bsdf.inputs["Roughness"], bsdf.inputs["Normal"],
                     tint=_scaled_color(nt, color, 1.0 / f0))
        lobe_out = lobe.outputs["BSDF"]
        if metal.is_linked or metal.default_value < 1.0:
            add = nt.nodes.new("ShaderNodeAddShader")
            nt.links.new(_weighted(nt, out, "metal", weight_from=metal, complement=True),
                         add.inputs[0])
            nt.links.new(_weighted(nt, lobe_out, "metal", weight_from=metal), add.inputs[1])
            out = add.outputs["Shader"]
        else:
            out = lobe_out  # a pure metal: no diffuse, sheen or dielectric specular
            f0 = 0.0  # nor (1 - Metallic) x the specular lobe below
    else:
        metal = None  # the metal stays the node's own
    if f0 > 0.0:
        spec = _lobe(nt, f0, bsdf.inputs["Roughness"], bsdf.inputs["Normal"])
        add = nt.nodes.new("ShaderNodeAddShader")
        nt.links.new(out, add.inputs[0])
        nt.links.new(_weighted(nt, spec.outputs["BSDF"], "specular",
                               weight_from=bsdf.inputs["Metallic"], complement=True),
                     add.inputs[1])
        out = add.outputs["Shader"]
    if metal is not None:  # now the lobes above have their weights from it
        if metal.is_linked:
            nt.links.remove(metal.links[0])
        metal.default_value = 0.0
    coat = bsdf.inputs["Coat Weight"]
    if not coat.is_linked and coat.default_value > 0.0:
        weight = coat.default_value
        coat.default_value = 0.0
        rough = bsdf.inputs["Coat Roughness"]
        if PARITY["coat_gtr1"] and not rough.is_linked:
            lobes = coat_v1_lobes(rough.default_value)
        else:
            lobes = [(rough, 1.0)]
        for r, w in lobes:
            lobe = _lobe(nt, 0.04, r, None)
            add = nt.nodes.new("ShaderNodeAddShader")
            nt.links.new(out, add.inputs[0])
            nt.links.new(_weighted(nt, lobe.outputs["BSDF"], "coat", weight=weight * w),
                         add.inputs[1])
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
