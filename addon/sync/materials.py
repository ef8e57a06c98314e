"""Blender materials (Cycles node trees) -> Parallax materials.

A node tree is reduced to weighted BSDF lobes plus one emission colour:
  Diffuse BSDF -> diffuse; Glossy BSDF -> GGX conductor (colour = reflectance, like Cycles);
  Glass BSDF -> GGX dielectric; Emission -> emission;
  Principled BSDF -> one principled material (Cycles' Principled v2: sheen, coat, F82-tint
      metal, glass, specular layer and diffuse base; shaders/lib/principled.glsl), plus
      emission colour * strength;
  Mix Shader and Add Shader -> weighted sums of their inputs;
  Image Texture (UV mapped) into a colour input -> that lobe's sRGB base-colour texture;
  any other graph of texture and maths nodes into a colour or factor input (node_graph.py) ->
  a node program the core runs at each hit, as Cycles' SVM does (also for a Mix Shader's
  factor: the chain's selection weights follow it).
Several lobes become a chain of core materials picked stochastically per hit with
probability weight / total (``Material.mix_next``/``mix_weight``); the total weight scales the
lobes' colours. Multiscatter GGX (the default of Glossy, Glass and Principled) is GGX with
Cycles' energy compensation. Documented approximations, each warned about once: Beckmann is
rendered as single-scatter GGX; Principled's sheen is a Charlie sheen lobe (Cycles' is a
fitted microfibre LTC), its subsurface renders as diffuse, its anisotropy, thin film, normal
inputs and alpha are ignored, and its emission is not dimmed by coat and sheen; linked factors and colours other than an Image Texture use the
socket's own value where node_graph.py cannot compile them; any other shader node renders as a
diffuse surface of its colour.
"""
import numpy as np

from .images import image_rgb
from .node_graph import GraphCompiler, Unsupported, attribute_requests, tangent_uv_maps

DEFAULT_COLOR = (0.8, 0.8, 0.8)  # Cycles' surface for objects without a material


class MaterialTable:
    """Global material indices for Blender materials.

    ``index`` hands out head indices while the geometry is exported; ``build`` then fills
    ``data.materials`` and ``data.textures``: the heads first, at those indices, and the
    extra lobes of mixed materials after them. So a later ``build`` (a material edit in the
    viewport) keeps every index the geometry refers to.
    """

    def __init__(self, warnings):
        from ..core import load

        self._scene = load().scene
        self._nodes = load().nodes
        self._warnings = warnings
        self._materials = []  # Blender materials (None: no material), by head index
        self._index = {}
        # Mesh data the node graphs read (node_graph.attribute_requests keys), by attribute
        # slot: the mesh export adds them as it meets them.
        self.attribute_keys = []
        self.has_emission = False

    def index(self, material):
        key = material.name_full if material is not None else None
        if key not in self._index:
            self._index[key] = len(self._materials)
            self._materials.append(material)
        return self._index[key]

    def __len__(self):
        return len(self._materials)

    def tangent_maps(self, index):
        """The UV maps ('' for the active one) whose tangents material ``index``'s Normal Maps
        need (the mesh export computes them)."""
        material = self._materials[index]
        return frozenset(tangent_uv_maps(node_tree(material))) if material is not None else frozenset()

    def attribute_requests(self, index):
        """The attribute_requests keys of material ``index``'s node tree."""
        material = self._materials[index]
        return frozenset(attribute_requests(node_tree(material))) if material is not None else frozenset()

    def attribute_slot(self, key, add=False):
        """The slot of attribute key ``key`` (added when ``add``; else None if no mesh has it)."""
        if key not in self.attribute_keys:
            if not add:
                return None
            self.attribute_keys.append(key)
        return self.attribute_keys.index(key)

    def build(self, data, warnings=None):
        """(Re)reads every material's node tree into ``data.materials``/``data.textures``."""
        if warnings is not None:
            self._warnings = warnings
        # Built aside and swapped in at the end: a viewport render thread may be reading
        # ``data`` at the same time.
        self._out_materials, self._out_textures, self._textures = [None] * len(self._materials), [], {}
        self.has_emission = False
        for head, material in enumerate(self._materials):
            name, lobes, emission = self._read(material)
            self._add_chain(head, name, lobes, emission)
        data.materials, data.textures = self._out_materials, self._out_textures

    # -- building core materials --

    def _read(self, material):
        """(name, [(weight, lobe)], emission) of a Blender material."""
        self._program = self._nodes.Program()
        if material is None:
            return "", [(1.0, _lobe("diffuse", DEFAULT_COLOR))], np.zeros(3)
        tree = node_tree(material)
        output = tree.get_output_node("CYCLES") if tree is not None else None
        if output is None:
            return material.name, [(1.0, _lobe("diffuse", tuple(material.diffuse_color[:3])))], np.zeros(3)
        reader = _NodeReader(material.name, self._warnings, self._texture, self.attribute_slot)
        lobes, emission = reader.shader(output.inputs.get("Surface"))
        self._program = reader.program
        return material.name, lobes, emission

    def _add_chain(self, head, name, lobes, emission):
        """Puts the head material (which carries the emission) at ``head`` and appends the
        rest of its lobe chain. Weights and inputs the node graph drives (registers of the
        material's node program) are set per hit by each link's program."""
        program = self._program
        constant = program.is_constant
        lobes = [(w, lobe) for w, lobe in lobes if not constant(w) or w > 0.0]
        total = 0.0
        for w, _ in lobes:
            total = program.math("ADD", total, w)
        if np.any(emission > 0):
            self.has_emission = True
        if constant(total) and abs(total - 1.0) > 1e-6 and any(lobe["type"] == "principled" for _, lobe in lobes):
            self._warnings.add(f"material '{name}': shaders adding up to a weight of {total:.3g} "
                               "scale a Principled BSDF's base colour only")
        Material = self._scene.Material
        materials = self._out_materials
        if not lobes:
            materials[head] = Material(type="emission", base_color=(0.0, 0.0, 0.0),
                                       emission=tuple(emission), name=name)
            return
        for i, (w, lobe) in enumerate(lobes):
            last = i == len(lobes) - 1
            link = program.fork()

            def field(key, value, neutral):
                """The Material's constant for ``value``, or ``neutral`` and a store."""
                if constant(value):
                    return value
                link.store(key, value)
                return neutral

            # This link's share of what is left of the chain: w_i / sum_{j >= i} w_j.
            remaining = 0.0
            for w_later, _ in lobes[i:]:
                remaining = link.math("ADD", remaining, w_later)
            weight = 1.0 if last else link.math("DIVIDE", w, remaining)
            color = lobe["base_color"]
            if not (constant(total) and total == 1.0):
                color = link.mix("MULTIPLY", 1.0, color, link.to_color(total))  # the lobes' weights add up to total
            principled = {k: field(k, v, 1.0 if k == "transmission" else 0.0) for k, v in lobe["principled"].items()}
            if lobe["normal"] is not None:
                link.store("normal", lobe["normal"])
            # The next lobe is appended after this one (after the head: at the end).
            next_index = len(materials) + (0 if i == 0 else 1)
            material = Material(
                type=lobe["type"], base_color=tuple(np.asarray(field("base_color", color, (1.0, 1.0, 1.0)))[:3]),
                roughness=field("roughness", lobe["roughness"], 0.0), ior=lobe["ior"],
                emission=tuple(emission) if i == 0 else (0.0, 0.0, 0.0),
                base_color_texture=lobe["texture"], name=name if i == 0 else f"{name} (lobe {i})",
                multiscatter=lobe["multiscatter"], **principled,
                mix_next=None if last else next_index,
                mix_weight=1.0 if last else min(1.0, float(field("mix_weight", weight, 1.0))))
            if link.words != program.words:
                material.node_program = tuple(link.finish())
            if i == 0:
                materials[head] = material
            else:
                materials.append(material)

    def _texture(self, image, node_label, interpolation="linear"):
        """Index of ``image`` with ``interpolation`` ("linear" or "closest") in data.textures
        (row 0 at the top), or None."""
        key = (image.name_full, interpolation)
        if key not in self._textures:
            self._textures[key] = self._load_texture(image, node_label, interpolation)
        return self._textures[key]

    def _load_texture(self, image, node_label, interpolation):
        loaded = image_rgb(image)
        if loaded is None:
            self._warnings.add(f"{node_label}: image '{image.name}' has no pixels (missing "
                               "file?); using the input's colour")
            return None
        pixels, stored_as_srgb = loaded
        if stored_as_srgb:  # 8-bit sRGB: bytes, interpolated before decoding (as Cycles)
            texels = np.clip(np.rint(pixels * 255.0), 0, 255).astype(np.uint8)
        else:  # float images and non-colour data: linear floats (half texels in the core)
            if not np.isfinite(pixels).all():
                self._warnings.add(f"{node_label}: image '{image.name}' has NaN or infinite pixels; "
                                   "replaced by 0 (NaN) and the largest half float (infinity)")
            texels = np.nan_to_num(pixels, nan=0.0, posinf=self._scene.HALF_MAX, neginf=0.0)
        self._out_textures.append(self._scene.Texture(np.ascontiguousarray(texels), name=image.name,
                                                      interpolation=interpolation))
        return len(self._out_textures) - 1


def node_tree(id_block):
    """The material/world node tree Cycles would use, or None (Blender 5 always uses nodes)."""
    import bpy

    if bpy.app.version < (5, 0, 0) and not id_block.use_nodes:
        return None
    return id_block.node_tree


def _lobe(type, base_color, roughness=0.5, ior=1.45, texture=None, multiscatter=False, principled=None, normal=None):
    from ..core import load

    constant = load().nodes.Program.is_constant  # else a register of the material's node program
    return dict(type=type, base_color=np.asarray(base_color[:3], dtype=np.float64) if constant(base_color) else base_color,
                roughness=float(roughness) if constant(roughness) else roughness,
                ior=float(ior), texture=texture,
                multiscatter=bool(multiscatter) and type in ("conductor", "dielectric", "principled"),
                principled=principled or {}, normal=normal)


class _NodeReader:
    """Walks one material's node tree from its output's Surface socket."""

    def __init__(self, material_name, warnings, texture_loader, attribute_slot):
        from ..core import load

        self.name = material_name
        self.warnings = warnings
        self.texture_loader = texture_loader
        self.program = load().nodes.Program()
        self.graph = GraphCompiler(self.program, texture_loader, material_name, attribute_slot)

    def driven(self, node, name, default, kind="float"):
        """The value at input ``name``: a constant, or a register of the material's node
        program when texture and maths nodes drive it. A graph the compiler cannot translate
        is named in a warning, and the socket's own value used (as before programs)."""
        socket = node.inputs.get(name)
        if socket is None:
            return default
        if self._source(socket) is None:
            return float(socket.default_value) if kind == "float" else np.asarray(socket.default_value[:3], np.float64)
        try:
            return self.graph.socket(socket, kind)
        except (Unsupported, ValueError) as e:  # ValueError: the program needs too many registers
            own = socket.default_value if kind == "float" else tuple(socket.default_value[:3])
            self.warn(f"'{node.name}' {name} is driven by {e}, which is not supported; using its value "
                      f"{own if kind != 'float' else f'{own:.3g}'}")
            return float(socket.default_value) if kind == "float" else np.asarray(socket.default_value[:3], np.float64)

    def warn(self, text):
        self.warnings.add(f"material '{self.name}': {text}")

    def normal(self, node, name="Normal"):
        """The shading normal nodes (Bump, Normal Map, ...) give a BSDF: a register of the
        program, or None where the input is unlinked or its graph is not supported (named in a
        warning; the surface's own normal is used)."""
        socket = node.inputs.get(name)
        if socket is None or self._source(socket) is None:
            return None
        try:
            normal = self.graph.socket(socket, "vector")
        except (Unsupported, ValueError) as e:
            self.warn(f"'{node.name}' {name} is driven by {e}, which is not supported; using the surface's normal")
            return None
        if self.program.is_constant(normal):
            self.warn(f"'{node.name}': a constant {name} is not supported; using the surface's normal")
            return None
        return normal

    def ior(self, node, default):
        """The node's IOR clamped into the core's range (scene.IOR_RANGE; Blender allows 0, and
        Cycles clamps it too), with a warning when it was outside."""
        from ..core import load

        ior = self.value(node, "IOR", default)
        low, high = load().scene.IOR_RANGE
        if not low <= ior <= high:
            self.warn(f"'{node.name}': IOR {ior:g} clamped to {low:g}..{high:g}")
            ior = min(max(ior, low), high)
        return ior

    # -- sockets --

    def _source(self, socket):
        """The (node, output socket) feeding ``socket``, through reroutes; None if unlinked."""
        while socket is not None and socket.is_linked:
            link = socket.links[0]
            if getattr(link, "is_muted", False):
                return None
            node = link.from_node
            if node.type == "REROUTE":
                socket = node.inputs[0]
                continue
            return node, link.from_socket
        return None

    def value(self, node, name, default):
        socket = node.inputs.get(name)
        if socket is None:
            return default
        if self._source(socket) is not None:
            self.warn(f"'{node.name}' {name} is driven by nodes; using its value "
                      f"{socket.default_value:.3g}")
        return float(socket.default_value)

    def color(self, node, name, default=DEFAULT_COLOR):
        """(rgb, texture index or None) of a colour input."""
        socket = node.inputs.get(name)
        if socket is None:
            return np.asarray(default, dtype=np.float64), None
        constant = np.asarray(socket.default_value[:3], dtype=np.float64)
        source = self._source(socket)
        if source is None:
            return constant, None
        src, out = source
        mapped = self._source(src.inputs["Vector"]) is not None if src.type == "TEX_IMAGE" else False
        if src.type == "TEX_IMAGE" and out.name == "Color" and src.image is not None and not mapped:
            label = f"material '{self.name}'"  # the texture slot: a mapped one is a node program's
            if src.projection != "FLAT" or src.extension != "REPEAT":
                self.warn(f"image texture '{src.name}' uses {src.projection} projection / "
                          f"{src.extension} extension; rendered as flat, repeating")
            if src.interpolation not in ("Linear", "Closest"):  # Cubic, Smart
                self.warn(f"image texture '{src.name}' uses {src.interpolation} interpolation; "
                          "rendered as Linear")
            interpolation = "closest" if src.interpolation == "Closest" else "linear"
            texture = self.texture_loader(src.image, label, interpolation)
            if texture is not None:
                return np.ones(3), texture
            return constant, None
        return self.driven(node, name, constant, "color"), None

    # -- shaders --

    def shader(self, socket):
        """(list of (weight, lobe), emission rgb) for a shader socket."""
        source = self._source(socket) if socket is not None else None
        if source is None:
            return [], np.zeros(3)  # no surface shader: black, like Cycles
        node = source[0]
        handler = getattr(self, "_" + node.type.lower(), None)
        if handler is None:
            return self._unsupported(node)
        return handler(node)

    def _mix_shader(self, node):
        p = self.program
        f = p.math("CLAMP", self.driven(node, node.inputs[0].name, 0.5), 0.0, 1.0)
        a_lobes, a_emission = self.shader(node.inputs[1])
        b_lobes, b_emission = self.shader(node.inputs[2])
        if not p.is_constant(f) and (np.any(a_emission > 0) or np.any(b_emission > 0)):
            # Emission stays a constant (the light table samples emitters by it).
            f = min(max(float(node.inputs[0].default_value), 0.0), 1.0)
            self.warn(f"'{node.name}': a Mix Shader factor driven by nodes over emission is not supported; "
                      f"using its value {f:.3g}")
        g = p.math("SUBTRACT", 1.0, f)
        lobes = [(p.math("MULTIPLY", g, w), l) for w, l in a_lobes] + [(p.math("MULTIPLY", f, w), l) for w, l in b_lobes]
        if not p.is_constant(f):
            return lobes, a_emission  # both zero
        return lobes, (1.0 - f) * a_emission + f * b_emission

    def _add_shader(self, node):
        a_lobes, a_emission = self.shader(node.inputs[0])
        b_lobes, b_emission = self.shader(node.inputs[1])
        return a_lobes + b_lobes, a_emission + b_emission

    def constant_color(self, node, name, color, texture, default):
        """An input only a constant may drive (emission, tints): the texture's or graph's
        colour is named in a warning and ``default`` (texture) or the socket's value used."""
        if texture is not None:
            self.warn(f"'{node.name}': a texture on {name} is not supported; using {tuple(default)}")
            return np.asarray(default, np.float64)
        if not self.program.is_constant(color):
            own = np.asarray(node.inputs[name].default_value[:3], np.float64)
            self.warn(f"'{node.name}': nodes driving {name} are not supported; using its value {tuple(own.round(3))}")
            return own
        return np.asarray(color, np.float64)[:3]

    def _emission(self, node):
        color, texture = self.color(node, "Color", (1.0, 1.0, 1.0))
        color = self.constant_color(node, "Color", color, texture, (1.0, 1.0, 1.0))
        return [], color * self.value(node, "Strength", 1.0)

    def _bsdf_diffuse(self, node):
        color, texture = self.color(node, "Color")
        if self.value(node, "Roughness", 0.0) > 0.0:
            self.warn(f"'{node.name}': Oren-Nayar roughness is rendered as Lambert (roughness 0)")
        return [(1.0, _lobe("diffuse", color, texture=texture, normal=self.normal(node)))], np.zeros(3)

    def _distribution(self, node, roughness):
        """(roughness, multiscatter) of a microfacet node's distribution."""
        distribution = getattr(node, "distribution", "GGX")
        rough = not self.program.is_constant(roughness) or roughness > 0.0
        if rough and distribution not in ("GGX", "SHARP", "MULTI_GGX"):
            self.warn(f"'{node.name}': {distribution} is rendered as single-scatter GGX")
        return (0.0 if distribution == "SHARP" else roughness), distribution == "MULTI_GGX"

    def _bsdf_glossy(self, node):
        color, texture = self.color(node, "Color")
        roughness, ms = self._distribution(node, self.driven(node, "Roughness", 0.5))
        if abs(self.value(node, "Anisotropy", 0.0)) > 0.0:
            self.warn(f"'{node.name}': anisotropy is ignored")
        return [(1.0, _lobe("conductor", color, roughness, texture=texture, multiscatter=ms,
                            normal=self.normal(node)))], np.zeros(3)

    _bsdf_anisotropic = _bsdf_glossy

    def _bsdf_metallic(self, node):
        self.warn(f"'{node.name}': Metallic BSDF uses its base colour as a constant Fresnel")
        color, texture = self.color(node, "Base Color")
        roughness, ms = self._distribution(node, self.value(node, "Roughness", 0.5))
        return [(1.0, _lobe("conductor", color, roughness, texture=texture, multiscatter=ms))], np.zeros(3)

    def _bsdf_glass(self, node):
        color, texture = self.color(node, "Color", (1.0, 1.0, 1.0))
        roughness, ms = self._distribution(node, self.driven(node, "Roughness", 0.0))
        ior = self.ior(node, 1.5)
        return [(1.0, _lobe("dielectric", color, roughness, ior, texture, ms, normal=self.normal(node)))], np.zeros(3)

    def _bsdf_principled(self, node):
        """Blender 4.x/5.0 inputs; Cycles clamps them as parallax_core.scene.PRINCIPLED_FIELDS."""
        def first(*names):
            return next((n for n in names if n in node.inputs), names[0])

        def tint(name):
            """A colour input; white where it is missing or, before Blender 4.0, a float."""
            if getattr(node.inputs.get(name), "type", None) != "RGBA":
                return (1.0, 1.0, 1.0)
            rgb, texture = self.color(node, name, (1.0, 1.0, 1.0))
            return tuple(float(x) for x in self.constant_color(node, name, rgb, texture, (1.0, 1.0, 1.0)))

        color, texture = self.color(node, "Base Color")
        roughness, ms = self._distribution(node, self.driven(node, "Roughness", 0.5))
        ior = self.ior(node, 1.5)
        if "Specular IOR Level" not in node.inputs:
            self.warn(f"'{node.name}': a Principled BSDF older than Blender 4.0; only its base "
                      "colour, metallic, roughness, IOR and transmission are read")
        principled = dict(
            metallic=self.driven(node, "Metallic", 0.0),
            transmission=self.driven(node, first("Transmission Weight", "Transmission"), 0.0),
            specular_ior_level=self.driven(node, "Specular IOR Level", 0.5),
            specular_tint=tint("Specular Tint"),
            coat_weight=self.driven(node, "Coat Weight", 0.0),
            coat_roughness=self.driven(node, "Coat Roughness", 0.03),
            coat_ior=self.value(node, "Coat IOR", 1.5),
            coat_tint=tint("Coat Tint"),
            sheen_weight=self.driven(node, "Sheen Weight", 0.0),
            sheen_roughness=self.value(node, "Sheen Roughness", 0.5),
            sheen_tint=tint("Sheen Tint"),
        )
        if not self.program.is_constant(principled["sheen_weight"]) or principled["sheen_weight"] > 0.0:
            self.warn(f"'{node.name}': Sheen is approximated (a Charlie sheen lobe, not Cycles' "
                      "microfibre LTC)")
        for name in ("Subsurface Weight", "Subsurface"):
            if name in node.inputs and self.value(node, name, 0.0) > 0.0:
                self.warn(f"'{node.name}': {name} is rendered as diffuse")
        if "Anisotropic" in node.inputs and self.value(node, "Anisotropic", 0.0) > 0.0:
            self.warn(f"'{node.name}': Anisotropic is ignored")
        if "Thin Film Thickness" in node.inputs and self.value(node, "Thin Film Thickness", 0.0) > 0.0:
            self.warn(f"'{node.name}': Thin Film is ignored")
        if "Coat Normal" in node.inputs and self._source(node.inputs["Coat Normal"]) is not None:
            self.warn(f"'{node.name}': the Coat Normal input is ignored (the coat uses the Normal)")
        if self.value(node, "Alpha", 1.0) < 1.0:
            self.warn(f"'{node.name}': Alpha is ignored (rendered opaque)")
        lobes = [(1.0, _lobe("principled", color, roughness, ior, texture, ms, principled, self.normal(node)))]
        emission_name = first("Emission Color", "Emission")
        emission_color, emission_texture = self.color(node, emission_name, (0.0, 0.0, 0.0))
        emission_color = self.constant_color(node, emission_name, emission_color, emission_texture, (1.0, 1.0, 1.0))
        emission = emission_color * self.value(node, "Emission Strength", 1.0)
        return lobes, emission

    def _unsupported(self, node):
        name = next((n for n in ("Color", "Base Color") if n in node.inputs), None)
        color = np.asarray(node.inputs[name].default_value[:3]) if name else np.asarray(DEFAULT_COLOR)
        self.warn(f"'{node.bl_label}' node '{node.name}' is not supported; rendered as a diffuse "
                  "surface of its colour")
        return [(1.0, _lobe("diffuse", color))], np.zeros(3)
