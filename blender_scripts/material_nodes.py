"""A tiny expression layer over Cycles node trees.

Blocks are written as arithmetic on sockets (`g.add(a, b)`, `g.floor(x)`); numbers are
accepted anywhere a socket is, and become node defaults rather than extra nodes, so the
trees stay as small as the arithmetic. Nothing here knows about materials.
"""

import math

import bpy


def _is_socket(v):
    return isinstance(v, bpy.types.NodeSocket)


class Graph:
    """Builds nodes into `node_tree`; every method returns an output socket (or a tuple)."""

    def __init__(self, node_tree):
        self.nt = node_tree
        self.count = 0

    # --- plumbing ------------------------------------------------------------------------

    def node(self, idname, **props):
        n = self.nt.nodes.new(idname)
        self.count += 1
        n.location = ((self.count // 20) * 220.0, -(self.count % 20) * 160.0)
        for k, v in props.items():
            setattr(n, k, v)
        return n

    def set(self, socket_in, value):
        """Link a socket or set a constant on an input socket."""
        if value is None:
            return
        if _is_socket(value):
            self.nt.links.new(value, socket_in)
        elif isinstance(value, (int, float)):
            if socket_in.type in ("VECTOR",):
                socket_in.default_value = (value, value, value)
            elif socket_in.type == "RGBA":
                socket_in.default_value = (value, value, value, 1.0)
            else:
                socket_in.default_value = value
        else:
            v = tuple(value)
            if socket_in.type == "RGBA" and len(v) == 3:
                v = v + (1.0,)
            socket_in.default_value = v

    # --- scalar math ---------------------------------------------------------------------

    def math(self, op, a, b=None, c=None, clamp=False):
        if not any(_is_socket(x) for x in (a, b, c)):
            return _fold(op, a, b, c, clamp)
        n = self.node("ShaderNodeMath", operation=op, use_clamp=clamp)
        for i, v in enumerate((a, b, c)):
            if v is not None:
                self.set(n.inputs[i], v)
        return n.outputs[0]

    def add(self, a, b):
        return self.math("ADD", a, b)

    def sub(self, a, b):
        return self.math("SUBTRACT", a, b)

    def mul(self, a, b):
        return self.math("MULTIPLY", a, b)

    def div(self, a, b):
        return self.math("DIVIDE", a, b)

    def madd(self, a, b, c):
        return self.math("MULTIPLY_ADD", a, b, c)

    def floor(self, a):
        return self.math("FLOOR", a)

    def frac(self, a):
        return self.math("FRACT", a)

    def abs(self, a):
        return self.math("ABSOLUTE", a)

    def mn(self, a, b):
        return self.math("MINIMUM", a, b)

    def mx(self, a, b):
        return self.math("MAXIMUM", a, b)

    def pow(self, a, b):
        return self.math("POWER", a, b)

    def sin(self, a):
        return self.math("SINE", a)

    def sqrt(self, a):
        return self.math("SQRT", a)

    def clamp01(self, a):
        return self.math("ADD", a, 0.0, clamp=True)

    def lerp(self, a, b, t):
        """a + (b - a) t."""
        if not _is_socket(a) and not _is_socket(b):
            return self.madd(t, b - a, a)
        return self.add(a, self.mul(self.sub(b, a), t))

    def smooth(self, lo, hi, x, clamp=True):
        """Smoothstep of x from lo to hi (reversed if lo > hi)."""
        n = self.node("ShaderNodeMapRange", interpolation_type="SMOOTHSTEP", clamp=clamp)
        self.set(n.inputs["Value"], x)
        self.set(n.inputs["From Min"], lo)
        self.set(n.inputs["From Max"], hi)
        return n.outputs["Result"]

    def remap(self, x, a, b, c, d, clamp=True):
        n = self.node("ShaderNodeMapRange", interpolation_type="LINEAR", clamp=clamp)
        self.set(n.inputs["Value"], x)
        for name, v in (("From Min", a), ("From Max", b), ("To Min", c), ("To Max", d)):
            self.set(n.inputs[name], v)
        return n.outputs["Result"]

    # --- vectors -------------------------------------------------------------------------

    def vmath(self, op, a, b=None, scale=None):
        n = self.node("ShaderNodeVectorMath", operation=op)
        self.set(n.inputs[0], a)
        if b is not None:
            self.set(n.inputs[1], b)
        if scale is not None:
            self.set(n.inputs["Scale"], scale)
        if op in ("DOT_PRODUCT", "LENGTH", "DISTANCE"):
            return n.outputs["Value"]
        return n.outputs["Vector"]

    def vscale(self, v, s):
        if not _is_socket(v) and not _is_socket(s):
            return tuple(x * s for x in v)
        return self.vmath("SCALE", v, scale=s)

    def sep(self, v):
        n = self.node("ShaderNodeSeparateXYZ")
        self.set(n.inputs[0], v)
        return n.outputs[0], n.outputs[1], n.outputs[2]

    def comb(self, x, y, z):
        n = self.node("ShaderNodeCombineXYZ")
        for i, v in enumerate((x, y, z)):
            self.set(n.inputs[i], v)
        return n.outputs[0]

    # --- textures ------------------------------------------------------------------------

    def noise(self, p, scale, detail=2.0, roughness=0.5, distortion=0.0):
        n = self.node("ShaderNodeTexNoise", noise_dimensions="3D")
        self.set(n.inputs["Vector"], p)
        self.set(n.inputs["Scale"], scale)
        self.set(n.inputs["Detail"], detail)
        self.set(n.inputs["Roughness"], roughness)
        self.set(n.inputs["Distortion"], distortion)
        return n.outputs["Fac"], n.outputs["Color"]

    def voronoi(self, p, scale, feature="F1", randomness=1.0, metric="EUCLIDEAN"):
        n = self.node("ShaderNodeTexVoronoi", voronoi_dimensions="3D", feature=feature,
                      distance=metric)
        self.set(n.inputs["Vector"], p)
        self.set(n.inputs["Scale"], scale)
        self.set(n.inputs["Randomness"], randomness)
        return n.outputs

    def white(self, v):
        n = self.node("ShaderNodeTexWhiteNoise", noise_dimensions="3D")
        self.set(n.inputs["Vector"], v)
        return n.outputs["Value"]

    def wave(self, p, scale, distortion, detail, direction="DIAGONAL", profile="SIN"):
        n = self.node("ShaderNodeTexWave", wave_type="BANDS", bands_direction=direction,
                      wave_profile=profile)
        self.set(n.inputs["Vector"], p)
        self.set(n.inputs["Scale"], scale)
        self.set(n.inputs["Distortion"], distortion)
        self.set(n.inputs["Detail"], detail)
        self.set(n.inputs["Detail Scale"], 1.5)
        return n.outputs["Fac"]

    # --- colour --------------------------------------------------------------------------

    def ramp(self, fac, colors, interpolation="LINEAR"):
        if len(colors) == 1:
            return tuple(colors[0]) + (1.0,)
        n = self.node("ShaderNodeValToRGB")
        cr = n.color_ramp
        cr.interpolation = interpolation
        k = len(colors)
        while len(cr.elements) < k:
            cr.elements.new(0.5)
        for i, c in enumerate(colors):
            cr.elements[i].position = i / (k - 1)
            cr.elements[i].color = tuple(c) + (1.0,)
        self.set(n.inputs["Fac"], fac)
        return n.outputs["Color"]

    def mix(self, fac, a, b, blend="MIX"):
        """Mix two colours (MixRGB semantics)."""
        n = self.node("ShaderNodeMixRGB", blend_type=blend)
        self.set(n.inputs["Fac"], fac)
        self.set(n.inputs["Color1"], a)
        self.set(n.inputs["Color2"], b)
        return n.outputs["Color"]

    def hsv(self, color, hue=0.5, sat=1.0, val=1.0):
        n = self.node("ShaderNodeHueSaturation")
        self.set(n.inputs["Color"], color)
        self.set(n.inputs["Hue"], hue)
        self.set(n.inputs["Saturation"], sat)
        self.set(n.inputs["Value"], val)
        return n.outputs["Color"]

    def luminance(self, color):
        n = self.node("ShaderNodeRGBToBW")
        self.set(n.inputs["Color"], color)
        return n.outputs["Val"]


def _fold(op, a, b, c, clamp):
    """Constant folding so that numeric-only expressions create no nodes."""
    f = {
        "ADD": lambda: a + b,
        "SUBTRACT": lambda: a - b,
        "MULTIPLY": lambda: a * b,
        "DIVIDE": lambda: a / b if b else 0.0,
        "MULTIPLY_ADD": lambda: a * b + c,
        "FLOOR": lambda: math.floor(a),
        "FRACT": lambda: a - math.floor(a),
        "ABSOLUTE": lambda: abs(a),
        "MINIMUM": lambda: min(a, b),
        "MAXIMUM": lambda: max(a, b),
        "POWER": lambda: a ** b if a > 0 else 0.0,
        "SINE": lambda: math.sin(a),
        "SQRT": lambda: math.sqrt(a) if a > 0 else 0.0,
    }[op]()
    return min(max(f, 0.0), 1.0) if clamp else f
