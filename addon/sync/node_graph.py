"""Cycles node graphs into a material's node program (parallax_core.nodes): the texture and
maths nodes that drive a shader's inputs, evaluated per hit on the device as Cycles' SVM does.

``GraphCompiler.socket(socket, kind)`` gives the value arriving at a shader input: a constant
(folded on the host) or a register of the program. Nodes it cannot compile raise
``Unsupported``; the caller then names the node in a warning and uses the socket's own value.
Supported: Value, RGB, Image Texture (Color; flat, repeating, any Vector), Noise
Texture (3D fBm, as Cycles: same hash, same noise), Checker Texture, Gradient Texture (linear,
quadratic, easing, diagonal), Voronoi Texture (3D; F1, F2, Smooth F1; every distance metric;
fractal detail; Distance, Color, Position), Wave Texture (bands and rings, every direction and
profile, distortion), Brick Texture (Color, Fac), Texture Coordinate (UV, Generated, Object,
Normal), Geometry (Position, Normal, True Normal, Incoming, Backfacing), UV Map (any map),
Attribute and Color Attribute (mesh attributes: attribute_requests), Mapping (point,
texture, vector), Math (every operation), Vector Math (every operation), Clamp, Mix and MixRGB
(the blend modes of parallax_core.nodes.BLEND_MODES), Invert, Hue/Saturation/Value,
Bright/Contrast, Gamma, Map Range (float and vector; linear, stepped, smooth step, smoother
step), ColorRamp (any interpolation, as Cycles: a 256-entry table), RGB Curves and Float Curve
(as Cycles: 256-entry tables over the curves' range, extrapolated or not), Separate/Combine
Color (RGB) and XYZ, Blackbody (a constant temperature), Fresnel, Layer Weight, Bump, Normal
Map (tangent, object and world space), Reroute and node groups (flattened). In a world
(parallax_core.node_fields evaluates the graph on the host): also Environment Texture, Sky
Texture and Blackbody of any temperature.
"""
import numpy as np


def _tree_nodes(tree, seen=None):
    """Every node of ``tree`` and of the node groups inside it (each tree once)."""
    seen = set() if seen is None else seen
    if tree is None or tree.name_full in seen:
        return
    seen.add(tree.name_full)
    for node in tree.nodes:
        yield node
        if node.type == "GROUP":
            yield from _tree_nodes(node.node_tree, seen)


def tangent_uv_maps(tree):
    """The UV maps ('' for the active one) whose tangents the tree's tangent-space Normal Map
    nodes use, node groups included: what the mesh export computes tangents for."""
    return {node.uv_map for node in _tree_nodes(tree) if node.type == "NORMAL_MAP" and node.space == "TANGENT"}


def attribute_requests(tree):
    """The mesh data the tree's nodes read beyond the active UV map: ("uv", name) for a UV Map
    node naming a map, ("attribute", name) for Attribute (geometry) and Color Attribute nodes
    ('' for the mesh's default colour attribute). The mesh export fills an attribute slot for
    each (parallax_core.scene Mesh.attributes)."""
    keys = set()
    for node in _tree_nodes(tree):
        if node.type == "UVMAP" and node.uv_map:
            keys.add(("uv", node.uv_map))
        elif node.type == "ATTRIBUTE" and node.attribute_type == "GEOMETRY" and node.attribute_name:
            keys.add(("attribute", node.attribute_name))
        elif node.type == "VERTEX_COLOR":
            keys.add(("attribute", node.layer_name))
    return keys


def vector_linked(node):
    """Whether the node's Vector input is available and linked (Blender 5's inputs["Vector"]
    skips an unavailable socket)."""
    socket = next((s for s in node.inputs if s.identifier == "Vector"), None)
    return socket is not None and getattr(socket, "enabled", True) and socket.is_linked


class Unsupported(Exception):
    """A node (or a setting of one) the compiler does not translate; its message names it."""


# Blender socket types -> value kinds.
_KINDS = {"VALUE": "float", "INT": "float", "BOOLEAN": "float", "RGBA": "color", "VECTOR": "vector"}


class GraphCompiler:
    def __init__(self, program, texture_loader, material_name, attribute_slot=lambda key: None):
        from ..core import load

        self.nodes = load().nodes
        self.program = program
        self.texture_loader = texture_loader
        self.material_name = material_name
        self.attribute_slot = attribute_slot  # attribute_requests' key -> slot (None: no mesh has it)
        self._memo = {}
        # Where coordinates are taken: the hit (0, 0.0), or one of the two points a Bump
        # evaluates its height at (offset 1 or 2, filter width); see Program._place.
        self.bump_offset = (0, 0.0)

    # -- sockets --

    def socket(self, socket, kind, groups=()):
        """The value at input ``socket`` as ``kind`` ("float", "color", "vector")."""
        link = next((l for l in socket.links if not getattr(l, "is_muted", False)), None) if socket.is_linked else None
        if link is None:
            if socket.type in ("RGBA", "VECTOR"):
                return self.convert(np.array(socket.default_value[:], np.float64), _KINDS[socket.type], kind)
            return self.convert(float(socket.default_value), "float", kind)
        node, output = link.from_node, link.from_socket
        if node.type == "REROUTE":
            return self.socket(node.inputs[0], kind, groups)
        if node.type == "GROUP_INPUT":  # the group node's own input, one level out
            if not groups:
                raise Unsupported(f"a Group Input outside a group ('{node.name}')")
            outer = groups[-1]
            return self.socket(outer.inputs[output.identifier], kind, groups[:-1])
        key = (tuple(g.name for g in groups), node.name, output.identifier, self.bump_offset)
        if key not in self._memo:
            self._memo[key] = self._output(node, output, groups)
        value, produced = self._memo[key]
        return self.convert(value, produced, kind)

    def convert(self, value, have, want):
        """As Blender converts between sockets: colour -> float is its luminance, vector ->
        float the mean of its components, float -> colour or vector grey."""
        p = self.program
        if have == want or {have, want} == {"color", "vector"}:
            return value
        if want == "float":
            return p.to_float(value, have)
        return p.to_color(value)

    def _in(self, node, index_or_name, kind, groups):
        """An input by index, identifier or name."""
        if isinstance(index_or_name, str):
            socket = next((s for s in node.inputs if s.identifier == index_or_name), None)
            if socket is not None:
                return self.socket(socket, kind, groups)
        return self.socket(node.inputs[index_or_name], kind, groups)

    # -- nodes --

    def _output(self, node, output, groups):
        """(value, kind) of ``output`` of ``node``."""
        from ..core import load

        handler = getattr(self, "_" + node.type.lower(), None)
        if handler is None:
            raise Unsupported(f"'{node.bl_label}' node '{node.name}'")
        try:
            return handler(node, output, groups)
        except load().node_fields.NotOnHost as e:  # a world's or light's graph (FieldProgram)
            raise Unsupported(f"'{node.bl_label}' node '{node.name}' ({e} here)") from None

    def _value(self, node, output, groups):
        return float(output.default_value), "float"

    def _rgb(self, node, output, groups):
        return np.array(output.default_value[:], np.float64), "color"

    def _group(self, node, output, groups):
        tree = node.node_tree
        out = next((n for n in tree.nodes if n.type == "GROUP_OUTPUT" and n.is_active_output), None) if tree else None
        if out is None:
            raise Unsupported(f"node group '{node.name}' without an output")
        inner = next(s for s in out.inputs if s.identifier == output.identifier)
        kind = _KINDS.get(output.type, "float")
        return self.socket(inner, kind, groups + (node,)), kind

    def _uv(self):
        return self.program.uv(self.bump_offset)

    def _tex_coord(self, node, output, groups):
        p = self.program
        if output.name == "Generated":
            return p.generated(self.bump_offset), "vector"
        if output.name == "UV":
            return self._uv(), "vector"
        if output.name == "Object" and node.object is None:
            return p.geometry("object", self.bump_offset), "vector"
        if output.name == "Normal":
            return p.geometry("object_normal"), "vector"
        raise Unsupported(f"Texture Coordinate '{node.name}' output {output.name}"
                          + (" from another object" if output.name == "Object" else "")
                          + " (UV, Generated, Object and Normal are supported)")

    def _new_geometry(self, node, output, groups):
        """Cycles' Geometry node: Position, Normal, True Normal, Incoming, Backfacing."""
        kinds = {"Position": "position", "Normal": "normal", "True Normal": "true_normal", "Incoming": "incoming",
                 "Backfacing": "backfacing"}
        if output.name not in kinds:
            raise Unsupported(f"Geometry '{node.name}' output {output.name}")
        value = self.program.geometry(kinds[output.name], self.bump_offset)
        return (self.program.separate(value, 0), "float") if output.name == "Backfacing" else (value, "vector")

    def _uvmap(self, node, output, groups):
        if getattr(node, "from_instancer", False):
            raise Unsupported(f"UV Map '{node.name}' from the instancer")
        if not node.uv_map:
            return self._uv(), "vector"
        return self._mesh_attribute(("uv", node.uv_map)), "vector"

    def _mesh_attribute(self, key):
        """The attribute slot's value at the hit; 0 where no mesh has it (as Cycles' Attribute
        node for a missing attribute)."""
        slot = self.attribute_slot(key)
        return np.zeros(4) if slot is None else self.program.attribute(slot, self.bump_offset)

    def _attribute(self, node, output, groups):
        """Cycles' Attribute node (svm_node_attr) for geometry attributes: Color and Vector the
        value, Fac the mean of its three components, Alpha its fourth (1 for non-colours)."""
        if node.attribute_type != "GEOMETRY":
            raise Unsupported(f"Attribute '{node.name}' of type {node.attribute_type} (geometry attributes are supported)")
        return self._attribute_output(self._mesh_attribute(("attribute", node.attribute_name)), output)

    def _vertex_color(self, node, output, groups):
        """Cycles' Color Attribute node: the named (or default) colour attribute and its alpha."""
        return self._attribute_output(self._mesh_attribute(("attribute", node.layer_name)), output)

    def _attribute_output(self, value, output):
        p = self.program
        if output.identifier == "Fac":
            return p.to_float(value, "vector"), "float"
        if output.identifier == "Alpha":
            return p.separate(value, 3), "float"
        return value, ("vector" if output.identifier == "Vector" else "color")

    def normal_input(self, node, groups, name="Normal"):
        """A Normal input: linked, else the hit's shading normal (Cycles' N)."""
        socket = node.inputs.get(name)
        if socket is not None and socket.is_linked:
            return self.socket(socket, "vector", groups)
        return self.program.geometry("normal")

    def _bump(self, node, output, groups):
        """Cycles' Bump (svm_node_set_bump): the Height graph compiled three times, at the hit
        and at the two offsets (nodes.glsl bump_step)."""
        p = self.program
        width = self._in(node, "Filter Width", "float", groups) if "Filter Width" in node.inputs else 0.1
        if not p.is_constant(width):
            raise Unsupported(f"Bump '{node.name}' with a linked Filter Width")
        saved, heights = self.bump_offset, []
        for offset in (0, 1, 2):
            self.bump_offset = (offset, float(width)) if offset else saved
            heights.append(self._in(node, "Height", "float", groups))
        self.bump_offset = saved
        strength, distance = self._in(node, "Strength", "float", groups), self._in(node, "Distance", "float", groups)
        return p.bump(strength, distance, heights, self.normal_input(node, groups), node.invert, float(width)), "vector"

    def _normal_map(self, node, output, groups):
        """Cycles' Normal Map; tangent space uses the tangents the mesh export computes for
        the materials whose trees hold one (tangent_uv_maps)."""
        color = self._in(node, "Color", "color", groups)
        strength = self._in(node, "Strength", "float", groups)
        return self.program.normal_map(color, strength, node.space), "vector"

    def _fresnel(self, node, output, groups):
        return self.program.fresnel("fresnel", self._in(node, "IOR", "float", groups), self.normal_input(node, groups)), "float"

    def _layer_weight(self, node, output, groups):
        kind = "layer_fresnel" if output.name == "Fresnel" else "layer_facing"
        return self.program.fresnel(kind, self._in(node, "Blend", "float", groups), self.normal_input(node, groups)), "float"

    def _tex_image(self, node, output, groups):
        if output.name != "Color":
            raise Unsupported(f"Image Texture '{node.name}' output {output.name}")
        if node.image is None:
            return np.zeros(4), "color"
        if node.projection != "FLAT" or node.extension != "REPEAT":
            raise Unsupported(f"Image Texture '{node.name}' with {node.projection} projection / {node.extension} extension")
        interpolation = "closest" if node.interpolation == "Closest" else "linear"
        texture = self.texture_loader(node.image, f"material '{self.material_name}'", interpolation)
        if texture is None:
            raise Unsupported(f"Image Texture '{node.name}' without pixels")
        vector = self._in(node, "Vector", "vector", groups) if vector_linked(node) else self._uv()
        return self.program.texture(vector, texture), "color"

    def _tex_environment(self, node, output, groups):
        """Cycles' Environment Texture (equirectangular or mirror ball) in a world: the image in
        the direction of its Vector (the view direction by default)."""
        if not hasattr(self.program, "environment"):
            raise Unsupported(f"'Environment Texture' node '{node.name}' outside a world")
        if output.name != "Color":
            raise Unsupported(f"Environment Texture '{node.name}' output {output.name}")
        if node.image is None:
            return np.zeros(4), "color"
        interpolation = "closest" if node.interpolation == "Closest" else "linear"
        image = self.texture_loader(node.image, self.material_name, interpolation)
        if image is None:
            raise Unsupported(f"Environment Texture '{node.name}' without pixels")
        vector = self._in(node, "Vector", "vector", groups) if vector_linked(node) else self.program.geometry("position")
        return self.program.environment(vector, image, node.projection), "color"

    def _tex_sky(self, node, output, groups):
        """Blender's Sky Texture in a world (parallax_core.sky: single and multiple scattering,
        Preetham), its sun disc left to the world export (a sun light)."""
        from ..core import load

        sky = load().sky
        if not hasattr(self.program, "sky"):
            raise Unsupported(f"'Sky Texture' node '{node.name}' outside a world")
        params = sky.SkyParams.from_node(node)  # Blender 4's Nishita is the single-scattering sky
        if params.sky_type not in sky.SKY_TYPES:
            raise Unsupported(f"Sky Texture '{node.name}' of type {node.sky_type}")
        return self.program.sky(self._texture_vector(node, groups), params, node.name), "color"

    def _offset(self, vector, seed):
        """vector + Cycles' random_float3_offset(seed): a noise's own seed."""
        offset = [self.nodes.random_offset(seed, k) for k in range(3)]
        return self.program.mix("ADD", 1.0, vector, offset)

    def _tex_noise(self, node, output, groups):
        """Cycles' Noise Texture, 3D fBm: distortion, then the noise and, for Color, two more
        at seeded offsets (kernel/svm/noisetex.h)."""
        if node.noise_dimensions != "3D" or getattr(node, "noise_type", "FBM") != "FBM":
            raise Unsupported(f"Noise Texture '{node.name}' ({node.noise_dimensions}, "
                              f"{getattr(node, 'noise_type', 'FBM')}; 3D fBm is supported)")
        p = self.program
        vector = p.mix("MULTIPLY", 1.0, self._texture_vector(node, groups),
                       p.to_color(self._in(node, "Scale", "float", groups)))
        detail, roughness, lacunarity = (self._in(node, k, "float", groups) for k in ("Detail", "Roughness", "Lacunarity"))
        normalize = getattr(node, "normalize", True)
        distortion = self._in(node, "Distortion", "float", groups)
        if not (p.is_constant(distortion) and distortion == 0.0):
            shift = p.combine(*(p.noise(self._offset(vector, float(k)), 0.0, 0.0, 2.0, False) for k in range(3)))
            vector = p.mix("ADD", 1.0, vector, p.mix("MULTIPLY", 1.0, shift, p.to_color(distortion)))
        value = p.noise(vector, detail, roughness, lacunarity, normalize)
        if output.identifier == "Fac":  # named "Factor" since Blender 5
            return value, "float"
        return p.combine(value, *(p.noise(self._offset(vector, seed), detail, roughness, lacunarity, normalize)
                                  for seed in (3.0, 4.0))), "color"

    def _texture_vector(self, node, groups):
        """A procedural texture's Vector: linked, else Generated coordinates (Blender's default;
        also where the input is unavailable, as the scattering Sky Texture's is)."""
        if vector_linked(node):
            return self._in(node, "Vector", "vector", groups)
        return self.program.generated(self.bump_offset)

    def _tex_checker(self, node, output, groups):
        """Cycles' svm_checker: cells of the scaled point (nudged off the cell edges), colour 1
        where the parities of |floor| of x and y agree exactly when z's is odd."""
        p = self.program
        point = p.mix("MULTIPLY", 1.0, self._texture_vector(node, groups), p.to_color(self._in(node, "Scale", "float", groups)))
        parity = []
        for k in range(3):
            x = p.math("MULTIPLY", p.math("ADD", p.separate(point, k), 0.000001), 0.999999)
            parity.append(p.math("MODULO", p.math("ABSOLUTE", p.math("FLOOR", x)), 2.0))
        same = lambda a, b: p.math("SUBTRACT", 1.0, p.math("ABSOLUTE", p.math("SUBTRACT", a, b)))
        fac = same(same(parity[0], parity[1]), parity[2])
        if output.identifier == "Fac":  # named "Factor" since Blender 5
            return fac, "float"
        return p.mix("MIX", fac, self._in(node, "Color2", "color", groups), self._in(node, "Color1", "color", groups)), "color"

    def _tex_gradient(self, node, output, groups):
        """Cycles' svm_gradient for the types made of x and y alone (linear, quadratic, easing,
        diagonal)."""
        p = self.program
        kind = node.gradient_type
        if kind not in ("LINEAR", "QUADRATIC", "EASING", "DIAGONAL"):
            raise Unsupported(f"Gradient Texture '{node.name}' of type {kind}")
        vector = self._texture_vector(node, groups)
        x = p.separate(vector, 0)
        if kind == "QUADRATIC":
            x = p.math("MAXIMUM", x, 0.0)
            x = p.math("MULTIPLY", x, x)
        elif kind == "EASING":  # 3 r^2 - 2 r^3 of r = x clamped to 0..1
            r = p.math("CLAMP", x, 0.0, 1.0)
            t = p.math("MULTIPLY", r, r)
            x = p.math("SUBTRACT", p.math("MULTIPLY", t, 3.0), p.math("MULTIPLY", p.math("MULTIPLY", t, r), 2.0))
        elif kind == "DIAGONAL":
            x = p.math("MULTIPLY", p.math("ADD", x, p.separate(vector, 1)), 0.5)
        fac = p.math("CLAMP", x, 0.0, 1.0)
        return (fac, "float") if output.identifier == "Fac" else (p.to_color(fac), "color")

    def _tex_voronoi(self, node, output, groups):
        """Cycles' 3D Voronoi Texture (kernel/svm/voronoi.h: F1, F2 and Smooth F1, fractal)."""
        if node.voronoi_dimensions != "3D":
            raise Unsupported(f"Voronoi Texture '{node.name}' in {node.voronoi_dimensions} (3D is supported)")
        if node.feature not in self.nodes.VORONOI_FEATURES:
            raise Unsupported(f"Voronoi Texture '{node.name}' feature {node.feature} (F1, F2, Smooth F1 are supported)")
        if output.identifier not in self.nodes.VORONOI_OUTPUTS:
            raise Unsupported(f"Voronoi Texture '{node.name}' output {output.name}")
        args = [self._in(node, k, "float", groups) for k in ("Scale", "Detail", "Roughness", "Lacunarity",
                                                               "Smoothness", "Exponent", "Randomness")]
        value = self.program.voronoi(self._texture_vector(node, groups), *args, node.feature, node.distance,
                                     node.normalize, output.identifier)
        return value, {"Distance": "float", "Color": "color", "Position": "vector"}[output.identifier]

    def _tex_wave(self, node, output, groups):
        """Cycles' Wave Texture (kernel/svm/wave.h): Color is the Fac as grey."""
        key = (tuple(g.name for g in groups), node.name, "wave")  # one value for both outputs
        if key not in self._memo:
            p = self.program
            rings = node.wave_type == "RINGS"
            direction = node.rings_direction if rings else node.bands_direction
            args = [self._in(node, k, "float", groups) for k in ("Scale", "Distortion", "Detail", "Detail Scale",
                                                                   "Detail Roughness", "Phase Offset")]
            self._memo[key] = p.wave(self._texture_vector(node, groups), args[0], node.wave_type, direction,
                                     node.wave_profile, *args[1:]), "float"
        fac = self._memo[key][0]
        return (fac, "float") if output.identifier == "Fac" else (self.program.to_color(fac), "color")

    def _tex_brick(self, node, output, groups):
        """Cycles' Brick Texture (kernel/svm/brick.h, brick_noise's integer hash)."""
        colors = [self._in(node, k, "color", groups) for k in ("Color1", "Color2", "Mortar")]
        floats = [self._in(node, k, "float", groups) for k in ("Scale", "Mortar Size", "Mortar Smooth", "Bias",
                                                                 "Brick Width", "Row Height")]
        value = self.program.brick(self._texture_vector(node, groups), floats[0], *colors, *floats[1:], node.offset,
                                   node.offset_frequency, node.squash, node.squash_frequency,
                                   "Fac" if output.identifier == "Fac" else "Color")
        return value, "float" if output.identifier == "Fac" else "color"

    def _mapping(self, node, output, groups):
        from mathutils import Euler, Matrix, Vector

        if node.vector_type not in ("POINT", "TEXTURE", "VECTOR"):
            raise Unsupported(f"Mapping '{node.name}' of type {node.vector_type}")
        names = [n for n in ("Location", "Rotation", "Scale") if n in node.inputs]
        if any(node.inputs[n].is_linked for n in names):
            raise Unsupported(f"Mapping '{node.name}' with linked location, rotation or scale")
        location = node.inputs["Location"].default_value if "Location" in node.inputs else (0.0, 0.0, 0.0)
        rotation = Euler(node.inputs["Rotation"].default_value, "XYZ").to_matrix().to_4x4()
        scale = Matrix.Diagonal((*node.inputs["Scale"].default_value, 1.0))
        # Cycles' mapping: point R (S v) + L; texture its inverse; vector without L.
        m = rotation @ scale
        if node.vector_type == "POINT":
            m = Matrix.Translation(location) @ m
        elif node.vector_type == "TEXTURE":
            m = m.inverted_safe() @ Matrix.Translation(-Vector(location))
        matrix = np.array(m, np.float64)[:3]
        return self.program.affine(self._in(node, "Vector", "vector", groups), matrix), "vector"

    def _math(self, node, output, groups):
        op = node.operation
        if op not in self.nodes.MATH_OPS:
            raise Unsupported(f"Math '{node.name}' operation {op}")
        a, b, c = (self._in(node, k, "float", groups) for k in range(3))
        value = self.program.math(op, a, b, c)
        if node.use_clamp:
            value = self.program.math("CLAMP", value, 0.0, 1.0)
        return value, "float"

    def _clamp(self, node, output, groups):
        value, low, high = (self._in(node, k, "float", groups) for k in range(3))
        p = self.program
        if node.clamp_type == "RANGE":  # either order
            low, high = p.math("MINIMUM", low, high), p.math("MAXIMUM", low, high)
        return p.math("CLAMP", value, low, high), "float"

    def _blend(self, node, mode, fac, a, b, clamp_factor, clamp_result):
        if mode not in self.nodes.BLEND_MODES:
            raise Unsupported(f"Mix '{node.name}' blend mode {mode}")
        if clamp_factor:
            fac = self.program.math("CLAMP", fac, 0.0, 1.0)
        return self.program.mix(mode, fac, a, b, clamp_result)

    def _mix(self, node, output, groups):
        sockets = {s.identifier: s for s in node.inputs}
        fac = self.socket(sockets["Factor_Float"], "float", groups)
        if node.data_type == "FLOAT":
            a, b = (self.socket(sockets[k], "float", groups) for k in ("A_Float", "B_Float"))
            return self._blend(node, "MIX", fac, a, b, node.clamp_factor, False), "float"
        if node.data_type != "RGBA":
            raise Unsupported(f"Mix '{node.name}' of {node.data_type.lower()} values")
        a, b = (self.socket(sockets[k], "color", groups) for k in ("A_Color", "B_Color"))
        return self._blend(node, node.blend_type, fac, a, b, node.clamp_factor, node.clamp_result), "color"

    def _mix_rgb(self, node, output, groups):
        fac, a, b = self._in(node, 0, "float", groups), self._in(node, 1, "color", groups), self._in(node, 2, "color", groups)
        return self._blend(node, node.blend_type, fac, a, b, True, node.use_clamp), "color"

    def _invert(self, node, output, groups):
        return self.program.invert(self._in(node, 0, "float", groups), self._in(node, 1, "color", groups)), "color"

    def _map_range(self, node, output, groups):
        """Cycles' MapRangeNode (clamped by the Clamp node its expand() adds) or, for vectors,
        VectorMapRangeNode, which this does component by component."""
        p = self.program
        kind = node.interpolation_type
        if kind not in self.nodes.MAP_RANGE_TYPES:
            raise Unsupported(f"Map Range '{node.name}' interpolation {kind}")
        sockets = {s.identifier: s for s in node.inputs}
        names = ("Value", "From Min", "From Max", "To Min", "To Max", "Steps")
        if node.data_type == "FLOAT":
            args = [self.socket(sockets[k], "float", groups) if k != "Steps" or kind == "STEPPED" else 4.0 for k in names]
            if output.identifier != "Result":
                return np.zeros(3), "vector"
            return p.map_range(*args[:5], node.clamp, kind, args[5]), "float"
        if node.data_type != "FLOAT_VECTOR":
            raise Unsupported(f"Map Range '{node.name}' of {node.data_type} values")
        if output.identifier != "Vector":
            return 0.0, "float"
        ids = ("Vector", "From_Min_FLOAT3", "From_Max_FLOAT3", "To_Min_FLOAT3", "To_Max_FLOAT3", "Steps_FLOAT3")
        args = [self.socket(sockets[k], "vector", groups) if k != "Steps_FLOAT3" or kind == "STEPPED" else np.full(3, 4.0)
                for k in ids]
        return p.combine(*(p.map_range(*(p.separate(x, k) for x in args[:5]), node.clamp, kind, p.separate(args[5], k),
                                       vector=True) for k in range(3))), "vector"

    def _vect_math(self, node, output, groups):
        """Cycles' svm_vector_math: Value is the float of Dot Product, Distance and Length (0
        for the others), Vector theirs (zero for those three)."""
        op = node.operation
        if op not in self.nodes.VECTOR_MATH_OPS:
            raise Unsupported(f"Vector Math '{node.name}' operation {op}")
        is_float = op in self.nodes.VECTOR_MATH_FLOAT_OPS
        if (output.identifier == "Value") != is_float:
            return (0.0, "float") if output.identifier == "Value" else (np.zeros(3), "vector")
        used = self.nodes.VECTOR_MATH_OPERANDS[op]
        sockets = {s.identifier: s for s in node.inputs}
        a, b, c = (self.socket(sockets[k], "vector", groups) if key in used else np.zeros(3)
                   for k, key in (("Vector", "a"), ("Vector_001", "b"), ("Vector_002", "c")))
        scale = self.socket(sockets["Scale"], "float", groups) if "s" in used else 1.0
        value = self.program.vector_math(op, a, b, c, scale)
        return (value, "float") if is_float else (value, "vector")

    def _blackbody(self, node, output, groups):
        """Blender's Blackbody (nodes.blackbody_reference): folded on the host where the
        temperature is a constant, evaluated per point in a world; not on the device."""
        temperature = self._in(node, "Temperature", "float", groups)
        if self.program.is_constant(temperature):
            return self.nodes.blackbody_reference(float(self.nodes._vec4(temperature)[0])), "color"
        if not hasattr(self.program, "blackbody"):
            raise Unsupported(f"Blackbody '{node.name}' with a varying temperature")
        return self.program.blackbody(temperature), "color"

    def _hue_sat(self, node, output, groups):
        args = [self._in(node, k, "float", groups) for k in ("Hue", "Saturation", "Value", "Fac")]
        return self.program.hsv(self._in(node, "Color", "color", groups), *args), "color"

    def _brightcontrast(self, node, output, groups):
        """Cycles' svm_brightness_contrast: max((1 + contrast) color + bright - contrast / 2, 0)."""
        p = self.program
        color = self._in(node, "Color", "color", groups)
        bright, contrast = self._in(node, "Bright", "float", groups), self._in(node, "Contrast", "float", groups)
        slope = p.to_color(p.math("ADD", 1.0, contrast))
        offset = p.to_color(p.math("SUBTRACT", bright, p.math("MULTIPLY", contrast, 0.5)))
        return p.vector_math("MAXIMUM", p.vector_math("MULTIPLY_ADD", color, slope, offset), np.zeros(3)), "color"

    def _gamma(self, node, output, groups):
        color, gamma = self._in(node, "Color", "color", groups), self._in(node, "Gamma", "float", groups)
        return self.program.vector_math("GAMMA", color, scale=gamma), "color"

    def _curve_tables(self, node, curves):
        """Cycles' curvemapping_color_to_array / curvemapping_float_to_array and
        curvemapping_minmax (intern/cycles/blender/util.h): 256 samples over the range of all the
        curves' points (the RGB ones through the combined curve first), and that range."""
        mapping = node.mapping
        mapping.initialize()
        lo = min(c.points[0].location[0] for c in curves)
        hi = max(c.points[len(c.points) - 1].location[0] for c in curves)
        size = self.nodes.NODE_RAMP_SIZE
        xs = [float(np.float32(lo + np.float32(i) / np.float32(size - 1) * np.float32(hi - lo))) for i in range(size)]
        if len(curves) == 1:
            table = [mapping.evaluate(curves[0], x) for x in xs]
        else:
            combined = [mapping.evaluate(curves[3], x) for x in xs]
            table = [[mapping.evaluate(curves[k], y) for k in range(3)] for y in combined]
        return np.array(table, np.float64), lo, hi, mapping.extend == "EXTRAPOLATED"

    def _curve_rgb(self, node, output, groups):
        table, lo, hi, extrapolate = self._curve_tables(node, node.mapping.curves[:4])
        fac, color = self._in(node, "Fac", "float", groups), self._in(node, "Color", "color", groups)
        return self.program.curves(table, lo, hi, extrapolate, fac, color), "color"

    def _curve_float(self, node, output, groups):
        table, lo, hi, extrapolate = self._curve_tables(node, node.mapping.curves[:1])
        fac, value = self._in(node, "Factor", "float", groups), self._in(node, "Value", "float", groups)
        return self.program.curves(table, lo, hi, extrapolate, fac, value), "float"

    def _valtorgb(self, node, output, groups):
        ramp = node.color_ramp
        size = self.nodes.NODE_RAMP_SIZE
        table = np.array([ramp.evaluate(i / (size - 1)) for i in range(size)], np.float64)
        value = self.program.ramp(self._in(node, "Fac", "float", groups), table, ramp.interpolation != "CONSTANT")
        if output.name == "Alpha":
            return self.program.separate(value, 3), "float"
        return value, "color"

    def _separate(self, node, output, groups, kind):
        value = self._in(node, 0, kind, groups)
        component = [s.identifier for s in node.outputs].index(output.identifier)
        return self.program.separate(value, component), "float"

    def _separate_color(self, node, output, groups):
        if node.mode != "RGB":
            raise Unsupported(f"Separate Color '{node.name}' in {node.mode}")
        return self._separate(node, output, groups, "color")

    def _seprgb(self, node, output, groups):
        return self._separate(node, output, groups, "color")

    def _sepxyz(self, node, output, groups):
        return self._separate(node, output, groups, "vector")

    def _combine(self, node, groups, kind):
        x, y, z = (self._in(node, k, "float", groups) for k in range(3))
        return self.program.combine(x, y, z), kind

    def _combine_color(self, node, output, groups):
        if node.mode != "RGB":
            raise Unsupported(f"Combine Color '{node.name}' in {node.mode}")
        return self._combine(node, groups, "color")

    def _combrgb(self, node, output, groups):
        return self._combine(node, groups, "color")

    def _combxyz(self, node, output, groups):
        return self._combine(node, groups, "vector")
