"""bpy data -> SceneData: geometry, instancing, materials, lights, world and camera."""
import math

import numpy as np
import pytest
from blender_helpers import export_current


def _cube(bpy, scene, name="Cube", material=None, location=(0, 0, 0)):
    bpy.ops.mesh.primitive_cube_add(size=2.0, location=location)
    obj = bpy.context.active_object
    obj.name = name
    if material is not None:
        obj.data.materials.append(material)
    return obj


def _material(bpy, name, node_type, **inputs):
    material = bpy.data.materials.new(name)
    tree = material.node_tree
    tree.nodes.clear()
    node = tree.nodes.new(node_type)
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    tree.links.new(node.outputs[0], out.inputs["Surface"])
    for key, value in inputs.items():
        if key in node.inputs:
            node.inputs[key].default_value = value
        else:
            setattr(node, key, value)
    return material, node


def test_instances_share_one_mesh_and_modifiers_apply(fresh, bpy):
    cube = _cube(bpy, fresh)
    cube.modifiers.new("Subdivision", "SUBSURF").levels = 1
    cube.modifiers["Subdivision"].render_levels = 1
    collection = bpy.data.collections.new("Props")
    collection.objects.link(cube)
    fresh.collection.objects.unlink(cube)
    for i in range(3):
        empty = bpy.data.objects.new(f"Instance{i}", None)
        empty.instance_type, empty.instance_collection = "COLLECTION", collection
        empty.location = (3.0 * i, 0.0, 0.0)
        fresh.collection.objects.link(empty)
    data, _ = export_current(bpy)
    assert len(data.meshes) == 1 and len(data.instances) == 3
    assert len(data.meshes[0].indices) == 6 * 4 * 2  # one subdivision level, triangulated
    offsets = sorted(np.asarray(i.transform)[0, 3] for i in data.instances)
    np.testing.assert_allclose(offsets, [0.0, 3.0, 6.0], atol=1e-6)


def test_smooth_normals_uvs_and_material_slots(fresh, bpy):
    bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8, radius=1.0)
    sphere = bpy.context.active_object
    bpy.ops.object.shade_smooth()
    red, _ = _material(bpy, "Red", "ShaderNodeBsdfDiffuse", Color=(1, 0, 0, 1))
    blue, _ = _material(bpy, "Blue", "ShaderNodeBsdfDiffuse", Color=(0, 0, 1, 1))
    sphere.data.materials.append(red)
    sphere.data.materials.append(blue)
    for polygon in sphere.data.polygons:
        polygon.material_index = int(polygon.center.z > 0)
    data, _ = export_current(bpy)
    mesh = data.meshes[0]
    corners = mesh.positions[mesh.indices]
    # Smooth: close to radial (Blender weights face normals by angle), unlike flat normals.
    radial = corners / np.linalg.norm(corners, axis=-1, keepdims=True)
    np.testing.assert_allclose(mesh.normals, radial, atol=0.03)
    flat = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    flat /= np.linalg.norm(flat, axis=-1, keepdims=True)
    assert np.abs(mesh.normals - flat[:, None]).max() > 0.1
    assert mesh.uvs is not None and mesh.uvs.shape == (len(mesh.indices), 3, 2)
    top = corners.mean(axis=1)[:, 2] > 0
    names = np.array([data.materials[k].name for k in mesh.material_indices])
    assert set(names[top]) == {"Blue"} and set(names[~top]) == {"Red"}


def test_principled_exports_every_layer(fresh, bpy):
    material, _ = _material(bpy, "Layered", "ShaderNodeBsdfPrincipled", **{
        "Base Color": (0.5, 0.4, 0.3, 1.0), "Metallic": 0.25, "Transmission Weight": 0.5,
        "Roughness": 0.3, "IOR": 1.33, "Specular IOR Level": 0.7, "Specular Tint": (1.0, 0.9, 0.8, 1.0),
        "Coat Weight": 0.6, "Coat Roughness": 0.2, "Coat IOR": 1.6, "Coat Tint": (0.9, 1.0, 0.7, 1.0),
        "Sheen Weight": 0.4, "Sheen Roughness": 0.35, "Sheen Tint": (0.2, 0.3, 1.0, 1.0),
        "Emission Color": (1.0, 0.5, 0.0, 1.0), "Emission Strength": 2.0, "distribution": "GGX"})
    plain, _ = _material(bpy, "Plain", "ShaderNodeBsdfPrincipled", **{"Metallic": 1.5})
    _cube(bpy, fresh, material=material)
    _cube(bpy, fresh, "B", plain, location=(3, 0, 0))
    data, warnings = export_current(bpy)
    by_name = {m.name: m for m in data.materials}
    m = by_name["Layered"]
    assert m.type == "principled" and m.mix_next is None and not m.multiscatter
    np.testing.assert_allclose(m.base_color, (0.5, 0.4, 0.3), rtol=1e-6)
    assert (m.roughness, m.ior, m.metallic, m.transmission, m.specular_ior_level) == pytest.approx(
        (0.3, 1.33, 0.25, 0.5, 0.7))
    assert (m.coat_weight, m.coat_roughness, m.coat_ior, m.sheen_weight, m.sheen_roughness) == pytest.approx(
        (0.6, 0.2, 1.6, 0.4, 0.35))
    np.testing.assert_allclose([m.specular_tint, m.coat_tint, m.sheen_tint],
                               [(1.0, 0.9, 0.8), (0.9, 1.0, 0.7), (0.2, 0.3, 1.0)], rtol=1e-6)
    np.testing.assert_allclose(m.emission, (2.0, 1.0, 0.0))
    assert any("Layered" in w and "Sheen" in w for w in warnings)
    # Blender's defaults, Multiscatter GGX; Cycles clamps Metallic to 1 (so does the export).
    p = by_name["Plain"]
    assert p.type == "principled" and p.multiscatter and p.coat_weight == 0.0 and p.sheen_weight == 0.0
    assert not any("Plain" in w for w in warnings)
    flat = data.flatten()
    k = [x.name for x in data.materials].index("Plain")
    assert flat["material_principled"][k][3] == pytest.approx(1.0)  # metallic column, clamped


def test_mix_shader_with_emission_scales_the_bsdf(fresh, bpy):
    material = bpy.data.materials.new("Glow")
    tree = material.node_tree
    tree.nodes.clear()
    diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (0.8, 0.6, 0.4, 1.0)
    glow = tree.nodes.new("ShaderNodeEmission")
    glow.inputs["Strength"].default_value = 5.0
    mix = tree.nodes.new("ShaderNodeMixShader")
    mix.inputs[0].default_value = 0.25
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    tree.links.new(diffuse.outputs[0], mix.inputs[1])
    tree.links.new(glow.outputs[0], mix.inputs[2])
    tree.links.new(mix.outputs[0], out.inputs["Surface"])
    _cube(bpy, fresh, material=material)
    data, _ = export_current(bpy)
    m = data.materials[data.meshes[0].material_indices[0]]
    assert m.type == "diffuse" and m.mix_next is None
    np.testing.assert_allclose(m.base_color, (0.6, 0.45, 0.3), rtol=1e-6)
    np.testing.assert_allclose(m.emission, (1.25, 1.25, 1.25), rtol=1e-6)


def test_glossy_glass_multiscatter_and_beckmann_warning(fresh, bpy):
    glossy, _ = _material(bpy, "Metal", "ShaderNodeBsdfAnisotropic", Roughness=0.4, distribution="GGX")
    glass, _ = _material(bpy, "Glass", "ShaderNodeBsdfGlass", Roughness=0.2, IOR=1.6,
                         distribution="MULTI_GGX")
    rough, _ = _material(bpy, "Rough", "ShaderNodeBsdfGlossy", Roughness=0.3, distribution="BECKMANN")
    _cube(bpy, fresh, "A", glossy)
    _cube(bpy, fresh, "B", glass, location=(3, 0, 0))
    _cube(bpy, fresh, "C", rough, location=(-3, 0, 0))
    data, warnings = export_current(bpy)
    by_name = {m.name: m for m in data.materials}
    assert by_name["Metal"].type == "conductor" and by_name["Metal"].roughness == pytest.approx(0.4)
    assert not by_name["Metal"].multiscatter
    assert by_name["Glass"].type == "dielectric" and by_name["Glass"].ior == pytest.approx(1.6)
    assert by_name["Glass"].multiscatter  # Cycles' energy compensation, no warning
    assert [w for w in warnings if "single-scatter GGX" in w] == [
        "material 'Rough': 'Glossy BSDF': BECKMANN is rendered as single-scatter GGX"]


def test_glass_ior_outside_the_core_range_is_clamped_with_a_warning(fresh, bpy):
    """Blender allows IOR 0 (Cycles clamps it); the core takes 0.001..1000 and rejects the
    rest, so the export clamps it into that range and says so."""
    glass, _ = _material(bpy, "Zero", "ShaderNodeBsdfGlass", IOR=0.0)
    _cube(bpy, fresh, "A", glass)
    data, warnings = export_current(bpy)
    assert data.materials[0].ior == pytest.approx(1e-3)
    assert "material 'Zero': 'Glass BSDF': IOR 0 clamped to 0.001..1000" in warnings
    data.validate()  # the core's range: no error


def test_image_texture_into_base_color(fresh, bpy):
    image = bpy.data.images.new("Checker", 4, 2, alpha=True)
    pixels = np.zeros((2, 4, 4), np.float32)
    pixels[..., 3] = 1.0
    pixels[1, :, 0] = 1.0  # Blender row 1 = the top row: red
    image.pixels.foreach_set(pixels.ravel())
    material, diffuse = _material(bpy, "Textured", "ShaderNodeBsdfDiffuse")
    tex = material.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = image
    material.node_tree.links.new(tex.outputs["Color"], diffuse.inputs["Color"])
    _cube(bpy, fresh, material=material)
    data, _ = export_current(bpy)
    m = data.materials[data.meshes[0].material_indices[0]]
    texels = data.textures[m.base_color_texture].pixels
    assert texels.shape[:2] == (2, 4) and texels.dtype == np.uint8
    assert (texels[0, :, 0] == 255).all() and (texels[1, :, 0] == 0).all()  # row 0 = top


def test_node_graphs_become_node_programs_and_the_rest_is_named(fresh, bpy):
    """Texture and maths nodes into an input compile to the material's node program (their
    parity with Cycles: test_parity_nodes.py); a node the compiler does not know is named in a
    warning and the input keeps its own value."""
    from parallax_core import nodes

    material, bsdf = _material(bpy, "Ramped", "ShaderNodeBsdfPrincipled", Roughness=0.4)
    tree = material.node_tree
    ramp, coords = tree.nodes.new("ShaderNodeValToRGB"), tree.nodes.new("ShaderNodeTexCoord")
    separate = tree.nodes.new("ShaderNodeSeparateXYZ")
    tree.links.new(coords.outputs["UV"], separate.inputs[0])
    tree.links.new(separate.outputs["X"], ramp.inputs["Fac"])
    tree.links.new(ramp.outputs["Color"], bsdf.inputs["Base Color"])
    voronoi = tree.nodes.new("ShaderNodeTexVoronoi")
    voronoi.voronoi_dimensions = "2D"  # 3D is compiled
    tree.links.new(voronoi.outputs["Distance"], bsdf.inputs["Roughness"])
    _cube(bpy, fresh, material=material)
    data, warnings = export_current(bpy)
    m = data.materials[data.meshes[0].material_indices[0]]
    words = m.node_program
    assert words and words[-1] == nodes.NODE_END
    stores = [nodes.FIELDS[extra[0]] for op, _, _, _, extra in nodes.instructions(words) if op == nodes.NODE_STORE]
    assert stores == ["base_color"]
    assert m.roughness == pytest.approx(0.4)  # the 2D Voronoi is not compiled: the socket's value
    assert any("Voronoi Texture 'Voronoi Texture' in 2D" in w and "Roughness" in w for w in warnings), warnings


def test_float_image_and_interpolation_reach_the_texture(fresh, bpy):
    """A float image stays linear floats (values above 1 kept); the node's Closest travels
    with the texture; Cubic renders as Linear with a warning."""
    image = bpy.data.images.new("HDR", 2, 1, float_buffer=True)
    image.pixels.foreach_set(np.array([0.25, 0.5, 1.0, 1.0, 3.0, 2.0, 0.125, 1.0], np.float32))
    material, diffuse = _material(bpy, "Float", "ShaderNodeBsdfDiffuse")
    tex = material.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation = image, "Closest"
    material.node_tree.links.new(tex.outputs["Color"], diffuse.inputs["Color"])
    _cube(bpy, fresh, material=material)
    data, warnings = export_current(bpy)
    index = data.materials[data.meshes[0].material_indices[0]].base_color_texture
    texture = data.textures[index]
    assert texture.interpolation == "closest" and texture.pixels.dtype == np.float32
    np.testing.assert_allclose(texture.pixels[0], [[0.25, 0.5, 1.0], [3.0, 2.0, 0.125]])
    flat = data.flatten()
    assert flat["texture_flags"][index] == 3  # TEXTURE_FLAG_CLOSEST | TEXTURE_FLAG_HALF
    assert not any("interpolation" in w for w in warnings)
    tex.interpolation = "Cubic"
    data, warnings = export_current(bpy)
    texture = data.textures[data.materials[data.meshes[0].material_indices[0]].base_color_texture]
    assert texture.interpolation == "linear"
    assert any("uses Cubic interpolation; rendered as Linear" in w for w in warnings)


def test_lights_in_cycles_units(fresh, bpy):
    def light(kind, **props):
        obj = bpy.data.objects.new(kind, bpy.data.lights.new(kind, kind))
        for key, value in props.items():
            setattr(obj.data, key, value)
        fresh.collection.objects.link(obj)
        return obj

    area = light("AREA", energy=40.0, shape="RECTANGLE", size=2.0, size_y=1.0)
    area.scale = (1.5, 2.0, 1.0)
    area.visible_camera = True  # new lights are hidden from the camera in Blender 5
    area.rotation_euler = (math.pi / 2, 0.0, 0.0)
    light("SUN", energy=3.0, angle=0.1)
    light("SPOT", energy=100.0, spot_size=0.8, spot_blend=0.3, shadow_soft_size=0.2)
    light("POINT", energy=10.0, shadow_soft_size=0.5, color=(1.0, 0.5, 0.25))
    data, _ = export_current(bpy)
    by = {l.name: l for l in data.lights}
    a = by["AREA"]
    assert (a.type, a.shape, a.power) == ("area", "rectangle", 40.0)
    assert (a.size, a.size_y) == pytest.approx((3.0, 2.0))
    assert a.camera_visible and not any(l.camera_visible for l in data.lights if l is not a)
    np.testing.assert_allclose(a.direction, (0.0, 1.0, 0.0), atol=1e-6)  # local -Z, rotated
    sun = by["SUN"]
    assert sun.type == "sun" and (sun.power, sun.angle) == pytest.approx((3.0, 0.1))
    s = by["SPOT"]
    assert s.type == "spot" and (s.spot_size, s.spot_blend, s.radius) == pytest.approx((0.8, 0.3, 0.2))
    p = by["POINT"]
    assert p.type == "point" and p.radius == pytest.approx(0.5) and p.power == 10.0
    np.testing.assert_allclose(p.color, (1.0, 0.5, 0.25))


def test_world_color_and_environment_texture(fresh, bpy):
    world = bpy.data.worlds.new("World")
    fresh.world = world
    tree = world.node_tree
    background = next(n for n in tree.nodes if n.type == "BACKGROUND")
    background.inputs["Color"].default_value = (0.2, 0.4, 0.6, 1.0)
    background.inputs["Strength"].default_value = 2.0
    data, _ = export_current(bpy)
    assert data.world.map is None and data.world.strength == pytest.approx(2.0)
    np.testing.assert_allclose(data.world.color, (0.2, 0.4, 0.6), rtol=1e-6)

    image = bpy.data.images.new("Sky", 8, 4, float_buffer=True)
    pixels = np.ones((4, 8, 4), np.float32)
    pixels[3, :, :3] = (5.0, 0.0, 0.0)  # Blender's last row is the top: the zenith
    image.pixels.foreach_set(pixels.ravel())
    env = tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = image
    tree.links.new(env.outputs["Color"], background.inputs["Color"])
    data, _ = export_current(bpy)
    assert data.world.map.shape == (4, 8, 3)
    np.testing.assert_allclose(data.world.map[0, 0], (5.0, 0.0, 0.0))  # row 0 = zenith
    np.testing.assert_allclose(data.world.map[1:], 1.0)


def test_camera_shift_and_orthographic(fresh, bpy):
    fresh.render.resolution_x, fresh.render.resolution_y = 64, 32
    cam = fresh.camera.data
    cam.lens, cam.sensor_width, cam.shift_x = 50.0, 36.0, 0.1
    data, _ = export_current(bpy)
    left, right, bottom, top = data.camera.window
    assert (data.width, data.height) == (64, 32)
    assert right - left == pytest.approx(36.0 / 50.0) and top - bottom == pytest.approx(18.0 / 50.0)
    assert (left + right) / 2 == pytest.approx(0.1 * 36.0 / 50.0)
    cam.type, cam.ortho_scale, cam.shift_x = "ORTHO", 4.0, 0.0
    data, _ = export_current(bpy)
    assert data.camera.type == "orthographic"
    assert data.camera.window == pytest.approx((-2.0, 2.0, -1.0, 1.0))


def test_particle_instances_share_the_instanced_mesh(fresh, bpy):
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=1, radius=0.1, location=(0, 0, 10))
    pebble = bpy.context.active_object
    bpy.ops.mesh.primitive_plane_add(size=2.0)
    emitter = bpy.context.active_object
    emitter.modifiers.new("Scatter", "PARTICLE_SYSTEM")
    settings = emitter.particle_systems[0].settings
    settings.count, settings.frame_start, settings.frame_end = 7, 1, 1
    settings.physics_type, settings.render_type, settings.instance_object = "NO", "OBJECT", pebble
    settings.use_rotation_instance = False
    data, _ = export_current(bpy)
    sizes = sorted(len(m.indices) for m in data.meshes)
    assert sizes == [2, 20]  # the emitter plane and the ico sphere, once each
    pebble_mesh = next(i for i, m in enumerate(data.meshes) if len(m.indices) == 20)
    placed = [i for i in data.instances if i.mesh == pebble_mesh]
    assert len(placed) == 1 + 7  # the object itself and its seven particles


@pytest.mark.parametrize("kind", ["PERSP", "ORTHO"])
def test_viewport_camera_from_view_and_projection_matrices(fresh, bpy, kind):
    """view_camera (what the viewport draws) agrees with the scene camera's own export when
    fed that camera's view and projection matrices (as in camera view)."""
    from addon.sync.camera import view_camera

    fresh.render.resolution_x, fresh.render.resolution_y = 64, 40
    cam = fresh.camera
    cam.data.type, cam.data.shift_x, cam.data.shift_y = kind, 0.1, -0.05
    cam.location, cam.rotation_euler = (1.0, -6.0, 2.0), (1.3, 0.0, 0.2)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    data, _ = export_current(bpy)
    projection = cam.calc_matrix_camera(depsgraph, x=64, y=40)
    viewport = view_camera(cam.matrix_world.inverted(), projection, kind == "PERSP")
    assert viewport.type == data.camera.type
    np.testing.assert_allclose(viewport.window, data.camera.window, rtol=1e-4, atol=1e-5)
    ray_origin = np.asarray(viewport.camera_to_world)[:, 3]
    if kind == "PERSP":
        np.testing.assert_allclose(viewport.camera_to_world, data.camera.camera_to_world, atol=1e-5)
        assert viewport.clip_start == pytest.approx(cam.data.clip_start, rel=1e-3)
    else:  # orthographic rays start on the near plane, behind the camera if it is negative
        forward = -np.asarray(data.camera.camera_to_world)[:, 2]
        offset = ray_origin - np.asarray(data.camera.camera_to_world)[:, 3]
        np.testing.assert_allclose(np.cross(offset, forward), 0.0, atol=1e-4)


def _camera_view_context(bpy, scene, width, height):
    """What a 3D viewport looking through the scene camera gives viewport_camera, with the
    camera frame filling the region (the frame's own projection)."""
    from types import SimpleNamespace

    cam = scene.camera
    depsgraph = bpy.context.evaluated_depsgraph_get()
    rv3d = SimpleNamespace(view_matrix=cam.matrix_world.inverted(), is_perspective=True, view_perspective="CAMERA",
                           window_matrix=cam.calc_matrix_camera(depsgraph, x=width, y=height))
    return SimpleNamespace(region_data=rv3d, space_data=SimpleNamespace(use_local_camera=False, camera=None),
                           scene=scene), depsgraph


def test_viewport_through_the_camera_has_its_depth_of_field_and_panorama(fresh, bpy):
    """Looking through the scene camera the viewport renders what F12 does (Cycles does too):
    its depth of field, and its panorama's image square over the camera frame."""
    from addon.sync.camera import viewport_camera

    fresh.render.resolution_x, fresh.render.resolution_y = 64, 40
    cam = fresh.camera.data
    cam.dof.use_dof, cam.dof.aperture_fstop, cam.dof.focus_distance, cam.dof.aperture_blades = True, 1.4, 3.0, 7
    context, depsgraph = _camera_view_context(bpy, fresh, 64, 40)
    data, _ = export_current(bpy)
    view = viewport_camera(context, depsgraph)
    assert view.aperture_radius == pytest.approx(cam.lens * 1e-3 / 2.8) == pytest.approx(data.camera.aperture_radius)
    assert (view.focus_distance, view.aperture_blades) == (3.0, 7)
    context.region_data.view_perspective = "PERSP"  # a free view: no depth of field
    assert viewport_camera(context, depsgraph).aperture_radius == 0.0
    cam.type, cam.panorama_type, cam.shift_x = "PANO", "FISHEYE_EQUIDISTANT", 0.1
    context, depsgraph = _camera_view_context(bpy, fresh, 64, 40)
    data, _ = export_current(bpy)
    view = viewport_camera(context, depsgraph)
    assert (view.type, view.panorama_type) == ("panorama", "FISHEYE_EQUIDISTANT") == (data.camera.type,
                                                                                      data.camera.panorama_type)
    np.testing.assert_allclose(view.window, data.camera.window, atol=1e-4)
    np.testing.assert_allclose(view.window, (0.1, 1.1, 0.0, 1.0), atol=1e-4)


def test_mix_shader_keeps_principled_in_its_chain(fresh, bpy):
    material = bpy.data.materials.new("Blend")
    tree = material.node_tree
    tree.nodes.clear()
    principled = tree.nodes.new("ShaderNodeBsdfPrincipled")
    principled.inputs["Coat Weight"].default_value = 0.7
    glossy = tree.nodes.new("ShaderNodeBsdfGlossy")
    mix = tree.nodes.new("ShaderNodeMixShader")
    mix.inputs[0].default_value = 0.25
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    tree.links.new(principled.outputs[0], mix.inputs[1])
    tree.links.new(glossy.outputs[0], mix.inputs[2])
    tree.links.new(mix.outputs[0], out.inputs["Surface"])
    _cube(bpy, fresh, material=material)
    data, warnings = export_current(bpy)
    head = data.materials[data.meshes[0].material_indices[0]]
    assert head.type == "principled" and head.coat_weight == pytest.approx(0.7)
    assert head.mix_weight == pytest.approx(0.75)
    assert data.materials[head.mix_next].type == "conductor"
    assert data.materials[head.mix_next].coat_weight == 0.0


def test_normal_maps_and_attributes_reach_the_meshes_and_edits_reexport_them(fresh, bpy):
    """A tangent-space Normal Map gives the meshes of its material MikkTSpace tangents, an
    Attribute node a slot of the named colour attribute (other meshes: none); a viewport edit
    that adds such a node needs the geometry again (SceneExporter.update answers "geometry")."""
    from addon.sync import SceneExporter

    material, bsdf = _material(bpy, "Bumpy", "ShaderNodeBsdfDiffuse")
    cube = _cube(bpy, fresh, material=material)
    plain = _cube(bpy, fresh, "Plain", location=(4, 0, 0))
    paint = cube.data.color_attributes.new("Paint", "FLOAT_COLOR", "CORNER")
    for k, corner in enumerate(paint.data):
        corner.color = (k / len(paint.data), 0.5, 0.25, 1.0)
    exporter = SceneExporter()
    data, _ = exporter.full(bpy.context.evaluated_depsgraph_get(), 32, 32)
    assert all(m.tangents is None and m.attributes == {} for m in data.meshes)

    tree = material.node_tree
    normal_map, attribute = tree.nodes.new("ShaderNodeNormalMap"), tree.nodes.new("ShaderNodeAttribute")
    attribute.attribute_name = "Paint"
    tree.links.new(normal_map.outputs["Normal"], bsdf.inputs["Normal"])
    tree.links.new(attribute.outputs["Color"], bsdf.inputs["Color"])
    parts, warnings = exporter.update(bpy.context.evaluated_depsgraph_get(), {"materials"})
    assert parts == {"geometry"}, parts
    data = exporter.data
    bumpy = next(m for m in data.meshes if m.name == cube.name)
    other = next(m for m in data.meshes if m.name == plain.name)
    assert bumpy.tangents is not None and bumpy.tangents.shape == (12, 3, 4)
    np.testing.assert_allclose(np.linalg.norm(bumpy.tangents[..., :3], axis=-1), 1.0, atol=1e-4)
    assert set(np.unique(bumpy.tangents[..., 3])) <= {-1.0, 1.0}
    assert list(bumpy.attributes) == [0] and other.attributes == {} and other.tangents is None
    values = bumpy.attributes[0]
    assert values.shape == (12, 3, 4) and np.allclose(values[..., 1:], (0.5, 0.25, 1.0))
    assert len(np.unique(values[..., 0])) > 6  # a value per corner
    program = data.materials[bumpy.material_indices[0]].node_program
    from parallax_core import nodes

    ops = {op for op, *_ in nodes.instructions(program)}
    assert {nodes.NODE_NORMAL_MAP, nodes.NODE_ATTRIBUTE} <= ops
    assert not [w for w in warnings if "Normal Map" in w or "attribute" in w], warnings
    # An edit that changes no mesh data stays a materials update.
    normal_map.inputs["Strength"].default_value = 0.5
    parts, _ = exporter.update(bpy.context.evaluated_depsgraph_get(), {"materials"})
    assert parts == {"materials"}


def test_a_normal_map_naming_a_uv_map_gets_that_maps_tangents(fresh, bpy):
    """The tangents follow the UV map the Normal Map names (Blender's calc_tangents of it), not
    the active one; naming a map the mesh lacks is a warning (the active map's are used)."""
    from addon.sync import export_scene

    material, bsdf = _material(bpy, "Mapped", "ShaderNodeBsdfDiffuse")
    cube = _cube(bpy, fresh, material=material)
    turned = cube.data.uv_layers.new(name="Turned")
    for loop in turned.data:
        loop.uv = (loop.uv[1], 1.0 - loop.uv[0])  # the active map turned 90 degrees
    cube.data.uv_layers.active_index = 0
    normal_map = material.node_tree.nodes.new("ShaderNodeNormalMap")
    normal_map.uv_map = "Turned"
    material.node_tree.links.new(normal_map.outputs["Normal"], bsdf.inputs["Normal"])

    def exported():
        data, warnings = export_scene(bpy.context.evaluated_depsgraph_get(), 16, 16)
        return data.meshes[0].tangents, warnings

    tangents, warnings = exported()
    mesh = cube.data
    mesh.calc_tangents(uvmap="Turned")
    want = np.array([mesh.loops[i].tangent for tri in mesh.loop_triangles for i in tri.loops])
    np.testing.assert_allclose(tangents[..., :3].reshape(-1, 3), want, atol=1e-5)
    assert not [w for w in warnings if "UV map" in w], warnings
    normal_map.uv_map = "Missing"
    tangents, warnings = exported()
    mesh.calc_tangents(uvmap=mesh.uv_layers.active.name)
    active = np.array([mesh.loops[i].tangent for tri in mesh.loop_triangles for i in tri.loops])
    np.testing.assert_allclose(tangents[..., :3].reshape(-1, 3), active, atol=1e-5)
    assert not np.allclose(want, active, atol=1e-3)  # the two maps' tangents differ
    assert any("'Missing', which the mesh lacks" in w for w in warnings), warnings


def test_a_world_graph_is_baked_and_the_viewport_bakes_it_smaller(fresh, bpy, monkeypatch):
    """A graph into the Background (here the direction's height as grey) becomes an
    equirectangular map of it: 1024 x 512 for F12, 512 x 256 in the Rendered viewport; baked
    a block of rows at a time, the blocks' map is the one-block map."""
    from addon.sync import SceneExporter, world

    sky = bpy.data.worlds.new("Gradient")
    fresh.world = sky
    nodes, links = sky.node_tree.nodes, sky.node_tree.links
    background = next(n for n in nodes if n.type == "BACKGROUND")
    coords, separate = nodes.new("ShaderNodeTexCoord"), nodes.new("ShaderNodeSeparateXYZ")
    links.new(coords.outputs["Generated"], separate.inputs[0])
    links.new(separate.outputs["Z"], background.inputs["Color"])
    for exporter, width in ((SceneExporter(), 1024), (SceneExporter(world.PREVIEW_BAKE_WIDTHS), 512)):
        data, warnings = exporter.full(bpy.context.evaluated_depsgraph_get(), 16, 16)
        assert data.world.map.shape == (width // 2, width, 3) and not warnings
        latitude = (0.5 - (np.arange(width // 2) + 0.5) / (width // 2)) * np.pi  # row 0 at the top
        np.testing.assert_allclose(data.world.map[:, 7, 1], np.maximum(np.sin(latitude), 0.0), atol=1e-6)
    monkeypatch.setattr(world, "BAKE_BLOCK", 3 * 512 + 100)  # 3 rows a block, the last one short
    blocks, _ = SceneExporter(world.PREVIEW_BAKE_WIDTHS).full(bpy.context.evaluated_depsgraph_get(), 16, 16)
    np.testing.assert_array_equal(blocks.world.map, data.world.map)
