"""The public test scenes in the shared scenes folder, as Parallax ``SceneData``.

    from bench.shared_scenes import SHARED_SCENES, available, thesis_irradiance_cache
    if available("thesis_irradianceCache"):
        scene = thesis_irradiance_cache(width=320)       # 320 x 180, the film's aspect

    .venv/bin/python -m bench.shared_scenes [--width 160] [--spp 256] [--max-depth 16]
        [--png /tmp/thesis_irradiance_cache.png]

The folder is ``<repo>/../shared/scenes`` (``PARALLAX_SHARED_SCENES`` overrides it). Its
files are data for tests and comparisons: they are read from there, never copied into the
repository.

``load_mitsuba(path)`` reads a Mitsuba 0.6 scene (the subset those scenes use) with
xml.etree and a small OBJ reader:

- ``<default>``/``$name`` substitutions, ``<include>``, named objects and ``<ref>``s;
  ``<transform>`` with ``matrix``, ``translate``, ``rotate``, ``scale`` and ``lookAt``
  (each applied after the ones before it, as in Mitsuba).
- Shapes ``obj`` (v/vn/vt/f, polygons as fans, negative indices; ``faceNormals``,
  ``flipNormals``; an OBJ without normals gets Mitsuba's angle-weighted vertex normals),
  ``sphere``, ``rectangle``, ``disk`` and ``cube``, baked into world space.
- BSDFs ``diffuse`` (``reflectance``, default 0.5) and ``twosided`` around it ->
  Material("diffuse"); ``roughconductor`` -> a GGX Material("conductor") coloured by its
  normal-incidence Fresnel reflectance, roughness sqrt(alpha) (both noted). Parallax's diffuse is two-sided; Mitsuba's one-sided diffuse is
  black from behind, which only matters where a back face is seen or lit.
- ``area`` emitters on meshes -> the material's emission (Parallax's mesh emission is
  two-sided, Mitsuba's one-sided). An ``area`` emitter on a ``sphere`` -> a Parallax point
  light of that radius with the same radiance: the core's sphere light has radiance
  P / (4 pi^2 r^2) * colour (native/src/scene/scene.cpp), so P = L * 4 pi^2 r^2.
- ``point`` (intensity I -> P = 4 pi I), ``directional`` (irradiance E -> a sun of strength
  E, angle 0), ``constant`` (radiance -> World colour) and ``envmap`` (an EXR in Mitsuba's
  latitude-longitude layout, u = atan2(x, -z) / 2 pi, v = acos(y) / pi in the emitter's
  frame, resampled into Blender's layout; not checked against a reference render).
- ``perspective`` (and ``thinlens``, without depth of field) sensors: ``fov`` with
  ``fovAxis`` (x, y, diagonal, smaller, larger) or ``focalLength``; ``toWorld``; near/far
  clip; the ``hdrfilm``'s width and height (default 768 x 576).

Coordinates: Mitsuba scenes exported from Blender are Y up; ``z_up=True`` (the default)
turns them into Blender's Z up with (x, y, z) -> (x, -z, y), which is what Blender's OBJ
import does (forward -Z, up Y). Mitsuba's camera looks down its local +Z with +Y up and
its local +X pointing to the image's LEFT (``lookAt`` puts "left" = up x dir in the first
column), so Parallax's camera (-Z forward, +X right) is ``toWorld`` with its X and Z
columns negated.

Anything else (other BSDFs, textures, other shapes and emitters) raises
NotImplementedError naming it. Approximations are listed in ``notes``.
"""
from __future__ import annotations

import argparse
import math
import os
import re
import sys
import time
import xml.etree.ElementTree as ET

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
SHARED_SCENES = os.path.abspath(os.environ.get("PARALLAX_SHARED_SCENES")
                                or os.path.join(REPO, "..", "shared", "scenes"))

IRRADIANCE_CACHE = "thesis_irradianceCache"
VEACH_MIS = "thesis_veachMIS"

# Mitsuba (Y up) -> Blender (Z up): (x, y, z) -> (x, -z, y).
Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0, 0.0],
                         [0.0, 0.0, -1.0, 0.0],
                         [0.0, 1.0, 0.0, 0.0],
                         [0.0, 0.0, 0.0, 1.0]])


def available(name):
    """Whether the shared folder holds the scene ``name`` (a folder name, as in its README)."""
    return os.path.isdir(os.path.join(SHARED_SCENES, name))


def scene_path(name, *parts):
    return os.path.join(SHARED_SCENES, name, *parts)


# ---- OBJ -------------------------------------------------------------------------------------

def _obj_index(token, count, line_no, path):
    i = int(token)
    if i > 0:
        i -= 1
    elif i < 0:
        i += count
    else:
        raise ValueError(f"{path}:{line_no}: OBJ index 0")
    if not 0 <= i < count:
        raise ValueError(f"{path}:{line_no}: OBJ index {token} out of range ({count} defined)")
    return i


def read_obj(path):
    """A Wavefront OBJ file as (positions (V,3), indices (T,3), normals (T,3,3) or None,
    uvs (T,3,2) or None). Polygons become fans (0, k, k+1); negative indices count back from
    the last element defined; normals and UVs are per corner (None when no face has them;
    corners without a normal get their face's normal, corners without a UV get (0, 0)).
    Groups, objects, materials and smoothing groups are ignored."""
    v, vt, vn = [], [], []
    corners = []  # (T*3, 3): position, uv, normal index per corner (-1: none)
    with open(path, "r", encoding="utf-8", errors="replace") as f:
        for line_no, line in enumerate(f, 1):
            parts = line.split()
            if not parts or parts[0].startswith("#"):
                continue
            tag = parts[0]
            if tag == "v":
                v.append([float(x) for x in parts[1:4]])
            elif tag == "vt":
                vt.append(([float(x) for x in parts[1:3]] + [0.0, 0.0])[:2])
            elif tag == "vn":
                vn.append([float(x) for x in parts[1:4]])
            elif tag == "f":
                face = []
                for tok in parts[1:]:
                    fields = tok.split("/")
                    idx = []
                    for k, count in enumerate((len(v), len(vt), len(vn))):
                        s = fields[k] if k < len(fields) else ""
                        idx.append(_obj_index(s, count, line_no, path) if s else -1)
                    if idx[0] < 0:
                        raise ValueError(f"{path}:{line_no}: face corner without a vertex")
                    face.append(idx)
                for k in range(1, len(face) - 1):
                    corners += [face[0], face[k], face[k + 1]]
    positions = np.asarray(v, dtype=np.float64).reshape(-1, 3)
    c = np.asarray(corners, dtype=np.int64).reshape(-1, 3, 3)
    indices = c[:, :, 0]
    normals = uvs = None
    if (c[:, :, 2] >= 0).any():
        n = np.asarray(vn, dtype=np.float64).reshape(-1, 3)
        normals = n[np.maximum(c[:, :, 2], 0)]
        missing = c[:, :, 2] < 0
        if missing.any():
            face_n = _face_normals(positions, indices)
            normals[missing] = np.broadcast_to(face_n[:, None, :], normals.shape)[missing]
    if (c[:, :, 1] >= 0).any():
        t = np.asarray(vt, dtype=np.float64).reshape(-1, 2)
        uvs = np.where((c[:, :, 1] >= 0)[..., None], t[np.maximum(c[:, :, 1], 0)], 0.0)
    return positions, indices, normals, uvs


def _face_normals(positions, indices):
    p = positions[indices]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)


def _vertex_normals(positions, indices):
    """Mitsuba's TriMesh::computeNormals: per vertex, the face normals weighted by the
    corner angles, normalised; returned per corner (T,3,3)."""
    p = positions[indices]
    face_n = _face_normals(positions, indices)
    acc = np.zeros_like(positions)
    for k in range(3):
        e1 = p[:, (k + 1) % 3] - p[:, k]
        e2 = p[:, (k + 2) % 3] - p[:, k]
        cos = np.einsum("ij,ij->i", e1, e2) / np.maximum(
            np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1), 1e-30)
        angle = np.arccos(np.clip(cos, -1.0, 1.0))
        np.add.at(acc, indices[:, k], face_n * angle[:, None])
    acc /= np.maximum(np.linalg.norm(acc, axis=1, keepdims=True), 1e-30)
    return acc[indices]


# ---- Mitsuba XML -----------------------------------------------------------------------------

_SPLIT = re.compile(r"[,\s]+")


def _numbers(text):
    return [float(x) for x in _SPLIT.split(text.strip()) if x]


def _translate(t):
    m = np.eye(4)
    m[:3, 3] = t
    return m


def _scale(s):
    return np.diag([*np.broadcast_to(np.asarray(s, dtype=np.float64), (3,)), 1.0])


def _rotate(axis, degrees):
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    x, y, z = a
    m = np.eye(4)
    m[:3, :3] = [[c + x * x * (1 - c), x * y * (1 - c) - z * s, x * z * (1 - c) + y * s],
                 [y * x * (1 - c) + z * s, c + y * y * (1 - c), y * z * (1 - c) - x * s],
                 [z * x * (1 - c) - y * s, z * y * (1 - c) + x * s, c + z * z * (1 - c)]]
    return m


def _look_at(origin, target, up):
    """Mitsuba's lookAt: columns (left, up', dir, origin), left = normalize(up x dir)."""
    origin, target = np.asarray(origin, float), np.asarray(target, float)
    d = target - origin
    d /= np.linalg.norm(d)
    up = np.asarray(up, float) if up is not None else np.array([0.0, 1.0, 0.0])
    left = np.cross(up, d)
    if np.linalg.norm(left) < 1e-9:  # up along the view direction: any perpendicular
        left = np.cross([1.0, 0.0, 0.0] if abs(d[0]) < 0.9 else [0.0, 0.0, 1.0], d)
    left /= np.linalg.norm(left)
    new_up = np.cross(d, left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, new_up, d, origin
    return m


def _srgb_to_linear(c):
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


class MitsubaScene:
    """A Mitsuba 0.6 XML scene turned into Parallax SceneData (see the module docstring).

    ``scene`` is the SceneData, ``notes`` the approximations made (strings)."""

    def __init__(self, path, width=None, height=None, z_up=True, sphere_segments=64):
        from parallax_core.scene import SceneData, World

        self.path = os.path.abspath(path)
        self.dir = os.path.dirname(self.path)
        self.basis = Y_UP_TO_Z_UP if z_up else np.eye(4)
        self.sphere_segments = sphere_segments
        self.notes = []
        self.meshes, self.materials, self.lights = [], [], []
        self.world = World((0.0, 0.0, 0.0), 1.0)
        self._material_keys = {}
        root = ET.parse(self.path).getroot()
        if root.tag != "scene":
            raise ValueError(f"{path}: root element <{root.tag}>, expected <scene>")
        self.version = root.get("version", "")
        self.integrator = None  # (type, properties) of the <integrator>, for information
        self.defaults = {}
        root = self._expand(root, self.dir)
        self.ids = {}
        for el in root.iter():
            if el.get("id") is not None and el.tag not in ("default", "ref"):
                self.ids[el.get("id")] = el
        camera, film = None, None
        for el in root:
            if el.tag == "shape":
                self._shape(el)
            elif el.tag == "emitter":
                self._emitter(el, None)
            elif el.tag == "sensor":
                if camera is not None:
                    self.notes.append("more than one sensor: the first one is used")
                    continue
                camera, film = el, el.find("film")
            elif el.tag in ("integrator", "bsdf", "texture", "default", "medium"):
                if el.tag == "integrator":
                    self.integrator = (el.get("type"), self._props(el))
                continue  # bsdfs/textures are used through <ref>s
            else:
                raise NotImplementedError(f"{path}: top-level <{el.tag}> is not supported")
        if camera is None:
            raise ValueError(f"{path}: no <sensor>")
        self.film_size = self._film_size(film)
        self.width, self.height = self._resolution(width, height)
        self.camera = self._camera(camera)
        self.scene = SceneData(self.meshes, [], self.materials, [], self.lights, self.world,
                               self.camera, self.width, self.height)

    # -- parsing --------------------------------------------------------------------------

    def _substitute(self, text):
        def repl(m):
            if m.group(1) not in self.defaults:
                raise ValueError(f"{self.path}: ${m.group(1)} has no <default> value")
            return self.defaults[m.group(1)]
        return re.sub(r"\$(\w+)", repl, text) if "$" in text else text

    def _expand(self, root, base_dir):
        """The tree with <default>s collected, $names substituted and <include>s spliced."""
        for el in root.iter("default"):
            self.defaults.setdefault(el.get("name"), el.get("value", ""))
        out = ET.Element(root.tag, root.attrib)
        for el in root:
            if el.tag == "include":
                inc = os.path.join(base_dir, self._substitute(el.get("filename", "")))
                sub = self._expand(ET.parse(inc).getroot(), os.path.dirname(inc))
                out.extend(list(sub))
                continue
            out.append(self._substituted(el))
        return out

    def _substituted(self, el):
        new = ET.Element(el.tag, {k: self._substitute(v) for k, v in el.attrib.items()})
        new.extend(self._substituted(c) for c in el)
        return new

    def _value(self, el):
        tag, a = el.tag, el.attrib
        if tag == "float":
            return float(a["value"])
        if tag == "integer":
            return int(a["value"])
        if tag == "boolean":
            return a["value"].strip().lower() == "true"
        if tag == "string":
            return a["value"]
        if tag in ("point", "vector"):
            if "value" in a:
                return np.array(_numbers(a["value"]), dtype=np.float64).reshape(3)
            return np.array([float(a.get(k, 0.0)) for k in "xyz"])
        if tag in ("rgb", "srgb", "spectrum"):
            text = a.get("value", "").strip()
            if tag == "srgb" and text.startswith("#"):
                h = text[1:]
                return _srgb_to_linear([int(h[i:i + 2], 16) / 255.0 for i in (0, 2, 4)])
            if tag == "spectrum" and (":" in text or "filename" in a):
                raise NotImplementedError(f"{self.path}: sampled <spectrum> '{text}'")
            v = np.asarray(_numbers(text), dtype=np.float64)
            if v.size == 1:
                v = np.repeat(v, 3)
            if v.size != 3:
                raise ValueError(f"{self.path}: <{tag} name='{a.get('name')}'> value '{text}'")
            return _srgb_to_linear(v) if tag == "srgb" else v
        if tag == "transform":
            return self._transform(el)
        if tag in ("blackbody", "texture"):
            raise NotImplementedError(f"{self.path}: <{tag}> as a parameter "
                                      f"('{a.get('name')}')")
        return None

    def _props(self, el):
        """Properties of an element: {name: value} of its parameter children."""
        props = {}
        for c in el:
            if c.get("name") is None:
                continue
            v = self._value(c)
            if v is not None:
                props[c.get("name")] = v
        return props

    def _transform(self, el):
        m = np.eye(4)
        for t in el:
            a = t.attrib
            xyz = lambda default: (np.array(_numbers(a["value"])) if "value" in a
                                   else np.array([float(a.get(k, default)) for k in "xyz"]))
            if t.tag == "matrix":
                step = np.array(_numbers(a["value"]), dtype=np.float64).reshape(4, 4)
            elif t.tag == "translate":
                step = _translate(xyz(0.0))
            elif t.tag == "scale":
                if "value" in a:
                    v = _numbers(a["value"])
                    step = _scale(v[0] if len(v) == 1 else v)
                else:
                    step = _scale(xyz(1.0))
            elif t.tag == "rotate":
                axis = (_numbers(a["axis"]) if "axis" in a
                        else [float(a.get(k, 0.0)) for k in "xyz"])
                step = _rotate(axis, float(a["angle"]))
            elif t.tag.lower() == "lookat":
                up = _numbers(a["up"]) if "up" in a else None
                step = _look_at(_numbers(a["origin"]), _numbers(a["target"]), up)
            else:
                raise NotImplementedError(f"{self.path}: <{t.tag}> in a <transform>")
            m = step @ m
        return m

    def _child(self, el, tag):
        """The child object <tag> of el, directly or through a <ref>."""
        for c in el:
            if c.tag == tag:
                return c
            if c.tag == "ref":
                target = self.ids.get(c.get("id"))
                if target is None:
                    raise ValueError(f"{self.path}: <ref id='{c.get('id')}'> names nothing")
                if target.tag == tag:
                    return target
        return None

    # -- materials ------------------------------------------------------------------------

    def _bsdf(self, bsdf):
        """(type, colour, roughness, name) of a BSDF: ``diffuse`` (possibly in a
        ``twosided``), or ``roughconductor`` -> a GGX conductor whose colour is the Fresnel
        reflectance at normal incidence of its ``eta``/``k`` (Beckmann's alpha is taken as
        GGX's, Cycles roughness = sqrt(alpha); the angular Fresnel falloff is dropped)."""
        if bsdf is None:
            return "diffuse", np.full(3, 0.5), 0.5, "default"
        name = bsdf.get("id", "")
        kind = bsdf.get("type")
        if kind == "twosided":
            inner_kind, color, roughness, inner_name = self._bsdf(self._child(bsdf, "bsdf"))
            return inner_kind, color, roughness, name or inner_name
        if kind == "diffuse":
            for c in bsdf:
                if c.get("name") == "reflectance" and c.tag in ("texture", "ref"):
                    raise NotImplementedError(f"{self.path}: textured diffuse reflectance")
            return "diffuse", self._props(bsdf).get("reflectance", np.full(3, 0.5)), 0.5, name
        if kind == "roughconductor":
            props = self._props(bsdf)
            eta = np.broadcast_to(np.asarray(props.get("eta", 0.0), float), (3,))
            k = np.broadcast_to(np.asarray(props.get("k", 1.0), float), (3,))
            f0 = ((eta - 1) ** 2 + k ** 2) / ((eta + 1) ** 2 + k ** 2)
            alpha = float(props.get("alpha", 0.1))
            label = name or f"roughconductor alpha {alpha:g}"
            if props.get("distribution", "beckmann") != "ggx":
                self.notes.append(f"{label}: Beckmann alpha {alpha:g} rendered as GGX alpha {alpha:g}")
            self.notes.append(f"{label}: conductor Fresnel (eta {eta[0]:g}, k {k[0]:g}) as its "
                              f"normal-incidence reflectance {f0[0]:.3f}")
            return "conductor", f0, math.sqrt(alpha), name
        raise NotImplementedError(f"{self.path}: <bsdf type='{kind}'> (only diffuse, twosided "
                                  "and roughconductor are converted)")

    def _material(self, bsdf, emission=None):
        from parallax_core.scene import Material

        kind, color, roughness, name = self._bsdf(bsdf)
        em = (0.0, 0.0, 0.0) if emission is None else tuple(float(x) for x in emission)
        key = (id(bsdf) if bsdf is not None else None, em)
        if key not in self._material_keys:
            self._material_keys[key] = len(self.materials)
            if not name:
                name = f"{bsdf.get('type')}{len(self.materials)}" if bsdf is not None else "default"
            if emission is not None:
                name += "_emitter"
            self.materials.append(Material(kind, tuple(float(x) for x in color), roughness=roughness,
                                           emission=em, emission_strength=1.0, name=name))
        return self._material_keys[key]

    # -- shapes ---------------------------------------------------------------------------

    def _world_matrix(self, m=None):
        return self.basis @ (np.eye(4) if m is None else m)

    def _shape(self, el):
        from parallax_core.scene import Mesh
        from parallax_core.scenes import uv_sphere

        kind = el.get("type")
        props = self._props(el)
        to_world = props.get("toWorld", props.get("to_world"))
        emitter = self._child(el, "emitter")
        radiance = None
        if emitter is not None:
            if emitter.get("type") != "area":
                raise NotImplementedError(f"{self.path}: <emitter type='{emitter.get('type')}'>"
                                          " on a shape")
            radiance = self._props(emitter).get("radiance", np.ones(3))
        bsdf = self._child(el, "bsdf")
        label = el.get("id") or props.get("filename") or kind
        if kind == "sphere":
            center = props.get("center", np.zeros(3))
            radius = float(props.get("radius", 1.0))
            m = self._world_matrix(to_world)
            center = (m @ np.append(center, 1.0))[:3]
            scale = np.abs(np.linalg.det(m[:3, :3])) ** (1.0 / 3.0)
            radius *= scale
            if radiance is not None:
                self._sphere_light(center, radius, radiance, bsdf, label)
                return
            mesh = uv_sphere(center, radius, self.sphere_segments, self.sphere_segments // 2,
                             self._material(bsdf), label)
            self.meshes.append(mesh)
            return
        if kind == "obj":
            positions, indices, normals, uvs = read_obj(os.path.join(self.dir, props["filename"]))
            if props.get("faceNormals", props.get("face_normals", False)):
                normals = None
            elif normals is None:
                normals = _vertex_normals(positions, indices)
            if props.get("flipNormals", props.get("flip_normals", False)):
                indices = indices[:, ::-1]
                normals = None if normals is None else -normals[:, ::-1]
                uvs = None if uvs is None else uvs[:, ::-1]
        elif kind in ("rectangle", "disk", "cube"):
            positions, indices, normals = self._analytic(kind)
            uvs = None
        else:
            raise NotImplementedError(f"{self.path}: <shape type='{kind}'>")
        m = self._world_matrix(to_world)
        a, t = m[:3, :3], m[:3, 3]
        positions = positions @ a.T + t
        if normals is not None:
            n = normals @ np.linalg.inv(a)  # (A^-T n) as rows
            normals = n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-30)
        if np.linalg.det(a) < 0:  # a mirror: keep the geometric normal the transformed one
            indices = indices[:, ::-1]
            normals = None if normals is None else normals[:, ::-1]
            uvs = None if uvs is None else uvs[:, ::-1]
        material = self._material(bsdf, radiance)
        self.meshes.append(Mesh(positions, indices, normals=normals, uvs=uvs,
                                material_indices=np.full(len(indices), material, np.int64),
                                name=os.path.splitext(os.path.basename(str(label)))[0]))
        if radiance is not None:
            self.notes.append(f"{label}: Mitsuba's area emitter is one-sided, Parallax's mesh "
                              "emission two-sided")

    def _analytic(self, kind):
        """Mitsuba's canonical rectangle ([-1,1]^2 at z=0, facing +z), disk (unit, facing +z)
        and cube ([-1,1]^3) as (positions, indices, flat corner normals or None)."""
        if kind == "rectangle":
            p = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float64)
            return p, np.array([[0, 1, 2], [0, 2, 3]]), None
        if kind == "disk":
            n = self.sphere_segments
            phi = 2 * np.pi * np.arange(n) / n
            p = np.concatenate([[[0.0, 0.0, 0.0]],
                                np.stack([np.cos(phi), np.sin(phi), np.zeros(n)], 1)])
            i = np.arange(n)
            return p, np.stack([np.zeros(n, np.int64), 1 + i, 1 + (i + 1) % n], 1), None
        from parallax_core.scenes import box
        b = box((0.0, 0.0, 0.0), 2.0)
        return b.positions, np.asarray(b.indices), None

    def _sphere_light(self, center, radius, radiance, bsdf, label):
        from parallax_core.scene import Light

        radiance = np.asarray(radiance, dtype=np.float64)
        peak = float(radiance.max())
        if peak <= 0:
            return
        if bsdf is not None and np.any(self._bsdf(bsdf)[1] > 0):
            self.notes.append(f"{label}: the sphere light's non-black BSDF is dropped "
                              "(Parallax's sphere lights do not reflect)")
        # The core's sphere light: radiance = colour * power / (4 pi^2 r^2).
        power = peak * 4.0 * math.pi ** 2 * radius ** 2
        self.lights.append(Light("point", color=tuple(radiance / peak), power=power,
                                 position=tuple(center), radius=radius, camera_visible=True,
                                 name=str(label)))

    # -- emitters -------------------------------------------------------------------------

    def _emitter(self, el, _shape):
        from parallax_core.scene import Light, World

        kind = el.get("type")
        props = self._props(el)
        to_world = props.get("toWorld", props.get("to_world"))
        m = self._world_matrix(to_world)
        if kind == "point":
            pos = props.get("position", np.zeros(3))
            pos = (m @ np.append(pos, 1.0))[:3]
            intensity = props.get("intensity", np.ones(3))
            peak = float(intensity.max())
            if peak > 0:
                self.lights.append(Light("point", color=tuple(intensity / peak),
                                         power=4.0 * math.pi * peak, position=tuple(pos),
                                         radius=0.0, name=el.get("id") or "point"))
        elif kind == "directional":
            d = props.get("direction", np.array([0.0, 0.0, 1.0]))
            d = m[:3, :3] @ d
            e = props.get("irradiance", np.ones(3))
            peak = float(e.max())
            if peak > 0:
                self.lights.append(Light("sun", color=tuple(e / peak), power=peak,
                                         direction=tuple(d / np.linalg.norm(d)), angle=0.0,
                                         name=el.get("id") or "directional"))
        elif kind == "constant":
            self.world = World(tuple(props.get("radiance", np.ones(3))), 1.0)
        elif kind == "envmap":
            self.world = World((0.0, 0.0, 0.0), 1.0,
                               self._envmap(props["filename"], float(props.get("scale", 1.0)),
                                            m))
            self.notes.append("envmap: resampled into Blender's layout (nearest texel)")
        else:
            raise NotImplementedError(f"{self.path}: <emitter type='{kind}'>")

    def _envmap(self, filename, scale, m):
        """Mitsuba lat-long map (row 0 = local +Y, u = atan2(x, -z) / 2 pi) -> Blender's."""
        from parallax_core.exr import read_exr
        from parallax_core.scene import equirectangular_to_direction

        path = os.path.join(self.dir, filename)
        if not path.lower().endswith(".exr"):
            raise NotImplementedError(f"{self.path}: envmap '{filename}' (EXR only)")
        ch = read_exr(path)
        src = np.stack([ch[c] for c in "RGB"], axis=-1).astype(np.float64)
        h, w = src.shape[:2]
        u = (np.arange(w) + 0.5) / w
        v = 1.0 - (np.arange(h) + 0.5) / h
        d = equirectangular_to_direction(u[None, :], v[:, None])  # Blender world
        rot = m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0)
        local = d @ rot  # (rot^T d) as rows: world -> the emitter's frame
        mu = (np.arctan2(local[..., 0], -local[..., 2]) / (2 * np.pi)) % 1.0
        mv = np.arccos(np.clip(local[..., 1], -1.0, 1.0)) / np.pi
        col = np.minimum((mu * w).astype(np.int64), w - 1)
        row = np.minimum((mv * h).astype(np.int64), h - 1)
        return (src[row, col] * scale).astype(np.float32)

    # -- camera ---------------------------------------------------------------------------

    def _film_size(self, film):
        props = self._props(film) if film is not None else {}
        return int(props.get("width", 768)), int(props.get("height", 576))

    def _resolution(self, width, height):
        fw, fh = self.film_size
        if width is None and height is None:
            return fw, fh
        if height is None:
            return int(width), max(1, int(round(width * fh / fw)))
        if width is None:
            return max(1, int(round(height * fw / fh))), int(height)
        return int(width), int(height)

    def _camera(self, el):
        from parallax_core.scene import Camera

        kind = el.get("type")
        if kind not in ("perspective", "thinlens"):
            raise NotImplementedError(f"{self.path}: <sensor type='{kind}'>")
        if kind == "thinlens":
            self.notes.append("thinlens sensor rendered as a pinhole (no depth of field)")
        props = self._props(el)
        aspect = self.width / self.height
        if "fov" in props:
            fov, axis = float(props["fov"]), props.get("fovAxis", props.get("fov_axis", "x"))
        else:  # Mitsuba 0.6: focalLength in 35 mm equivalent, along the diagonal
            f = str(props.get("focalLength", "50mm")).strip().lower().rstrip("m")
            fov = math.degrees(2.0 * math.atan(math.hypot(36.0, 24.0) / (2.0 * float(f))))
            axis = "diagonal"
        if axis == "smaller":
            axis = "y" if aspect > 1 else "x"
        elif axis == "larger":
            axis = "x" if aspect > 1 else "y"
        t = math.tan(math.radians(fov) / 2.0)
        if axis == "x":
            hx, hy = t, t / aspect
        elif axis == "y":
            hx, hy = t * aspect, t
        elif axis == "diagonal":
            hx, hy = t * aspect / math.hypot(aspect, 1.0), t / math.hypot(aspect, 1.0)
        else:
            raise ValueError(f"{self.path}: fovAxis '{axis}'")
        m = self._world_matrix(props.get("toWorld", props.get("to_world")))[:3].copy()
        m[:, 0] *= -1.0  # Mitsuba's +X is the image's left, Parallax's its right
        m[:, 2] *= -1.0  # Mitsuba looks down +Z, Parallax down -Z
        lengths = np.linalg.norm(m[:, :3], axis=0)
        m[:, :3] /= lengths
        near = float(props.get("nearClip", props.get("near_clip", 1e-2)))
        far = float(props.get("farClip", props.get("far_clip", 1e4)))
        return Camera(m, "perspective", (-hx, hx, -hy, hy), near, far)


def load_mitsuba(path, width=None, height=None, z_up=True):
    """(SceneData, notes) of a Mitsuba 0.6 XML scene (see the module docstring)."""
    s = MitsubaScene(path, width, height, z_up)
    return s.scene, s.notes


def thesis_irradiance_cache(width=None, height=None):
    """The thesis' irradiance-cache scene (diffuse floor, rounded box, cylinder and box under a
    black sky, lit by one sphere light of radius 0.9 and radiance 1000) as SceneData, Z up.
    Resolution: the film's 1280 x 720 unless given (one of them given: the other keeps the
    aspect)."""
    return load_mitsuba(scene_path(IRRADIANCE_CACHE, "irradianceCache.xml"), width, height)[0]


def thesis_veach_mis(width=None, height=None):
    """The thesis' Veach MIS scene (four rough conductor plates, a red floor, four sphere lights
    of radius 0.033-0.9) as SceneData, Z up; resolution as in thesis_irradiance_cache."""
    return load_mitsuba(scene_path(VEACH_MIS, "veachMIS.xml"), width, height)[0]


# The thesis' scenes under the names bench.converge --suite thesis and
# blender_scenes/thesis_scenes.py give them: (shared folder, SceneData loader).
THESIS_SCENES = {"thesis_veach_mis": (VEACH_MIS, thesis_veach_mis),
                 "thesis_irradiance_cache": (IRRADIANCE_CACHE, thesis_irradiance_cache)}


# ---- comparison with the reference ----------------------------------------------------------

def read_rgb_exr(path):
    """(H, W, 3) float32 linear RGB of an EXR, row 0 at the top."""
    from parallax_core.exr import read_exr

    ch = read_exr(path)
    return np.stack([ch[c] for c in "RGB"], axis=-1).astype(np.float32)


def downscale(image, width, height):
    """Box-filtered (H, W, C) -> (height, width, C); the sizes must divide evenly."""
    h, w = image.shape[:2]
    if h % height or w % width or (h // height) != (w // width):
        raise ValueError(f"cannot box-downscale {w}x{h} to {width}x{height} "
                         "(needs one integer factor)")
    f = h // height
    return image.reshape(height, f, width, f, -1).mean(axis=(1, 3))


def reference(width, height, name=IRRADIANCE_CACHE, file="irradianceCache.exr"):
    return downscale(read_rgb_exr(scene_path(name, file)), width, height)


def block_average(image, block):
    h, w = (image.shape[0] // block) * block, (image.shape[1] // block) * block
    a = image[:h, :w]
    return a.reshape(h // block, block, w // block, block, -1).mean(axis=(1, 3))


def rel_mse(x, r, block=8):
    """(x - r)^2 / (r^2 + 1e-3), averaged, after block-averaging both (block x block)."""
    xb, rb = block_average(x, block), block_average(r, block)
    return float(np.mean((xb - rb) ** 2 / (rb ** 2 + 1e-3)))


def render(scene, spp=256, method="mis", max_depth=16, spp_per_frame=16, seed=0, device=None):
    """(H, W, 3) float32 Parallax render of ``scene``."""
    import parallax_core as pc

    s = pc.Session(scene.width, scene.height, device)
    k = max(1, min(spp, spp_per_frame))
    s.set_params(method=method, samples_per_frame=k, max_depth=max_depth, seed=seed)
    s.update(scene)
    s.render(max(1, spp // k))
    return s.read("combined")[..., :3].copy()


def main(argv=None):
    from parallax_core.exr import write_png

    p = argparse.ArgumentParser(description="Render the thesis' irradiance-cache scene with "
                                "Parallax and compare it with the thesis' reference EXR.")
    p.add_argument("--width", type=int, default=160, help="a divisor of 1280 (default 160)")
    p.add_argument("--spp", type=int, default=256)
    p.add_argument("--max-depth", type=int, default=16)
    p.add_argument("--method", default="mis")
    p.add_argument("--device", default=None)
    p.add_argument("--png", default="/tmp/thesis_irradiance_cache.png",
                   help="side-by-side PNG: Parallax | reference | |difference| x 4")
    args = p.parse_args(argv)
    if not available(IRRADIANCE_CACHE):
        print(f"{IRRADIANCE_CACHE} not found in {SHARED_SCENES} (set PARALLAX_SHARED_SCENES)")
        return 1
    loaded = MitsubaScene(scene_path(IRRADIANCE_CACHE, "irradianceCache.xml"), args.width)
    scene = loaded.scene
    tris = sum(len(m.indices) for m in scene.meshes)
    print(f"scene: {len(scene.meshes)} meshes, {tris} triangles, {len(scene.lights)} lights, "
          f"{scene.width}x{scene.height}")
    for light in scene.lights:
        print(f"  light {light.name}: {light.type} at {np.round(light.position, 3).tolist()}, "
              f"radius {light.radius:g}, power {light.power:.1f} W x {light.color}")
    for note in loaded.notes:
        print(f"  note: {note}")
    t0 = time.perf_counter()
    image = render(scene, args.spp, args.method, args.max_depth, device=args.device)
    seconds = time.perf_counter() - t0
    ref = reference(scene.width, scene.height)
    bad = int((~np.isfinite(image)).sum())
    print(f"parallax {args.method}, {args.spp} spp, max depth {args.max_depth}: {seconds:.1f} s, "
          f"{bad} non-finite values")
    m_x, m_r = image.reshape(-1, 3).mean(0), ref.reshape(-1, 3).mean(0)
    print("mean      R        G        B")
    print("parallax  " + "  ".join(f"{v:7.4f}" for v in m_x))
    print("reference " + "  ".join(f"{v:7.4f}" for v in m_r))
    print("ratio     " + "  ".join(f"{v:7.4f}" for v in m_x / np.maximum(m_r, 1e-12)))
    print(f"relMSE (8x8 blocks): {rel_mse(image, ref, 8):.5f}   "
          f"(per pixel: {rel_mse(image, ref, 1):.5f})")
    gap = np.ones((scene.height, 2, 3), np.float32)
    diff = np.abs(image - ref) * 4.0
    write_png(args.png, np.concatenate([image, gap, ref, gap, diff], axis=1))
    print(f"wrote {args.png} (Parallax | reference | |difference| x 4)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
