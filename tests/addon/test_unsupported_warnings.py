"""Scene features Parallax does not render are named in one export warning each."""
import pytest
from blender_helpers import export_current

FEATURES = ("motion blur", "holdout", "indirect only", "volume shaders", "hair curves")


def _cube(bpy, name="Cube"):
    bpy.ops.mesh.primitive_cube_add(size=2.0)
    obj = bpy.context.active_object
    obj.name = name
    return obj


def _light(bpy, scene):
    light = bpy.data.objects.new("Light", bpy.data.lights.new("Light", "POINT"))
    light.location = (0.0, -3.0, 3.0)
    scene.collection.objects.link(light)


def _feature_warnings(bpy, feature):
    """The F12 export's warnings that name ``feature``."""
    _, warnings = export_current(bpy)
    return [w for w in warnings if feature in w]


def _in_collection(bpy, scene, obj, name):
    """Moves ``obj`` into a new collection of the scene; returns its view-layer entry."""
    collection = bpy.data.collections.new(name)
    scene.collection.children.link(collection)
    for owner in obj.users_collection:
        owner.objects.unlink(obj)
    collection.objects.link(obj)
    return bpy.context.view_layer.layer_collection.children[name]


def _volume_output(bpy, tree, node_type):
    """Links a new ``node_type`` node into the tree's active output's Volume input."""
    node = tree.nodes.new(node_type)
    output = tree.get_output_node("CYCLES")
    tree.links.new(node.outputs[0], output.inputs["Volume"])


def test_plain_scene_has_none_of_these_warnings(fresh, bpy):
    _cube(bpy)
    _light(bpy, fresh)
    _, warnings = export_current(bpy)
    assert not [w for w in warnings if any(feature in w for feature in FEATURES)]


def test_motion_blur(fresh, bpy):
    _cube(bpy)
    fresh.render.use_motion_blur = True
    assert _feature_warnings(bpy, "motion blur") == [
        "motion blur is not supported: the scene renders as if it were off"]


def test_holdout_collection_and_object_one_warning(fresh, bpy):
    _in_collection(bpy, fresh, _cube(bpy), "Mask").holdout = True
    _cube(bpy, "Solid").is_holdout = True  # Blender 5.0's object-level holdout
    assert _feature_warnings(bpy, "holdout") == [
        "holdout is not supported: collection 'Mask' and 1 more rendered as if holdout were off"]


def test_indirect_only_collection(fresh, bpy):
    _in_collection(bpy, fresh, _cube(bpy), "Fill").indirect_only = True
    assert _feature_warnings(bpy, "indirect only") == [
        "indirect only is not supported: collection 'Fill' rendered as if indirect only "
        "were off (directly visible)"]


def test_excluded_holdout_collection_is_not_reported(fresh, bpy):
    entry = _in_collection(bpy, fresh, _cube(bpy), "Mask")
    entry.holdout = entry.exclude = True
    assert _feature_warnings(bpy, "holdout") == []


def test_volume_material(fresh, bpy):
    material = bpy.data.materials.new("Smoke")
    _volume_output(bpy, material.node_tree, "ShaderNodeVolumePrincipled")
    _cube(bpy).data.materials.append(material)
    assert _feature_warnings(bpy, "volume shaders") == [
        "volume shaders are not supported: material 'Smoke' rendered as if the Volume "
        "output were unlinked"]


def test_volume_world(fresh, bpy):
    _cube(bpy)
    world = fresh.world = bpy.data.worlds.new("Fog")
    _volume_output(bpy, world.node_tree, "ShaderNodeVolumeScatter")
    assert _feature_warnings(bpy, "volume shaders") == [
        "volume shaders are not supported: world 'Fog' rendered as if the Volume output "
        "were unlinked"]


def test_hair_curves_object(fresh, bpy):
    _cube(bpy)
    curves = bpy.data.hair_curves.new("Hair")
    curves.add_curves([4, 4, 4])
    fresh.collection.objects.link(bpy.data.objects.new("Hair", curves))
    assert _feature_warnings(bpy, "hair curves") == [
        "hair curves are not supported: curves object 'Hair' not rendered"]


@pytest.mark.parametrize("render_type, warned", [("PATH", True), ("NONE", False)])
def test_hair_particles(fresh, bpy, render_type, warned):
    cube = _cube(bpy)
    cube.modifiers.new("Fur", "PARTICLE_SYSTEM")
    settings = cube.particle_systems[0].settings
    settings.type, settings.count, settings.render_type = "HAIR", 20, render_type
    name = cube.particle_systems[0].name
    assert _feature_warnings(bpy, "hair curves") == [
        f"hair curves are not supported: hair particles '{name}' on object 'Cube' not rendered"
    ] * warned


def test_point_cloud(fresh, bpy):
    cube = _cube(bpy)
    # Geometry nodes turn the cube's vertices into points (a point cloud Cycles renders as spheres).
    tree = bpy.data.node_groups.new("ToPoints", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    source, sink = tree.nodes.new("NodeGroupInput"), tree.nodes.new("NodeGroupOutput")
    to_points = tree.nodes.new("GeometryNodeMeshToPoints")
    tree.links.new(source.outputs[0], to_points.inputs["Mesh"])
    tree.links.new(to_points.outputs["Points"], sink.inputs[0])
    cube.modifiers.new("Points", "NODES").node_group = tree
    assert _feature_warnings(bpy, "point clouds") == ["point clouds are not supported: object 'Cube' not rendered"]
