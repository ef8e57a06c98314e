"""Mitsuba 3 as a peer renderer: a Parallax ``SceneData`` as a Mitsuba scene, rendered.

    from bench.mitsuba_peer import mitsuba_available, scene_dict, render, render_for
    variant = mitsuba_available()            # 'cuda_ad_rgb' / 'llvm_ad_rgb', or None
    image = render(scene, spp=256, variant=variant)          # float32 (H, W, 3), row 0 = top
    image, spp, seconds = render_for(scene, 10.0, variant)   # equal-time comparisons

``scene`` is a ``parallax_core.scene.SceneData`` or the path of a ``.npz`` written by
``SceneData.save``. The conversion works on ``scene.flatten()``, the arrays the native core
consumes (degenerate triangles and zero-size lights already dropped), so Mitsuba sees what
Parallax renders, in Parallax's (Cycles') units:

- Camera: perspective -> ``perspective`` (fov_axis x, principal point offset for shifted
  windows); orthographic -> ``orthographic`` (scale and shift in ``to_world``). Film
  ``hdrfilm`` with a box filter (Parallax: box, one-pixel jitter). Exact. Parallax's
  camera looks down -Z with +X right; Mitsuba's down +Z with +X LEFT in the image (its
  ``look_at`` puts "left" in the first column), so ``to_world`` is ``camera_to_world`` with
  its X and Z columns negated. Windows whose pixels are not square are refused (Mitsuba's
  perspective camera has square pixels and allows no scale in ``to_world``).
- Meshes: one Mitsuba ``Mesh`` per (instance, material) group, unwelded (3 vertices per
  triangle: Parallax normals/UVs are per corner), the instance transform baked into the
  positions (normals by the inverse transpose, re-normalised). A mirroring transform
  (det < 0) reverses the winding, so the geometric normal is Parallax's (the inverse
  transpose of the object's), which is what decides a dielectric's inside. Corner normals
  are put on the geometric normal's side (Parallax flips the interpolated normal there).
  Meshes without normals are flat shaded in both. Exact.
- Materials (the Material docstring, shaders/lib/bsdf.glsl):
  diffuse -> ``twosided(diffuse)``: exact. conductor -> ``twosided(roughconductor)`` GGX,
  alpha = roughness^2, ``specular_reflectance`` = colour, no eta/k (Fresnel 1, as Cycles'
  Glossy); ``conductor`` when alpha < 1e-4 (Parallax's delta threshold). Mitsuba's Smith
  shadowing is separable where Parallax's is height-correlated: slightly darker at high
  roughness and grazing angles (see tests for the measured size). dielectric ->
  ``roughdielectric`` GGX / ``dielectric``, int_ior = ior, ext_ior = 1, reflectance and
  transmittance = colour; same G difference; Mitsuba scales radiance by 1/eta^2 on
  refraction where Parallax (like Cycles) does not: the factors cancel on any path that
  enters and leaves a closed object, so only paths ending inside glass (a light or the
  camera in the glass) differ. emission -> black ``twosided(diffuse)`` (Parallax ends the
  path there). Textures: uint8 sRGB, upsampled bilinearly up to 16x (Parallax interpolates
  sRGB values and then decodes, as Cycles does; Mitsuba decodes first), -> linear in numpy,
  times base_color (bilinear interpolation is linear, so this is Parallax's colour * lookup),
  a ``bitmap`` with raw=True, bilinear, repeat; UV v flipped (Mitsuba's texture space has
  v = 0 at the top row). Close: only the decode's curvature within 1/16 texel differs. Mix chains -> nested ``blendbsdf`` with
  weight = 1 - mix_weight (Mitsuba's weight is the probability of its SECOND bsdf). Exact.
- Emission (any material with emission > 0, the head material's): an ``area`` emitter on
  the group's mesh. Mitsuba's area emitters are one-sided, Parallax's mesh emission is
  two-sided, so a second copy of the mesh with reversed winding (and negated normals),
  moved back along each face's normal by a tiny distance (2e-5 x scene extent), carries
  another emitter and the SAME BSDF: a ray from the front reaches the front copy first and
  a ray from the back the back copy first, each seeing the emitting side and a two-sided
  BSDF that is the same from either side; a light sample on the copy facing away is
  occluded by the other copy and would be zero anyway. Mitsuba decides the emitting side
  by the shading normal, so emission-only meshes lose their normals (their black BSDF does
  not need them) and the side is the geometric one, as in Parallax. Exact except for the
  offset, for smooth-shaded emissive meshes with a non-black BSDF (near silhouettes, where
  the shading normal turns away), and for emissive glass (its transmission would meet the
  second copy).
- Lights (units as the core's scene.cpp): point (radius 0) -> ``point``, intensity
  P/(4 pi) colour: exact. Point with radius r -> a ``sphere`` with an ``area`` emitter of
  radiance P/(4 pi^2 r^2) colour and a black BSDF: exact for what sees it, but Parallax's
  analytic lights are not in the BVH, so they cast no shadows on other lights' shadow rays
  while Mitsuba's sphere does. Area rect/ellipse -> ``rectangle``/``disk`` (scaled,
  emitting along ``direction``), radiance P/(pi A) colour, black BSDF: same caveat, and
  Parallax's lights are invisible from behind where Mitsuba's shape is a black occluder.
  Spot -> ``spot``, intensity P/(4 pi) colour, cutoff = spot_size/2, beam width where
  Parallax's smoothstep (in cos) reaches 1; Mitsuba's falloff is linear in the ANGLE over
  that band, so only spot_blend = 0 is exact; a spot with radius > 0 becomes a point spot.
  Sun, angle 0 -> ``directional``, irradiance S colour: exact; angle > 0 -> the same
  directional light (same irradiance at normal incidence; no soft shadows, and the disc
  itself is not visible). ``camera_visible=False`` cannot be honoured (Mitsuba has no
  per-emitter camera visibility): such lights are still seen by camera rays.
- World: constant -> ``constant``: exact. Map -> ``envmap`` with to_world columns (+Y, +Z,
  +X), so Mitsuba's local frame (+Y up, u = 0 at -Z, u = 0.25 at +X) lands on Blender's
  (+Z up, u = 0 at -X, u = 0.25 at +Y). Parallax looks the map up by NEAREST texel (pixel
  centres at (col + 0.5)/W, (row + 0.5)/H); Mitsuba interpolates bilinearly on a grid whose
  rows run from the zenith to the nadir inclusive. The map is resampled onto a Mitsuba grid
  k times finer by nearest lookup (k = ENV_UPSAMPLE, less for maps too big for
  ENV_MAX_TEXELS), so both agree exactly except within 1/(2k) of a texel of a vertical texel
  edge and 1/k of a horizontal one, where Mitsuba blends the two neighbours linearly
  (symmetric about the edge, so the integral is kept).
- Integrator: ``path``, max_depth = Parallax max_depth + 2: Parallax counts bounces (0 =
  direct lighting only, as Cycles), Mitsuba counts path segments (1 = emitters seen
  directly, 2 = direct lighting); the tests show Parallax's 0 matching Mitsuba's 2 and not
  its 1. rr_depth 5, hide_emitters off. Parallax's depth_leeway must be 0 for this.
- Light selection: every emitter gets a ``sampling_weight`` like the core's (power-based)
  light CDF. That changes only the noise, not the expected image.

Mitsuba's llvm variants need a newer LLVM than Debian 12's default (drjit aborts with
libLLVM 15; 19 works): ``mitsuba_available`` points ``DRJIT_LIBLLVM_PATH`` at the newest
libLLVM >= 16 it finds (``apt-get install libllvm19``) before importing drjit.
"""
from __future__ import annotations

import glob
import math
import os
import re
import time

import numpy as np

__all__ = ["mitsuba_available", "scene_dict", "render", "render_for", "find_libllvm",
           "ENV_UPSAMPLE", "DELTA_ALPHA"]

DELTA_ALPHA = 1e-4     # Parallax's delta threshold (shaders/lib/bsdf.glsl)
ENV_UPSAMPLE = 32      # most Mitsuba envmap grid resolution / Parallax map resolution
ENV_MAX_TEXELS = 1 << 20  # ... within this many grid texels (12 MiB of float32 RGB)
EMITTER_BACK_OFFSET = 2e-5  # back copy of emissive meshes: this x scene extent behind
MAX_LANES = 1 << 22    # most samples (pixels x spp) one Mitsuba pass evaluates at once

_MIN_LLVM = 16         # drjit aborts with Debian's LLVM 15


# ---- availability -------------------------------------------------------------------------

def _llvm_version(path):
    """Major version from a name like libLLVM-19.so, libLLVM.so.19.1, libLLVM-14.0.6.so.1."""
    m = re.search(r"libLLVM(?:-|\.so\.)(\d+)", os.path.basename(path))
    return int(m.group(1)) if m else -1


def find_libllvm():
    """Path of a usable libLLVM shared library (version >= 16, the newest found), or None.
    Looks where Debian/Ubuntu (libllvmNN), Fedora and Homebrew put it."""
    patterns = ["/usr/lib/x86_64-linux-gnu/libLLVM*.so*", "/usr/lib/aarch64-linux-gnu/libLLVM*.so*",
                "/usr/lib/llvm-*/lib/libLLVM*.so*", "/usr/lib64/libLLVM*.so*", "/usr/lib/libLLVM*.so*",
                "/usr/local/lib/libLLVM*.so*", "/opt/homebrew/opt/llvm/lib/libLLVM.dylib",
                "/usr/local/opt/llvm/lib/libLLVM.dylib"]
    found = {os.path.realpath(p) for pat in patterns for p in glob.glob(pat) if os.path.isfile(p)}
    usable = [p for p in found if _llvm_version(p) >= _MIN_LLVM]
    if not usable:
        return None
    return max(usable, key=lambda p: (_llvm_version(p), p))


_AVAILABLE = {}


def mitsuba_available(variant=None):
    """The Mitsuba variant this machine can run ('cuda_ad_rgb' with a CUDA GPU, else
    'llvm_ad_rgb'), or ``variant`` if given and it loads; None if mitsuba is missing or no
    variant loads. Sets DRJIT_LIBLLVM_PATH (if unset) to a libLLVM >= 16 before importing."""
    key = variant or ""
    if key in _AVAILABLE:
        return _AVAILABLE[key]
    if not os.environ.get("DRJIT_LIBLLVM_PATH"):
        lib = find_libllvm()
        if lib:
            os.environ["DRJIT_LIBLLVM_PATH"] = lib
    result = None
    try:
        import drjit as dr
        import mitsuba as mi
    except Exception:  # ImportError, or drjit failing to initialise
        _AVAILABLE[key] = None
        return None
    candidates = [variant] if variant else []
    if not variant:
        if dr.has_backend(dr.JitBackend.CUDA):
            candidates.append("cuda_ad_rgb")
        if dr.has_backend(dr.JitBackend.LLVM):
            candidates.append("llvm_ad_rgb")
    for v in candidates:
        if v not in mi.variants():
            continue
        try:
            mi.set_variant(v)
            result = v
            break
        except Exception:
            continue
    _AVAILABLE[key] = result
    return result


def _mitsuba(variant=None):
    """The mitsuba module with ``variant`` (or the available one) set."""
    v = mitsuba_available(variant)
    if v is None:
        raise RuntimeError(f"Mitsuba variant {variant or '(any)'} is not available "
                           "(pip install mitsuba; apt-get install libllvm19 for llvm_ad_rgb)")
    import mitsuba as mi
    if mi.variant() != v:
        mi.set_variant(v)
    return mi


# ---- scene input --------------------------------------------------------------------------

def _as_scene(scene):
    from parallax_core.scene import SceneData
    if isinstance(scene, (str, os.PathLike)):
        return SceneData.load(os.fspath(scene))
    if isinstance(scene, SceneData):
        return scene
    raise TypeError(f"expected a SceneData or a .npz path, got {type(scene).__name__}")


def _resolution(scene):
    if not scene.width or not scene.height:
        raise ValueError("scene has no resolution (SceneData.width/height)")
    return int(scene.width), int(scene.height)


# ---- small helpers ------------------------------------------------------------------------

def _rgb(v):
    return {"type": "rgb", "value": [float(x) for x in np.asarray(v, np.float64).reshape(3)]}


def _luminance(c):
    c = np.asarray(c, np.float64)
    return float(0.2126 * c[..., 0] + 0.7152 * c[..., 1] + 0.0722 * c[..., 2])


def upsample_bilinear(image, factor):
    """(h, w, C) -> (h * factor, w * factor, C): the bilinear, repeat-wrapped lookup of
    `image` at the finer texels' centres. Parallax (as Cycles) interpolates 8-bit sRGB texels
    and decodes the result, Mitsuba decodes first; decoding this finer grid instead leaves only
    the decode's curvature within 1/factor of a texel."""
    for axis in (0, 1):
        n = image.shape[axis]
        x = (np.arange(n * factor) + 0.5) / factor - 0.5  # in texels, centres at integers
        i0 = np.floor(x).astype(int)
        t = (x - i0).reshape((-1, 1, 1) if axis == 0 else (1, -1, 1))
        image = (1 - t) * np.take(image, i0 % n, axis) + t * np.take(image, (i0 + 1) % n, axis)
    return image


def srgb_to_linear(c):
    """Parallax's sRGB decoding (shaders/lib/surface.glsl) of values in [0,1]."""
    c = np.asarray(c, np.float64)
    return np.where(c < 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _transform(mi, m):
    """mi.ScalarTransform4f from a (3,4) or (4,4) matrix."""
    m = np.asarray(m, np.float64)
    full = np.eye(4)
    full[:3] = m[:3]
    return mi.ScalarTransform4f(full.tolist())


def _perpendicular(d):
    d = np.asarray(d, np.float64)
    a = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(d, a)
    return u / np.linalg.norm(u)


# ---- camera -------------------------------------------------------------------------------

def _sensor(mi, flat, width, height, spp):
    m = flat["camera_to_world"].astype(np.float64)
    l, r, b, t = (float(x) for x in flat["camera_window"])
    near, far = (float(x) for x in flat["camera_clip"])
    ortho = int(flat["camera_type"][0]) == 1
    # Mitsuba camera space: +X left, +Y up, +Z forward. Parallax: +X right, +Y up, -Z fwd.
    to_world = m.copy()
    to_world[:, 0] *= -1.0
    to_world[:, 2] *= -1.0
    half_x, half_y = 0.5 * (r - l), 0.5 * (t - b)
    cx, cy = 0.5 * (r + l), 0.5 * (t + b)
    film = {"type": "hdrfilm", "width": width, "height": height, "pixel_format": "rgb",
            "component_format": "float32", "rfilter": {"type": "box"}, "sample_border": False}
    sampler = {"type": "independent", "sample_count": int(spp)}
    if ortho:
        # Mitsuba's orthographic camera sees x in [-1, 1], y in [-1/aspect, 1/aspect] of
        # its local space (aspect = width/height); scale and shift that onto the window.
        aspect = width / height
        s = to_world.copy()
        s[:, 3] = m[:, :3] @ np.array([cx, cy, 0.0]) + m[:, 3]
        s[:, 0] *= half_x
        s[:, 1] *= half_y * aspect
        # Clip distances along the view axis, unscaled.
        return {"type": "orthographic", "to_world": _transform(mi, s), "near_clip": near,
                "far_clip": far, "film": film, "sampler": sampler}
    pixel_aspect = (half_x / width) / (half_y / height)
    if abs(pixel_aspect - 1.0) > 1e-4:
        raise ValueError(f"camera window {l, r, b, t} at {width}x{height} has non-square pixels "
                         f"(aspect {pixel_aspect:.5f}); Mitsuba's perspective camera cannot")
    fov = 2.0 * math.degrees(math.atan(half_x))
    # Principal point offset: the window centre in units of the film's extent (x right,
    # y down in Mitsuba's sample space: a window shifted up moves the centre down).
    return {"type": "perspective", "to_world": _transform(mi, to_world), "fov": fov,
            "fov_axis": "x", "near_clip": near, "far_clip": far,
            "principal_point_offset_x": cx / (2.0 * half_x),
            "principal_point_offset_y": -cy / (2.0 * half_y),
            "film": film, "sampler": sampler}


# ---- materials ----------------------------------------------------------------------------

class _Materials:
    def __init__(self, mi, flat):
        self.mi = mi
        self.f = flat
        self.textures = {}   # (texture, colour) -> bitmap texture dict
        self.bsdfs = {}      # material -> loaded BSDF object

    def _colour(self, k):
        """Reflectance value or texture of material k: colour x texture."""
        f = self.f
        colour = f["material_base_color"][k].astype(np.float64)
        x = int(f["material_texture"][k])
        if x < 0:
            return _rgb(colour)
        key = (x, tuple(colour.tolist()))
        if key not in self.textures:
            off, w, h = (int(v) for v in f["texture_info"][x])
            flags = int(f["texture_flags"][x]) if "texture_flags" in f else 0
            closest = bool(flags & 1)  # TEXTURE_FLAG_CLOSEST
            if flags & 2:  # TEXTURE_FLAG_HALF: linear floats, interpolated as they are
                px = f["texture_half_texels"].view(np.float16)[off:off + w * h, :3].reshape(h, w, 3)
                lin = (px.astype(np.float64) * colour).astype(np.float32)
            else:
                px = f["texture_texels"][off:off + w * h, :3].reshape(h, w, 3) / 255.0
                fine = px if closest else upsample_bilinear(px, max(1, min(16, 2048 // max(w, h))))
                lin = (srgb_to_linear(fine) * colour).astype(np.float32)
            self.textures[key] = {"type": "bitmap", "bitmap": self.mi.Bitmap(np.ascontiguousarray(lin)),
                                  "raw": True, "filter_type": "nearest" if closest else "bilinear",
                                  "wrap_mode": "repeat"}
        return self.textures[key]

    def _single(self, k):
        f = self.f
        t = int(f["material_type"][k])
        alpha = float(f["material_roughness"][k]) ** 2
        if t == 0:  # diffuse
            return {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": self._colour(k)}}
        if t == 1:  # conductor: Fresnel 1 (no eta/k), reflectance = colour
            c = self._colour(k)
            if alpha < DELTA_ALPHA:
                inner = {"type": "conductor", "specular_reflectance": c}
            else:
                inner = {"type": "roughconductor", "distribution": "ggx", "alpha": alpha,
                         "specular_reflectance": c}
            return {"type": "twosided", "bsdf": inner}
        if t == 2:  # dielectric
            ior = float(f["material_ior"][k])
            d = {"type": "dielectric" if alpha < DELTA_ALPHA else "roughdielectric",
                 "int_ior": ior, "ext_ior": 1.0,
                 "specular_reflectance": self._colour(k), "specular_transmittance": self._colour(k)}
            if alpha >= DELTA_ALPHA:
                d.update(distribution="ggx", alpha=alpha)
            return d
        # emission: absorbs (Parallax ends the path)
        return {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": _rgb((0, 0, 0))}}

    def bsdf_dict(self, k):
        """Material k with its mix chain: f = w f_k + (1 - w) f_chain(next)."""
        nxt = int(self.f["material_mix_next"][k])
        d = self._single(k)
        if nxt < 0:
            return d
        w = float(self.f["material_mix_weight"][k])
        return {"type": "blendbsdf", "weight": 1.0 - w, "bsdf_0": d, "bsdf_1": self.bsdf_dict(nxt)}

    def bsdf(self, k):
        if k not in self.bsdfs:
            self.bsdfs[k] = self.mi.load_dict(self.bsdf_dict(k))
        return self.bsdfs[k]

    def black(self, k):
        """Whether material k's whole chain is "emission" (absorbs everything)."""
        while k >= 0:
            if int(self.f["material_type"][k]) != 3:
                return False
            k = int(self.f["material_mix_next"][k])
        return True


# ---- meshes -------------------------------------------------------------------------------

def _mi_mesh(mi, name, p, n, uv, bsdf, emitter=None):
    """A Mitsuba mesh from unwelded corners: p (T,3,3), n (T,3,3) or None, uv (T,3,2)."""
    T = len(p)
    props = mi.Properties()
    props["bsdf"] = bsdf
    if emitter is not None:
        props["emitter"] = emitter
    mesh = mi.Mesh(name, 3 * T, T, props=props, has_vertex_normals=n is not None,
                   has_vertex_texcoords=True)
    params = mi.traverse(mesh)
    params["vertex_positions"] = np.ascontiguousarray(p, np.float32).ravel()
    params["faces"] = np.arange(3 * T, dtype=np.uint32)
    if n is not None:
        params["vertex_normals"] = np.ascontiguousarray(n, np.float32).ravel()
    params["vertex_texcoords"] = np.ascontiguousarray(uv, np.float32).ravel()
    params.update()
    return mesh


def _shapes(mi, flat, mats, extent, weights):
    """Mitsuba meshes of every (instance, material) group; emissive groups twice."""
    shapes = {}
    pos = flat["positions"].astype(np.float64)
    idx = flat["indices"].astype(np.int64)
    tmat = flat["triangle_material"].astype(np.int64)
    offset = EMITTER_BACK_OFFSET * extent
    for i, (mesh, xf) in enumerate(zip(flat["instance_mesh"], flat["instance_transform"])):
        t0 = int(flat["mesh_first_triangle"][mesh])
        t1 = t0 + int(flat["mesh_triangle_count"][mesh])
        if t1 == t0:
            continue
        A, c = xf[:, :3].astype(np.float64), xf[:, 3].astype(np.float64)
        p = pos[idx[t0:t1]] @ A.T + c                     # (T,3,3) world corners
        n = None
        if flat["mesh_has_normals"][mesh]:
            N = np.linalg.inv(A).T if abs(np.linalg.det(A)) > 1e-30 else A
            n = flat["corner_normals"][t0:t1].astype(np.float64) @ N.T
        if flat["mesh_has_uvs"][mesh]:
            uv = flat["corner_uvs"][t0:t1].astype(np.float64).copy()
        else:
            uv = np.zeros((t1 - t0, 3, 2))                # Parallax: uv = (0, 0)
        uv[..., 1] = 1.0 - uv[..., 1]                      # Mitsuba: v = 0 is the top row
        if np.linalg.det(A) < 0:                           # keep Parallax's geometric normal
            order = [0, 2, 1]
            p, uv = p[:, order], uv[:, order]
            n = None if n is None else n[:, order]
        face = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        area2 = np.linalg.norm(face, axis=1)
        keep = area2 > 0
        face = face / np.where(area2 > 0, area2, 1.0)[:, None]
        if n is not None:
            ln = np.linalg.norm(n, axis=2, keepdims=True)
            n = np.where(ln > 1e-12, n / np.where(ln > 1e-12, ln, 1.0), face[:, None, :])
            n = np.where(np.sum(n * face[:, None, :], axis=2, keepdims=True) < 0, -n, n)
        mats_here = tmat[t0:t1]
        for k in np.unique(mats_here):
            sel = keep & (mats_here == k)
            if not sel.any():
                continue
            k = int(k)
            gp, gn, guv = p[sel], None if n is None else n[sel], uv[sel]
            bsdf = mats.bsdf(k)
            emission = flat["material_emission"][k].astype(np.float64)
            name = f"inst{i}_mat{k}"
            if emission.max() <= 0:
                shapes[name] = _mi_mesh(mi, name, gp, gn, guv, bsdf)
                continue
            if mats.black(k):
                # Mitsuba's area emitter tests the side against the SHADING normal: without
                # normals it is the geometric one, as in Parallax (which ignores normals for
                # emission); a black BSDF does not care.
                gn = None
            area = 0.5 * float(area2[sel].sum())
            w = _luminance(emission) * area * math.pi   # each side's emitted power
            front = mi.load_dict({"type": "area", "radiance": _rgb(emission), "sampling_weight": w})
            back = mi.load_dict({"type": "area", "radiance": _rgb(emission), "sampling_weight": w})
            weights.append(w)
            # Back side: reversed winding, negated normals, moved behind the front copy.
            order = [0, 2, 1]
            bp = gp[:, order] - offset * face[sel][:, None, :]
            bn = None if gn is None else -gn[:, order]
            shapes[name] = _mi_mesh(mi, name, gp, gn, guv, bsdf, front)
            shapes[name + "_back"] = _mi_mesh(mi, name + "_back", bp, bn, guv[:, order], bsdf, back)
    return shapes


# ---- lights -------------------------------------------------------------------------------

def _lights(mi, flat, extent):
    out = {}
    black = {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": _rgb((0, 0, 0))}}
    for j, t in enumerate(flat["light_type"].astype(int)):
        pos = flat["light_position"][j].astype(np.float64)
        d = flat["light_direction"][j].astype(np.float64)
        d /= np.linalg.norm(d)
        col = flat["light_color"][j].astype(np.float64)   # colour x power
        radius = float(flat["light_radius"][j])
        name = f"light{j}"
        if col.max() <= 0:
            continue
        if t == 1 and radius > 0:  # sphere light
            L = col / (4.0 * math.pi * math.pi * radius * radius)
            out[name] = {"type": "sphere", "center": pos.tolist(), "radius": radius, "bsdf": black,
                         "emitter": {"type": "area", "radiance": _rgb(L),
                                     "sampling_weight": _luminance(col)}}
        elif t == 1:  # point
            out[name] = {"type": "point", "position": pos.tolist(),
                         "intensity": _rgb(col / (4.0 * math.pi)), "sampling_weight": _luminance(col)}
        elif t == 2:  # spot (a radius becomes a point spot)
            half = 0.5 * min(max(float(flat["light_spot_size"][j]), 0.0), math.pi)
            blend = min(max(float(flat["light_spot_blend"][j]), 0.0), 1.0)
            cos_half = math.cos(half)
            beam = math.acos(min(1.0, cos_half + (1.0 - cos_half) * blend))
            beam = min(beam, half * (1.0 - 1e-6))
            xf = mi.ScalarTransform4f().look_at(origin=pos.tolist(), target=(pos + d).tolist(),
                                                up=_perpendicular(d).tolist())
            out[name] = {"type": "spot", "to_world": xf, "intensity": _rgb(col / (4.0 * math.pi)),
                         "cutoff_angle": math.degrees(half), "beam_width": math.degrees(beam),
                         "sampling_weight": _luminance(col) * max(0.05, 0.5 * (1 - cos_half))}
        elif t == 3:  # sun -> directional (exact for angle 0)
            out[name] = {"type": "directional", "direction": d.tolist(), "irradiance": _rgb(col),
                         "sampling_weight": _luminance(col) * math.pi * extent * extent}
        elif t in (4, 5):  # rectangle / ellipse, emitting along d
            u = flat["light_axis_u"][j].astype(np.float64)
            v = flat["light_axis_v"][j].astype(np.float64)
            full = float(np.linalg.norm(np.cross(u, v)))
            area = full if t == 4 else full * math.pi * 0.25
            if area <= 0:
                continue
            L = col / (math.pi * area)
            # Local [-1,1]^2 (disk: radius 1) in XY, normal +Z -> (-u/2, v/2, d): right-handed
            # since u x v = -d, so Mitsuba's normal is d either way.
            m = np.column_stack([-0.5 * u, 0.5 * v, d, pos])
            if np.dot(np.cross(m[:, 0], m[:, 1]), d) < 0:
                m[:, 0] *= -1.0
            out[name] = {"type": "rectangle" if t == 4 else "disk", "to_world": _transform(mi, m),
                         "bsdf": black, "emitter": {"type": "area", "radiance": _rgb(L),
                                                    "sampling_weight": _luminance(L) * math.pi * area}}
    return out


def _env_grid(env, upsample=None):
    """The Parallax map (H,W,3), nearest-texel lookups, on Mitsuba's envmap grid: Wm columns
    at u = (j + 0.5)/Wm, Hm rows at theta = pi i/(Hm - 1)."""
    H, W = env.shape[:2]
    k = upsample or max(1, min(ENV_UPSAMPLE, int(math.sqrt(ENV_MAX_TEXELS / (W * H)))))
    Wm, Hm = k * W, k * H + 1
    u = (np.arange(Wm) + 0.5) / Wm
    theta = np.pi * np.arange(Hm) / (Hm - 1)
    col = np.minimum((u * W).astype(np.int64), W - 1)
    # Parallax: row = floor((1 - v) H) with v = 1 - theta/pi, clamped. Grid rows k*r fall
    # exactly on the boundary between Parallax rows r-1 and r: give them the average, so
    # the blend zone is symmetric about the boundary (preserves the integral to first order).
    row = np.minimum((theta / np.pi * H).astype(np.int64), H - 1)
    grid = env[row][:, col, :3].astype(np.float64)
    r = np.arange(1, H)
    grid[k * r] = 0.5 * (env[r - 1][:, col, :3] + env[r][:, col, :3])
    return np.ascontiguousarray(grid, dtype=np.float32)


def _world(mi, flat, extent):
    env = flat["world_map"]
    if env.size:
        grid = _env_grid(env.astype(np.float32))
        # Columns: Mitsuba local X -> world +Y, local Y (up) -> +Z, local Z -> +X.
        rot = np.array([[0.0, 0.0, 1.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]])
        lum = float(np.mean(0.2126 * env[..., 0] + 0.7152 * env[..., 1] + 0.0722 * env[..., 2]))
        return {"type": "envmap", "bitmap": mi.Bitmap(grid), "to_world": _transform(mi, rot),
                "sampling_weight": max(lum, 1e-12) * 4 * math.pi * math.pi * extent * extent}
    colour = flat["world_color"].astype(np.float64)
    if colour.max() <= 0:
        return None
    return {"type": "constant", "radiance": _rgb(colour),
            "sampling_weight": _luminance(colour) * 4 * math.pi * math.pi * extent * extent}


# ---- the scene ----------------------------------------------------------------------------

def _extent(flat):
    """Largest coordinate magnitude of the instanced geometry, lights and camera (>= 1)."""
    vals = [1.0, float(np.abs(flat["camera_to_world"][:, 3]).max())]
    pos = flat["positions"].astype(np.float64)
    for mesh, xf in zip(flat["instance_mesh"], flat["instance_transform"]):
        t0 = int(flat["mesh_first_triangle"][mesh])
        t1 = t0 + int(flat["mesh_triangle_count"][mesh])
        if t1 > t0:
            p = pos[np.unique(flat["indices"][t0:t1])] @ xf[:, :3].T.astype(np.float64) + xf[:, 3]
            vals.append(float(np.abs(p).max()))
    if len(flat["light_position"]):
        vals.append(float(np.abs(flat["light_position"]).max()))
    return max(vals)


def scene_dict(scene, max_depth=8, spp=16, variant=None):
    """The ``mi.load_dict`` input for ``scene`` (SceneData or .npz path). Parallax's
    ``max_depth`` (bounces, depth_leeway 0) becomes Mitsuba's max_depth + 2. Needs the
    Mitsuba variant set (``variant`` or the available one): meshes are Mitsuba objects."""
    mi = _mitsuba(variant)
    scene = _as_scene(scene)
    width, height = _resolution(scene)
    flat = scene.flatten()
    extent = _extent(flat)
    mats = _Materials(mi, flat)
    d = {"type": "scene",
         "integrator": {"type": "path", "max_depth": int(max_depth) + 2, "rr_depth": 5,
                        "hide_emitters": False},
         "sensor": _sensor(mi, flat, width, height, spp)}
    d.update(_shapes(mi, flat, mats, extent, []))
    d.update(_lights(mi, flat, extent))
    world = _world(mi, flat, extent)
    if world is not None:
        d["world"] = world
    return d


def _to_numpy(img):
    return np.array(img, dtype=np.float32)[..., :3]


def _passes(width, height, spp):
    """spp split into passes of at most MAX_LANES samples."""
    per = max(1, MAX_LANES // max(1, width * height))
    out = []
    while spp > 0:
        out.append(min(per, spp))
        spp -= out[-1]
    return out


def render(scene, spp, variant=None, seed=0, max_depth=8):
    """Render ``scene`` with Mitsuba at ``spp`` samples per pixel: float32 (H, W, 3),
    linear, row 0 at the top."""
    mi = _mitsuba(variant)
    scene = _as_scene(scene)
    width, height = _resolution(scene)
    ms = mi.load_dict(scene_dict(scene, max_depth, spp=1, variant=variant))
    acc, total = None, 0
    for k, n in enumerate(_passes(width, height, int(spp))):
        img = _to_numpy(mi.render(ms, spp=n, seed=int(seed) * 1000003 + k))
        acc = img * n if acc is None else acc + img * n
        total += n
    return (acc / total).astype(np.float32)


def render_for(scene, seconds, variant=None, max_depth=8, progress=None):
    """Progressive render for about ``seconds`` of wall time (scene conversion and load
    included): passes of N spp with different seeds, averaged by sample count. The first
    pass is small (it includes JIT compilation); later passes are sized to take about a
    tenth of the budget each, and the last one is shrunk to fit. At least one pass runs.
    ``progress(mean_image, spp_so_far, elapsed)`` is called after each pass.
    Returns (image, spp, seconds used)."""
    start = time.perf_counter()
    mi = _mitsuba(variant)
    scene = _as_scene(scene)
    width, height = _resolution(scene)
    ms = mi.load_dict(scene_dict(scene, max_depth, spp=1, variant=variant))
    cap = max(1, MAX_LANES // (width * height))
    acc, total, seed, n = None, 0, 0, 1
    while True:
        t = time.perf_counter()
        img = _to_numpy(mi.render(ms, spp=n, seed=seed))
        per_spp = (time.perf_counter() - t) / n  # the first pass's includes JIT compilation
        acc = img * n if acc is None else acc + img * n
        total += n
        seed += 1
        elapsed = time.perf_counter() - start
        if progress is not None:
            progress(acc / total, total, elapsed)
        left = seconds - elapsed
        n = int(min(cap, max(1.0, 0.1 * seconds / per_spp), left / per_spp))
        if n < 1:
            break
    return (acc / total).astype(np.float32), total, time.perf_counter() - start
