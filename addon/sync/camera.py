"""The scene camera -> Parallax Camera (Blender's view plane: sensor fit, shift, clipping)."""

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
    if cam.type not in ("PERSP", "ORTHO"):
        kind = {"PANO": "panoramic"}.get(cam.type, cam.type.lower())
        raise ValueError(f"camera '{obj.name}': {kind} cameras are not supported "
                         "(perspective and orthographic are)")
    render = scene.render
    camera = Camera.from_blender(
        obj.matrix_world, width, height, type=cam.type, lens=cam.lens,
        sensor_width=cam.sensor_width, sensor_height=cam.sensor_height,
        sensor_fit=cam.sensor_fit, ortho_scale=cam.ortho_scale, shift_x=cam.shift_x,
        shift_y=cam.shift_y, clip_start=cam.clip_start, clip_end=cam.clip_end,
        pixel_aspect=render.pixel_aspect_x / render.pixel_aspect_y)
    if region is not None:
        x, y, w, h = region
        left, right, bottom, top = camera.window
        sx, sy = (right - left) / width, (top - bottom) / height
        camera.window = (left + sx * x, left + sx * (x + w), bottom + sy * y, bottom + sy * (y + h))
    return camera


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
