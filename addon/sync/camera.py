"""The scene camera -> Parallax Camera (Blender's view plane: sensor fit, shift, clipping)."""


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
