"""A corpus of malformed scenes, files, settings and command lines (issue 16), each with the
one outcome it must have: a clean error naming the item, or a finite render with a warning.

tests/unit/test_bad_input.py runs every case in-process. Run as a script, this file runs each
case in a process of its own and counts the outcomes, crashes and hangs included:

    python tests/bad_input_cases.py [--timeout 600] [NAME ...]
"""
from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import os
import re
import subprocess
import sys
import tempfile
import threading
import time
from typing import Callable

import numpy as np

import parallax_core as pc
from parallax_core import cli, scenes
from parallax_core.scene import Light, Material, Mesh, SceneData, Texture

W = H = 8  # every render is tiny: 8x8 pixels, 2 frames of 1 sample


@dataclasses.dataclass
class Case:
    name: str
    kind: str          # scene (SceneData), flat (dict for update), npz (a file to load), cli (argv),
                       # session (Session arguments), params (set_params keywords), cancel (heavy render)
    build: Callable    # (tmp dir) -> the input
    expect: str        # "error", "warn" or "cancelled"
    match: str         # regex the error message (or one warning) must match


def cornell():
    return scenes.cornell_box(W, H)


def flat(edit=None):
    """Cornell box arrays with ``edit`` applied."""
    arrays = cornell().flatten()
    if edit is not None:
        edit(arrays)
    return arrays


def with_scene(edit):
    """A Cornell box SceneData with ``edit`` applied."""
    def build(_tmp):
        sc = cornell()
        sc.instances = sc.effective_instances()
        edit(sc)
        return sc
    return build


def npz(edit=None, meta=None, raw=None):
    """A Cornell box .npz with ``edit`` applied to its arrays and ``meta`` to its metadata;
    ``raw`` (bytes) writes those bytes instead."""
    def build(tmp):
        path = os.path.join(tmp, "scene.npz")
        if raw is not None:
            with open(path, "wb") as f:
                f.write(raw)
            return path
        sc = cornell()
        arrays, m = sc.flatten(), sc.metadata()
        if edit is not None:
            edit(arrays)
        if meta is not None:
            meta(m)
        np.savez(path, **arrays, __meta__=np.array(json.dumps(m)))
        return path
    return build


def set_(key, index, value):
    def edit(a):
        a[key][index] = value
    return edit


def replace(key, value):
    def edit(a):
        a[key] = value
    return edit


def setattr_(obj_path, value):
    """SceneData edit: ``obj_path`` like "materials.0.base_color"."""
    def edit(sc):
        *path, attr = obj_path.split(".")
        obj = sc
        for p in path:
            obj = obj[int(p)] if p.isdigit() else getattr(obj, p)
        setattr(obj, attr, value)
    return edit


def scaled(factor, offset=(0.0, 0.0, 0.0)):
    """SceneData edit: instance 0 (the floor) scaled by ``factor`` (3 values) and moved."""
    def edit(sc):
        t = np.eye(4)
        t[:3, :3] = np.diag(np.broadcast_to(np.asarray(factor, float), (3,)))
        t[:3, 3] = offset
        sc.instances[0].transform = t
    return edit


def far_floor(offset):
    """A 2 m floor under a camera, both ``offset`` metres from the origin."""
    def build(_tmp):
        o = np.array([offset, offset, 0.0])
        floor = scenes.quad([o + (-1, -1, 0), o + (1, -1, 0), o + (1, 1, 0), o + (-1, 1, 0)], 0, "floor")
        cam = pc.scene.Camera.look_at(o + (0, -2, 1), o, width=W, height=H)
        return SceneData([floor], [], [Material()], [], [], pc.scene.World((1, 1, 1), 1.0), cam, W, H)
    return build


def cli_render(build_file, *extra):
    """``parallax render FILE -o OUT.exr --spp 1 ...`` for the file ``build_file`` writes."""
    def build(tmp):
        return ["render", build_file(tmp), "-o", os.path.join(tmp, "out.exr"), "--spp", "1", *extra]
    return build


def _texture_past_texels(a):
    a["texture_info"] = np.array([[0, 100, 100]], np.uint32)
    a["texture_texels"] = np.zeros((16, 4), np.uint8)
    a["texture_flags"] = np.zeros(1, np.uint32)


def _degenerate_camera(scale):
    def edit(a):
        a["camera_to_world"][:, :3] *= scale
    return edit


def _light(**kw):
    return with_scene(lambda sc: sc.lights.append(Light(**kw)))


def _add_light(**kw):
    """Flat-array edit: one analytic light with the given flat fields (light_* without the
    prefix) appended; the others are a valid point light's."""
    row = {"type": 1, "position": (0, 0, 1), "direction": (0, 0, -1), "axis_u": (1, 0, 0),
           "axis_v": (0, 1, 0), "radius": 0.1, "color": (10, 10, 10), "spot_size": 1.0,
           "spot_blend": 0.1, "sun_angle": 0.0, "camera_visible": 1, "soft_falloff": 0}
    row.update(kw)

    def edit(a):
        for k, v in row.items():
            key = "light_" + k
            a[key] = np.concatenate([a[key], np.array([v], dtype=a[key].dtype).reshape((1,) + a[key].shape[1:])])
    return edit


def _append_light(**kw):
    return lambda _tmp: flat(_add_light(**kw))


def _heavy(_tmp):
    """The issue's hang: ~2e9 rays in one render(1) call (albedo 1, no roulette)."""
    return scenes.closed_emitter_box(1.0, 1.0, W, H)


HEAVY_PARAMS = dict(samples_per_frame=4096, max_depth=1024, depth_leeway=1024, rr_start_depth=0)


E, Wn = "error", "warn"
CASES = [
    # -- silent non-finite outputs (issue: Normal NaN, film Inf, Albedo Inf) --
    Case("instance-scaled-8e12", "scene", with_scene(scaled(8e12)), Wn, r"reaches 8e\+12 m from the origin"),
    Case("instance-anisotropic-1e20", "scene", with_scene(scaled((1e20, 1, 1e20))), E,
         r"instance_transform\[\d+\] places mesh 0 .* beyond the coordinate limit"),
    Case("world-map-3e38", "scene", with_scene(setattr_("world.map", np.full((4, 8, 3), 3e38, np.float32))), Wn,
         r"world_map: 32 texel\(s\) above the radiance limit .* clamped"),
    Case("base-color-3e38", "scene", with_scene(setattr_("materials.0.base_color", (3e38, 0.5, 0.5))), E,
         r"material 0: base_color 3e\+38 exceeds the limit"),
    # -- silently wrong renders --
    Case("area-light-1.8e19", "scene", _light(type="area", power=100.0, position=(0, 0, -50), size=1.8e19), E,
         r"light 0: position or size beyond the coordinate limit"),
    Case("area-light-flat-1e19", "flat", _append_light(type=4, axis_u=(1e19, 0, 0), axis_v=(0, 1e19, 0)), E,
         r"light 0: position or size beyond the coordinate limit"),
    Case("camera-all-zero", "flat", lambda _t: flat(replace("camera_to_world", np.zeros((3, 4), np.float32))), E,
         r"camera_to_world: an axis has length 0"),
    Case("camera-rotation-1e-25", "flat", lambda _t: flat(_degenerate_camera(1e-25)), E,
         r"camera_to_world: an axis has length 1e-25"),
    Case("camera-parallel-axes", "flat",
         lambda _t: flat(set_("camera_to_world", (slice(None), 1), flat()["camera_to_world"][:, 0])), E,
         r"camera_to_world is singular"),
    Case("camera-window-1e30", "flat",
         lambda _t: flat(replace("camera_window", np.array([-1e30, 1e30, -1e30, 1e30], np.float32))), E,
         r"camera_window \(-1e\+30, .*\) must be finite and within"),
    Case("camera-window-nan", "flat", lambda _t: flat(set_("camera_window", 0, np.nan)), E, r"camera_window"),
    Case("camera-clip-nan", "flat", lambda _t: flat(replace("camera_clip", np.array([np.nan, np.nan], np.float32))), E,
         r"camera_clip \(nan, nan\) must be finite"),
    Case("camera-clip-negative", "flat", lambda _t: flat(set_("camera_clip", 0, -1.0)), E,
         r"camera_clip \(-1, .*\) must be finite with 0 <= start < end"),
    Case("camera-clip-reversed", "flat", lambda _t: flat(replace("camera_clip", np.array([5, 1], np.float32))), E,
         r"camera_clip \(5, 1\)"),
    Case("camera-clip-scene-reversed", "scene", with_scene(setattr_("camera.clip_end", 0.01)), E,
         r"camera: bad clip range"),
    Case("camera-position-1e20", "flat", lambda _t: flat(set_("camera_to_world", (0, 3), 1e20)), E,
         r"camera position is beyond the coordinate limit"),
    # -- node programs (issue 37; every check: tests/render/test_node_programs.py) --
    Case("node-program-offset-past-end", "flat", lambda _t: flat(set_("material_node_program", 0, 5)), E,
         r"material 0: node program at word 5 runs past the end"),
    Case("node-program-unknown-op", "flat",
         lambda _t: flat(lambda a: (replace("material_node_programs", np.array([77, 0, 0], np.uint32))(a),
                                    set_("material_node_program", 0, 0)(a))), E, r"unknown operation 77"),
    # -- the thin lens and panoramas (issue 37) --
    Case("camera-aperture-nan", "flat", lambda _t: flat(set_("camera_aperture", 0, np.nan)), E,
         r"camera_aperture holds NaN"),
    Case("camera-aperture-negative", "flat", lambda _t: flat(set_("camera_aperture", 0, -0.1)), E,
         r"camera aperture radius -0.1 must be in 0\.\."),
    Case("camera-aperture-ratio-0", "flat", lambda _t: flat(set_("camera_aperture", 4, 0.0)), E,
         r"camera aperture ratio 0 must be in 0.001\.\.1000"),
    Case("camera-aperture-scene-negative", "scene", with_scene(setattr_("camera.aperture_radius", -1.0)), E,
         r"camera: aperture_radius, focus_distance and aperture_blades must be finite and not negative"),
    Case("camera-panorama-type-99", "flat", lambda _t: flat(set_("camera_panorama_type", 0, 99)), E,
         r"camera_panorama_type"),
    Case("camera-panorama-scene-unknown", "scene", with_scene(setattr_("camera.panorama_type", "STEREOGRAPHIC")), E,
         r"camera: unknown panorama_type 'STEREOGRAPHIC'"),
    Case("camera-fisheye-lens-0", "flat", lambda _t: flat(set_("camera_fisheye", 1, 0.0)), E,
         r"camera_fisheye: field of view, lens and sensor size must be positive"),
    Case("camera-fisheye-inf", "flat", lambda _t: flat(set_("camera_fisheye", 5, np.inf)), E,
         r"camera_fisheye holds NaN or infinity"),
    Case("base-color-1e30", "scene", with_scene(setattr_("materials.0.base_color", (1e30, 1e30, 1e30))), E,
         r"material 0: base_color 1e\+30 exceeds the limit of 1000"),
    Case("base-color-flat-1e4", "flat", lambda _t: flat(set_("material_base_color", (1, 1), 1e4)), E,
         r"material 1: base_color 10000 exceeds the limit"),
    Case("ior-zero-scene", "scene", with_scene(setattr_("materials.0.ior", 0.0)), E,
         r"material 'white' \(material 0\): ior must be positive"),
    Case("ior-negative-scene", "scene", with_scene(setattr_("materials.2.ior", -1.5)), E,
         r"material 'green' \(material 2\): ior must be positive"),
    Case("ior-zero-flat", "flat", lambda _t: flat(set_("material_ior", 0, 0.0)), E, r"material 0: ior must be positive"),
    Case("ior-huge-flat", "flat", lambda _t: flat(set_("material_ior", 1, 1e6)), E,
         r"material 1: ior must be positive, in 0\.001\.\.1000 \(got 1e\+06\)"),
    # -- lights: derived values, the light table --
    Case("light-power-x-color-overflow", "scene", _light(color=(10, 10, 10), power=1e38), E,
         r"light 0: color x power = 1e\+39 does not fit in float32"),
    Case("light-radiance-over-limit", "flat", _append_light(color=(1e30, 1e30, 1e30), radius=1e-6), E,
         r"light 0: emitted radiance .* exceeds the limit of 1e\+20"),
    Case("light-tiny-area", "flat", _append_light(type=4, color=(100, 100, 100), axis_u=(1e-20, 0, 0),
                                                  axis_v=(0, 1e-20, 0)), E, r"light 0: emitted radiance"),
    Case("light-black", "scene", _light(power=0.0), Wn, r"light 0 emits no light .*skipped"),
    Case("light-zero-size-flat", "flat", _append_light(type=4, axis_u=(0, 0, 0), axis_v=(0, 0, 0)), Wn,
         r"light 0 emits no light \(black or zero size\)"),
    Case("light-zero-size-scene", "scene", _light(type="area", size=0.0), Wn, r"zero-size area light skipped"),
    Case("light-nan-flat", "flat", _append_light(spot_size=np.nan, type=2), E, r"light 0: NaN or infinite value"),
    Case("light-zero-direction", "flat", _append_light(direction=(0, 0, 0)), E, r"light 0: zero direction"),
    Case("light-unknown-type-flat", "flat", _append_light(type=9), E, r"light 0: unknown type 9"),
    Case("light-unknown-type-scene", "scene", _light(type="laser"), E, r"light 0: unknown type 'laser'"),
    Case("light-unknown-shape", "scene", _light(type="area", shape="star"), E, r"unknown area shape 'star'"),
    Case("light-position-1e19", "flat", _append_light(position=(1e19, 0, 0)), E, r"light 0: position or size beyond"),
    Case("light-far-precision", "scene", _light(position=(0, 0, 1e8), power=1e3), Wn, r"reaches 1e\+08 m"),
    Case("light-camera-visible-length", "flat",
         lambda _t: flat(replace("light_camera_visible", np.ones(3, np.uint32))), E,
         r"light_camera_visible and light_type differ in length"),
    # -- materials, textures, world --
    Case("emission-1e30-flat", "flat", lambda _t: flat(set_("material_emission", (3, 0), 1e30)), E,
         r"material 3: emission 1e\+30 exceeds the radiance limit"),
    Case("emission-strength-overflow", "scene", with_scene(setattr_("materials.3.emission_strength", 1e38)), E,
         r"material 'light' \(material 3\): emission x emission_strength = 1\.7e\+39 does not fit"),
    Case("base-color-string", "scene", with_scene(setattr_("materials.0.base_color", "red")), E,
         r"material 'white' \(material 0\): base_color must be numbers, got 'red'"),
    Case("roughness-none", "scene", with_scene(setattr_("materials.1.roughness", None)), E,
         r"material 'red' \(material 1\): roughness must be numbers"),
    Case("material-unknown-type", "scene", with_scene(setattr_("materials.1.type", "plastic")), E,
         r"material 'red' \(material 1\): unknown type 'plastic'"),
    Case("material-unknown-type-flat", "flat", lambda _t: flat(set_("material_type", 2, 7)), E,
         r"material 2: unknown type 7"),
    Case("mix-cycle", "scene", lambda _t: _mix_cycle(), E, r"mix chain has a cycle"),
    Case("texture-float-nan", "scene", with_scene(lambda sc: sc.textures.append(Texture(np.full((2, 2, 3), np.nan)))), E,
         r"texture 0: float pixels must be finite"),
    Case("texture-int16", "scene", with_scene(lambda sc: sc.textures.append(Texture(np.zeros((2, 2, 3), np.int16)))), E,
         r"texture 0: pixels must be uint8 sRGB or float linear, got int16"),
    Case("texture-zero-size", "scene", with_scene(lambda sc: sc.textures.append(Texture(np.zeros((0, 4, 3), np.uint8)))), E,
         r"zero-size image"),
    Case("texture-index-string", "scene", with_scene(setattr_("materials.0.base_color_texture", "wood")), E,
         r"base_color_texture must be an integer index, got 'wood'"),
    Case("world-color-1e30-flat", "flat", lambda _t: flat(replace("world_color", np.full(3, 1e30, np.float32))), E,
         r"world_color 1e\+30 exceeds the radiance limit"),
    Case("world-strength-overflow", "scene", with_scene(lambda sc: setattr(sc.world, "strength", 1e30) or
                                                         setattr(sc.world, "map", np.full((2, 4, 3), 1e10, np.float32))), E,
         r"world map: pixel x strength = 1e\+40 does not fit in float32"),
    Case("world-map-nan-flat", "flat", lambda _t: flat(replace("world_map", np.full((2, 4, 3), np.nan, np.float32))), E,
         r"world_map pixel \(row 0, column 0\) is NaN or infinite"),
    Case("world-map-nan-scene", "scene", with_scene(setattr_("world.map", np.full((2, 4, 3), np.nan))), E,
         r"world map: pixel \(row 0, column 0\) is NaN/Inf"),
    Case("world-none", "scene", with_scene(setattr_("world", None)), E, r"world: expected a World"),
    # -- geometry and instances --
    Case("positions-1e39", "scene", with_scene(lambda sc: sc.meshes[0].positions.__setitem__((0, 0), 1e39)), E,
         r"mesh 'floor' \(mesh 0\): positions = 1e\+39 does not fit in float32"),
    Case("positions-1e20-flat", "flat", lambda _t: flat(set_("positions", (0, 0), 1e20)), E,
         r"positions\[0\] is beyond the coordinate limit"),
    Case("positions-nan-flat", "flat", lambda _t: flat(set_("positions", (3, 1), np.nan)), E, r"positions\[3\] is NaN"),
    Case("indices-out-of-range-flat", "flat", lambda _t: flat(set_("indices", (2, 1), 10**6)), E,
         r"indices\[2\] refers to vertex 1000000"),
    Case("degenerate-triangles", "scene", with_scene(lambda sc: sc.meshes.append(
        Mesh(np.array([[0, 0, 0], [1, 1, 1], [2, 2, 2]], float), np.array([[0, 1, 2]]), name="line"))), Wn,
         r"mesh 'line' \(mesh 8\): 1 degenerate triangles skipped"),
    Case("instance-singular", "scene", with_scene(scaled(0.0)), Wn,
         r"instance\(s\) of empty meshes or with singular transforms skipped"),
    Case("instance-mesh-string", "scene", with_scene(lambda sc: setattr(sc.instances[1], "mesh", "box")), E,
         r"instance 1: mesh must be an integer index, got 'box'"),
    Case("instance-projective", "scene", with_scene(lambda sc: sc.instances[0].transform.__setitem__((3, 0), 1.0)), E,
         r"instance 0: transform is projective"),
    Case("instance-nan-flat", "flat", lambda _t: flat(set_("instance_transform", (0, 0, 0), np.nan)), E,
         r"instance_transform\[0\] is NaN"),
    Case("floor-scaled-1e8", "scene", with_scene(scaled(1e8)), Wn, r"reaches 1e\+08 m from the origin"),
    Case("floor-offset-1e8", "scene", far_floor(1e8), Wn, r"reaches 1(\.\d+)?e\+08 m from the origin"),
    Case("floor-offset-3e6", "scene", far_floor(3e6), Wn, r"beyond 1e\+06 m float32 precision fails"),
    # -- .npz files: wrong ids, lengths, metadata, damaged files --
    Case("npz-unknown-material-type", "npz", npz(set_("material_type", 1, 9)), E,
         r"array 'material_type' holds unknown type id 9"),
    Case("npz-unknown-light-type", "npz", npz(_add_light(type=8)), E,
         r"array 'light_type' holds unknown type id 8"),
    Case("npz-unknown-camera-type", "npz", npz(replace("camera_type", np.array([5], np.uint32))), E,
         r"array 'camera_type' holds unknown type id 5"),
    Case("npz-empty-camera-type", "npz", npz(replace("camera_type", np.zeros(0, np.uint32))), E,
         r"array 'camera_type' has shape \(0,\), expected 1 rows"),
    Case("npz-material-lengths", "npz", npz(lambda a: a.update(material_roughness=a["material_roughness"][:2])), E,
         r"arrays of one kind differ in length: .*'material_roughness': 2"),
    Case("npz-mesh-lengths", "npz", npz(lambda a: a.update(mesh_has_uvs=a["mesh_has_uvs"][:3])), E,
         r"arrays of one kind differ in length"),
    Case("npz-missing-array", "npz", npz(lambda a: a.pop("material_ior")), E, r"missing arrays \['material_ior'\]"),
    Case("npz-positions-2d", "npz", npz(lambda a: a.update(positions=a["positions"][:, :2].copy())), E,
         r"array 'positions' has shape \(\d+, 2\), expected \(V,3\)"),
    Case("npz-indices-out-of-range", "npz", npz(set_("indices", (0, 0), 10**6)), E,
         r"array 'indices' refers to vertices outside"),
    Case("npz-mesh-past-triangles", "npz", npz(set_("mesh_triangle_count", 0, 10**6)), E,
         r"mesh 0 covers triangles 0\.\.1000000"),
    Case("npz-texture-past-texels", "npz", npz(_texture_past_texels), E,
         r"texture 0: 100x100 texels at offset 0 do not fit in the 16 texels"),
    Case("npz-meta-short-mesh-names", "npz", npz(meta=lambda m: m.update(mesh_names=["floor"])), E,
         r"__meta__ mesh_names must be a list of 8 strings"),
    Case("npz-meta-short-material-names", "npz", npz(meta=lambda m: m.update(material_names=[])), E,
         r"__meta__ material_names must be a list of 4 strings"),
    Case("npz-meta-negative-width", "npz", npz(meta=lambda m: m.update(width=-5)), E,
         r"__meta__ width must be a positive integer, got -5"),
    Case("npz-meta-first-vertex", "npz", npz(meta=lambda m: m.update(mesh_first_vertex=[-3] * 8)), E,
         r"__meta__ mesh_first_vertex must be 8 increasing vertex indices"),
    Case("npz-meta-not-json", "npz", lambda tmp: _npz_meta_text(tmp, "{not json"), E, r"__meta__ is not valid JSON"),
    Case("npz-empty-file", "npz", npz(raw=b""), E, r"not a readable \.npz \(EOFError"),
    Case("npz-truncated", "npz", lambda tmp: _truncated(tmp), E, r"not a readable \.npz"),
    Case("npz-text-file", "npz", npz(raw=b"hello, this is not a scene\n"), E, r"not a readable \.npz"),
    Case("npz-single-array", "npz", lambda tmp: _npy(tmp), E, r"a single array, not an archive"),
    # -- sessions and settings --
    Case("session-negative-width", "session", lambda _t: (-5, 8), E, r"image size: width must be an integer in 1\.\.16384, got -5"),
    Case("session-float-height", "session", lambda _t: (8, 2.5), E, r"image size: height must be an integer"),
    Case("params-samples-0", "params", lambda _t: {"samples_per_frame": 0}, E, r"samples_per_frame must be in \[1, 4096\], got 0"),
    Case("params-samples-huge", "params", lambda _t: {"samples_per_frame": 10**5}, E, r"samples_per_frame"),
    Case("params-depth-huge", "params", lambda _t: {"max_depth": 5000}, E, r"max_depth must be in \[0, 1024\], got 5000"),
    Case("params-light-samples-0", "params", lambda _t: {"light_samples": 0}, E, r"light_samples must be in \[1, 64\], got 0"),
    Case("params-negative-seed", "params", lambda _t: {"seed": -1}, E, r"seed must be in \[0, 2147483647\], got -1"),
    Case("params-method", "params", lambda _t: {"method": "bdpt"}, E, r"method must be one of mis, nee, pt, got 'bdpt'"),
    Case("params-ic-accuracy-nan", "params", lambda _t: {"ic_accuracy": float("nan")}, E, r"ic_accuracy"),
    Case("heavy-render-cancelled", "cancel", _heavy, "cancelled", r"render\(1000\) stopped by cancel\(\)"),
    # -- the command line: one line on stderr and exit 2, never a traceback --
    Case("cli-truncated", "cli", cli_render(lambda tmp: _truncated(tmp)), E, r"not a readable \.npz"),
    Case("cli-empty", "cli", cli_render(npz(raw=b"")), E, r"not a readable \.npz"),
    Case("cli-unknown-material-type", "cli", cli_render(npz(set_("material_type", 0, 42))), E, r"unknown type id 42"),
    Case("cli-empty-camera-type", "cli", cli_render(npz(replace("camera_type", np.zeros(0, np.uint32)))), E,
         r"'camera_type' has shape"),
    Case("cli-short-names", "cli", cli_render(npz(meta=lambda m: m.update(material_names=["a"]))), E,
         r"material_names must be a list of 4 strings"),
    Case("cli-negative-width", "cli", cli_render(npz(), "--width", "-5"), E, r"image size: width must be"),
    Case("cli-meta-negative-height", "cli", cli_render(npz(meta=lambda m: m.update(height=-1))), E,
         r"height must be a positive integer"),
    Case("cli-missing-file", "cli", cli_render(lambda tmp: os.path.join(tmp, "nowhere.npz")), E, r"No such file"),
    Case("cli-bad-set", "cli", cli_render(npz(), "--set", "max_depth=lots"), E, r"--set 'max_depth=lots': expected an integer"),
    Case("cli-precision-warning", "cli", cli_render(lambda tmp: _save(far_floor(1e8)(tmp), tmp)), Wn,
         r"parallax: warning: the scene reaches"),
]


def _mix_cycle():
    sc = cornell()
    sc.materials[0].mix_next, sc.materials[1].mix_next = 1, 0
    return sc


def _save(scene, tmp):
    path = os.path.join(tmp, "scene.npz")
    scene.save(path)
    return path


def _truncated(tmp):
    path = _save(cornell(), tmp)
    data = open(path, "rb").read()
    with open(path, "wb") as f:
        f.write(data[: len(data) // 2])
    return path


def _npy(tmp):
    path = os.path.join(tmp, "scene.npz")
    with open(path, "wb") as f:
        np.save(f, np.zeros(3))
    return path


def _npz_meta_text(tmp, text):
    path = os.path.join(tmp, "scene.npz")
    np.savez(path, **cornell().flatten(), __meta__=np.array(text))
    return path


# ---- running a case -----------------------------------------------------------------------

@dataclasses.dataclass
class Outcome:
    kind: str            # "error", "warn", "render" (no warning), "nonfinite", "traceback",
                         # "cancelled" (a render stopped from another thread)
    message: str = ""    # the error, or the warnings joined
    error_type: str = ""

    def matches(self, case):
        if self.kind != case.expect:
            return False
        return re.search(case.match, self.message) is not None


def _render(session, scene_input):
    """Updates, renders 2 frames and checks every pass; the Outcome."""
    warnings = session.update(scene_input)
    session.render(2)
    finite = all(np.isfinite(session.read(p.name)).all() for p in pc.PASSES if p.core)
    if not finite:
        return Outcome("nonfinite", "; ".join(warnings))
    return Outcome("warn" if warnings else "render", "\n".join(warnings))


def _cancelled(session, scene, wait=1.0, limit=300.0, frames=1000):
    """Starts ``frames`` heavy frames on a thread, cancels them after ``wait`` seconds and waits
    up to ``limit`` for the call to return (one frame takes minutes on lavapipe)."""
    session.set_params(**HEAVY_PARAMS)
    session.update(scene)
    done = []
    thread = threading.Thread(target=lambda: done.append(session.render(frames)), daemon=True)
    thread.start()
    time.sleep(wait)
    session.cancel()
    thread.join(limit)
    if thread.is_alive():
        raise TimeoutError(f"render(1) still running {limit:.0f} s after cancel()")
    finite = all(np.isfinite(session.read(p.name)).all() for p in pc.PASSES if p.core)
    if done[0] >= frames or not finite:
        return Outcome("render" if finite else "nonfinite", f"render({frames}) completed {done} frames")
    return Outcome("cancelled", f"render({frames}) stopped by cancel() after {done[0]} frames")


def run(case, session, tmp):
    """Runs ``case`` on ``session`` (8x8); returns its Outcome. A clean error is a ValueError
    (the CLI: exit 2 and one line); any other exception propagates (a test failure)."""
    value = case.build(tmp)
    if case.kind == "cli":
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            code = cli.main(value)
        lines = [line for line in err.getvalue().replace("\r", "\n").splitlines() if line.startswith("parallax:")]
        if code == 2 and len(lines) == 1 and lines[0].startswith("parallax: error: "):
            return Outcome("error", lines[0], "exit 2")
        if code == 0:
            return Outcome("warn" if lines else "render", "\n".join(lines))
        return Outcome("traceback", err.getvalue(), f"exit {code}")
    try:
        if case.kind == "session":
            pc.Session(*value)
            return Outcome("render")
        if case.kind == "params":
            session.set_params(**value)
            return Outcome("render")
        if case.kind == "cancel":
            return _cancelled(session, value)
        session.set_params(**dataclasses.asdict(pc.RenderParams()))  # earlier cases may have changed them
        if case.kind == "npz":
            value = SceneData.load(value)
        return _render(session, value)
    except ValueError as e:
        return Outcome("error", str(e), type(e).__name__)


# ---- each case in a process of its own ----------------------------------------------------

def _one(name):
    case = next(c for c in CASES if c.name == name)
    with tempfile.TemporaryDirectory() as tmp:
        try:
            outcome = run(case, pc.Session(W, H), tmp)
        except Exception as e:  # a wrong exception type: reported, not a crash
            outcome = Outcome("traceback", f"{type(e).__name__}: {e}", type(e).__name__)
    print("OUTCOME " + json.dumps(dataclasses.asdict(outcome)))


def main(argv):
    import argparse

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("names", nargs="*", help="cases to run (default: all)")
    p.add_argument("--timeout", type=float, default=600, help="seconds before a case counts as a hang")
    p.add_argument("--one", help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.one:
        _one(a.one)
        return 0
    counts = {}
    for case in CASES:
        if a.names and case.name not in a.names:
            continue
        start = time.perf_counter()
        try:
            r = subprocess.run([sys.executable, __file__, "--one", case.name], capture_output=True, text=True,
                               timeout=a.timeout)
            line = [x for x in r.stdout.splitlines() if x.startswith("OUTCOME ")]
            if r.returncode != 0 or not line:
                result, detail = "crash", f"exit {r.returncode}: {r.stderr.strip()[-300:]}"
            else:
                o = Outcome(**json.loads(line[0][8:]))
                result = {"error": "clean error", "warn": "warned render", "render": "render without warning",
                          "nonfinite": "silent non-finite", "traceback": "wrong exception",
                          "cancelled": "stopped by cancel"}[o.kind]
                if o.kind in ("error", "warn", "cancelled") and not o.matches(case):
                    result = "unexpected"
                detail = o.message.replace("\n", " | ")[:160]
        except subprocess.TimeoutExpired:
            result, detail = "hang", f"over {a.timeout:.0f} s"
        counts[result] = counts.get(result, 0) + 1
        print(f"{case.name:34s} {result:18s} {time.perf_counter() - start:5.1f} s  {detail}", flush=True)
    print(f"\n{sum(counts.values())} cases: " + ", ".join(f"{n} {k}" for k, n in sorted(counts.items())))
    for k in ("crash", "hang", "silent non-finite", "wrong exception", "unexpected", "render without warning"):
        print(f"  {k}: {counts.get(k, 0)}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
