"""The scene camera -> Parallax Camera (Blender's view plane: sensor fit, shift, clipping; depth
of field and panoramas as Cycles reads them)."""

import numpy as np


def export_camera(depsgraph, width, height, region=None):
    """Camera for a ``width`` x ``height`` frame; with ``region`` = (x, y, w, h) (pixels, y
    from the bottom) the view plane is cut down to that part of the frame."""
    from ..core import load

    Camera = load().scene.Camera
    scene = depsgraph.scene
    if scene.camera is None:
        raise ValueError("the scene has no active camera")
    obj = scene.camera.evaluated_get(depsgraph)
    cam = obj.data
    if obj.type != "CAMERA":
        raise ValueError(f"the active camera '{obj.name}' is a {obj.type.lower()}, not a camera")
    if cam.type not in ("PERSP", "ORTHO", "PANO"):
        raise ValueError(f"camera '{obj.name}': {cam.type.lower()} cameras are not supported "
                         "(perspective, orthographic and panoramic are)")
    render = scene.render
    camera = Camera.from_blender(
        obj.matrix_world, width, height, type=cam.type, lens=cam.lens,
        sensor_width=cam.sensor_width, sensor_height=cam.sensor_height,
        sensor_fit=cam.sensor_fit, ortho_scale=cam.ortho_scale, shift_x=cam.shift_x,
        shift_y=cam.shift_y, clip_start=cam.clip_start, clip_end=cam.clip_end,
        pixel_aspect=render.pixel_aspect_x / render.pixel_aspect_y,
        **lens_settings(obj, depsgraph))
    if region is not None:
        x, y, w, h = region
        left, right, bottom, top = camera.window
        sx, sy = (right - left) / width, (top - bottom) / height
        camera.window = (left + sx * x, left + sx * (x + w), bottom + sy * y, bottom + sy * (y + h))
    return camera


def lens_settings(obj, depsgraph):
    """Camera.from_blender's depth of field and panorama keywords for camera object ``obj``,
    as Cycles' Blender sync reads them (intern/cycles/blender/camera.cpp)."""
    cam = obj.data
    out = {}
    if cam.type == "PANO":
        out["panorama_type"] = _panorama(cam, "panorama_type")
        if out["panorama_type"] == "CENTRAL_CYLINDRICAL":
            radius = cam.central_cylindrical_radius
            out["panorama_range"] = (cam.central_cylindrical_range_u_min, cam.central_cylindrical_range_u_max,
                                     cam.central_cylindrical_range_v_min / radius,
                                     cam.central_cylindrical_range_v_max / radius)
        else:
            out["panorama_range"] = tuple(_panorama(cam, k) for k in
                                          ("longitude_min", "longitude_max", "latitude_min", "latitude_max"))
        out["fisheye_fov"], out["fisheye_lens"] = _panorama(cam, "fisheye_fov"), _panorama(cam, "fisheye_lens")
        out["fisheye_polynomial"] = tuple(_panorama(cam, f"fisheye_polynomial_k{k}") for k in range(5))
    dof = cam.dof
    if dof.use_dof:
        # Cycles: the aperture radius from the f-number (the focal length in metres over twice
        # the f-number; 1 / (2 f) for orthographic cameras).
        fstop = max(dof.aperture_fstop, 1e-5)
        out["aperture_radius"] = 1.0 / (2.0 * fstop) if cam.type == "ORTHO" else cam.lens * 1e-3 / (2.0 * fstop)
        out["focus_distance"] = focus_distance(obj, depsgraph)
        out["aperture_blades"] = dof.aperture_blades
        out["aperture_rotation"] = dof.aperture_rotation
        out["aperture_ratio"] = dof.aperture_ratio
    return out


def _panorama(cam, name):
    """A panorama setting: on the camera since Blender 4, in Cycles' settings (cam.cycles) before."""
    if hasattr(cam, name):
        return getattr(cam, name)
    return getattr(cam.cycles, name)


def focus_distance(obj, depsgraph):
    """The camera's focus distance: its focus object's (or bone's) distance along the view
    axis, as Cycles measures it, else the distance setting."""
    dof = obj.data.dof
    target = dof.focus_object
    if target is None:
        return dof.focus_distance
    target = target.evaluated_get(depsgraph)
    matrix = target.matrix_world
    if dof.focus_subtarget and target.pose is not None and dof.focus_subtarget in target.pose.bones:
        matrix = matrix @ target.pose.bones[dof.focus_subtarget].matrix
    camera = np.array(obj.matrix_world, dtype=np.float64)
    axis = camera[:3, 2] / max(np.linalg.norm(camera[:3, 2]), 1e-30)
    offset = camera[:3, 3] - np.array(matrix, dtype=np.float64)[:3, 3]
    return float(abs(axis @ offset))


def view_camera(view_matrix, window_matrix, is_perspective):
    """The Camera of a 3D viewport from its view (world -> view) and window (projection)
    matrices, as Blender draws it: also right for camera view, zoom and offsets included.

    OpenGL projection: perspective P[0][0] = 2/(R - L), P[0][2] = (R + L)/(R - L) for the
    window [L, R] at distance 1 (likewise y); orthographic P[0][0] = 2/(r - l),
    P[0][3] = -(r + l)/(r - l).
    """
    from ..core import load

    Camera = load().scene.Camera
    view = np.array(view_matrix, dtype=np.float64)
    p = np.array(window_matrix, dtype=np.float64)
    camera_to_world = np.linalg.inv(view)[:3]
    camera_to_world[:, :3] /= np.linalg.norm(camera_to_world[:, :3], axis=0)
    if is_perspective:
        window = ((p[0, 2] - 1) / p[0, 0], (p[0, 2] + 1) / p[0, 0],
                  (p[1, 2] - 1) / p[1, 1], (p[1, 2] + 1) / p[1, 1])
        near, far = p[2, 3] / (p[2, 2] - 1), p[2, 3] / (p[2, 2] + 1)
        return Camera(camera_to_world, "perspective", window, near, far)
    window = ((-1 - p[0, 3]) / p[0, 0], (1 - p[0, 3]) / p[0, 0],
              (-1 - p[1, 3]) / p[1, 1], (1 - p[1, 3]) / p[1, 1])
    near, far = (p[2, 3] + 1) / p[2, 2], (p[2, 3] - 1) / p[2, 2]
    # Orthographic rays start on the camera plane: move it back to the near plane (Blender's
    # orthographic viewports put it behind the view point).
    camera_to_world[:, 3] += camera_to_world[:, 2] * -near
    return Camera(camera_to_world, "orthographic", window, 0.0, far - near)


def viewport_camera(context, depsgraph):
    """The Camera of a 3D viewport (``view_camera``); looking through the scene camera, also
    its depth of field, and its panorama mapped onto the camera frame, as Cycles' viewport
    does (blender_camera_from_view)."""
    import dataclasses

    rv3d = context.region_data
    view = view_camera(rv3d.view_matrix, rv3d.window_matrix, rv3d.is_perspective)
    if rv3d.view_perspective != "CAMERA":
        return view
    space = context.space_data
    obj = space.camera if getattr(space, "use_local_camera", False) and space.camera else context.scene.camera
    if obj is None or obj.type != "CAMERA":
        return view
    obj = obj.evaluated_get(depsgraph)
    settings = lens_settings(obj, depsgraph)
    cam = obj.data
    if cam.type != "PANO":
        dof = ("aperture_radius", "focus_distance", "aperture_blades", "aperture_rotation", "aperture_ratio")
        return dataclasses.replace(view, **{k: settings[k] for k in dof if k in settings})
    # The panorama's image square spans the camera frame, which Blender draws as a perspective
    # camera's: the view's window relative to that frame, in the frame's (u, v).
    from ..core import load

    render = context.scene.render
    width = render.resolution_x * render.resolution_percentage // 100
    height = render.resolution_y * render.resolution_percentage // 100
    common = dict(sensor_width=cam.sensor_width, sensor_height=cam.sensor_height, sensor_fit=cam.sensor_fit,
                  shift_x=cam.shift_x, shift_y=cam.shift_y, clip_start=cam.clip_start, clip_end=cam.clip_end,
                  pixel_aspect=render.pixel_aspect_x / render.pixel_aspect_y)
    Camera = load().scene.Camera
    fl, fr, fb, ft = Camera.from_blender(obj.matrix_world, width, height, type="PERSP", lens=cam.lens,
                                         **common).window
    vl, vr, vb, vt = view.window
    panorama = Camera.from_blender(obj.matrix_world, width, height, type="PANO", **common, **settings)
    u0, v0 = panorama.window[0], panorama.window[2]  # the shift
    panorama.window = (u0 + (vl - fl) / (fr - fl), u0 + (vr - fl) / (fr - fl),
                       v0 + (vb - fb) / (ft - fb), v0 + (vt - fb) / (ft - fb))
    return panorama
