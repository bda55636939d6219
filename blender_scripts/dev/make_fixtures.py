"""Writes the hand-made scene-file fixtures of tests/data/scenes/ (plain python3, no Blender).

Poses follow the reference base scene (no jitter), objects are hand-placed, so the files are
stable and readable. Regenerate with: python3 blender_scripts/dev/make_fixtures.py
Once `clevrtex sample` writes scene files, fixtures may come from it instead.
"""

import json
import math
import os

OUT = os.path.join(os.path.dirname(__file__), "..", "..", "tests", "data", "scenes")

RENDER = {
    "width": 320, "height": 240, "samples": 64,
    "max_bounces": 12, "diffuse_bounces": 4, "glossy_bounces": 4,
    "transmission_bounces": 12, "transparent_max_bounces": 8, "clamp_indirect": 0.0,
    "filter_width": 1.5, "blur_glossy": 2.0,
    "view_transform": "Filmic", "look": "Very High Contrast", "exposure": 0.0, "gamma": 1.0,
}
ALL_PASSES = ["rgb", "mask", "depth", "normal", "albedo", "shadow"]
PROFILE = [[-7.1, 0.0], [2.0, 0.0], [7.6, 0.05], [11.9, 0.24], [14.4, 0.62],
           [16.1, 1.33], [17.7, 3.1], [18.5, 5.5], [19.3, 9.9]]


def norm(v):
    n = math.sqrt(sum(c * c for c in v))
    return [c / n for c in v]


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def look_matrix(loc, forward):
    """Row-major 4x4: -Z along `forward`, +Y up as Blender's track-to."""
    z = [-c for c in norm(forward)]
    x = norm(cross([0.0, 0.0, 1.0], z))
    y = cross(z, x)
    return [[x[0], y[0], z[0], loc[0]], [x[1], y[1], z[1], loc[1]],
            [x[2], y[2], z[2], loc[2]], [0.0, 0.0, 0.0, 1.0]]


def look_at(loc, target=(0.0, 0.0, 0.0)):
    return look_matrix(loc, [t - l for t, l in zip(target, loc)])


def light(name, loc, size, energy, color):
    return {"name": name, "location": loc, "matrix_world": look_at(loc), "size": size,
            "energy": energy, "color": color}


def srgb_to_linear(c):
    c = c / 255.0
    return round(c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4, 6)


COLORS = {"gray": (87, 87, 87), "red": (173, 35, 35), "blue": (42, 75, 215),
          "green": (29, 105, 20), "brown": (129, 74, 25), "purple": (129, 38, 192),
          "cyan": (41, 208, 208), "yellow": (255, 238, 51)}


def mat(name, random=0.5, color=None, displacement=None, scale=None):
    m = {"name": name, "random": random}
    if color is not None:
        m["color_name"] = color
        m["color"] = [srgb_to_linear(c) for c in COLORS[color]]
    if displacement is not None:
        m["displacement"] = displacement
    if scale is not None:
        m["scale"] = scale
    return m


SIZES = {"large": 0.9, "medium": 0.6, "small": 0.4}
OOD_SIZES = {"large": 1.0, "medium": 0.8, "small": 0.6}


def obj(shape, size, x, y, rot, material, sizes=SIZES):
    s = sizes[size]
    return {"shape": shape, "size": size, "scale": s, "location": [x, y, s],
            "rotation_deg": rot, "material": material}


def scene(variant, index, objects, backdrop_mat, passes=ALL_PASSES, **render):
    cam = [7.481, -6.508, 5.344]
    sun_dir = norm([-0.414, 0.195, -0.889])
    r = dict(RENDER)
    r.update(render)
    return {
        "format": "clevrtex-scene", "version": 1, "variant": variant, "index": index,
        "split": "test", "seed": 0, "attempt": 0,
        "stem": "CLEVRTEX_%s_%06d" % (variant, index),
        "render": r, "passes": passes,
        "camera": {"location": cam, "look_at": [0.0, 0.0, 0.0], "matrix_world": look_at(cam),
                   "focal_length_mm": 35.0, "sensor_width_mm": 32.0,
                   "clip_start": 0.1, "clip_end": 100.0},
        "lights": [light("key", [6.447, -2.905, 4.258], 0.5, 500.0, [1.0, 0.932, 0.867]),
                   light("fill", [-4.671, -4.014, 3.011], 0.2, 200.0, [0.762, 0.818, 1.0]),
                   light("back", [-1.169, 2.646, 5.816], 1.0, 350.0, [1.0, 1.0, 1.0])],
        "sun": {"direction": sun_dir, "matrix_world": look_matrix([0.0, 0.0, 0.0], sun_dir),
                "strength": 0.85, "angle": 0.199},
        "backdrop": {"profile": PROFILE, "y_range": [-19.2, 18.5], "rotation_z": 2.698,
                     "material": backdrop_mat},
        "objects": objects,
    }


def main():
    scenes = {
        # The typical scene of the measurements: 8 objects, every main shape, CLEVR materials.
        "typical8": scene("clevr", 0, [
            obj("cube", "large", -2.2, -1.4, 30.0, mat("rubber", 0.1, "red")),
            obj("sphere", "medium", 0.3, -2.3, 0.0, mat("metal", 0.2, "blue")),
            obj("cylinder", "small", 2.4, -0.6, 10.0, mat("rubber", 0.3, "green")),
            obj("monkey", "large", 0.2, 0.6, 200.0, mat("metal", 0.4, "yellow")),
            obj("cube", "small", 2.0, 1.9, 75.0, mat("metal", 0.5, "purple")),
            obj("sphere", "large", -2.0, 2.4, 0.0, mat("rubber", 0.6, "cyan")),
            obj("cylinder", "medium", -0.6, -0.6, 0.0, mat("metal", 0.7, "brown")),
            obj("monkey", "small", 2.6, -2.6, 300.0, mat("rubber", 0.8, "gray")),
        ], mat("plain", 0.0)),
        # The same layout as a `full` (ClevrTex) scene: textured materials, a displaced
        # textured backdrop. Material names are the built-in catalogue's.
        "full8": scene("full", 5, [
            obj("cube", "large", -2.2, -1.4, 30.0, mat("bricks", 0.1)),
            obj("sphere", "medium", 0.3, -2.3, 0.0, mat("copper_chainmail", 0.2)),
            obj("cylinder", "small", 2.4, -0.6, 10.0, mat("denim", 0.3)),
            obj("monkey", "large", 0.2, 0.6, 200.0, mat("flemish_red_bricks", 0.4)),
            obj("cube", "small", 2.0, 1.9, 75.0, mat("white_painted_bricks", 0.5)),
            obj("sphere", "large", -2.0, 2.4, 0.0, mat("cobblestone_arches", 0.6)),
            obj("cylinder", "medium", -0.6, -0.6, 0.0, mat("denim", 0.7)),
            obj("monkey", "small", 2.6, -2.6, 300.0, mat("bricks", 0.8)),
        ], mat("cobblestone_arches", 0.9, displacement=0.35, scale=2.0)),
        # Every shape once (OOD sizes), for a look at the meshes.
        "all_shapes": scene("outd", 1, [
            obj("cube", "small", -2.4, -2.0, 20.0, mat("rubber", 0.1, "red"), OOD_SIZES),
            obj("sphere", "small", -0.5, -2.5, 0.0, mat("rubber", 0.2, "blue"), OOD_SIZES),
            obj("cylinder", "small", 1.5, -2.0, 0.0, mat("rubber", 0.3, "green"), OOD_SIZES),
            obj("monkey", "small", 2.7, 0.0, 225.0, mat("rubber", 0.4, "yellow"), OOD_SIZES),
            obj("cone", "small", -2.6, 0.4, 0.0, mat("rubber", 0.5, "purple"), OOD_SIZES),
            obj("torus", "small", -0.5, 0.0, 0.0, mat("rubber", 0.6, "cyan"), OOD_SIZES),
            obj("icosahedron", "small", 1.2, 1.2, 15.0, mat("rubber", 0.7, "brown"), OOD_SIZES),
            obj("teapot", "small", -1.2, 2.6, 250.0, mat("rubber", 0.8, "gray"), OOD_SIZES),
        ], mat("plain", 0.0)),
        # A tiny, fast scene for protocol tests: 3 objects at 64x48, 4 samples.
        "tiny3": scene("clevr", 2, [
            obj("cube", "large", -1.5, -1.0, 45.0, mat("rubber", 0.1, "red")),
            obj("sphere", "large", 1.2, -0.8, 0.0, mat("metal", 0.2, "blue")),
            obj("cylinder", "large", 0.0, 1.8, 0.0, mat("rubber", 0.3, "green")),
        ], mat("plain", 0.0), width=64, height=48, samples=4),
        # A lit empty floor: the shadow pass must be 0 everywhere on it.
        "empty_floor": scene("clevr", 3, [], mat("plain", 0.0),
                             width=64, height=48, samples=16),
        # Only two passes requested: nothing else may be produced.
        "rgb_mask_only": scene("clevr", 4, [
            obj("cube", "medium", 0.0, 0.0, 0.0, mat("rubber", 0.1, "red")),
        ], mat("plain", 0.0), passes=["rgb", "mask"], width=64, height=48, samples=4),
    }
    os.makedirs(OUT, exist_ok=True)
    for name, s in scenes.items():
        with open(os.path.join(OUT, name + ".json"), "w") as f:
            json.dump(s, f, indent=1)
            f.write("\n")


if __name__ == "__main__":
    main()
