"""Mesh geometry and instances.

Every renderable object instance of the evaluated depsgraph (plain objects, collection
instances, geometry-nodes instances, particles) becomes one ``Instance``; instances of the
same evaluated geometry with the same materials share one ``Mesh`` (one BLAS in the core).
"""
import numpy as np

GEOMETRY_TYPES = {"MESH", "CURVE", "CURVES", "SURFACE", "META", "FONT"}


def export_geometry(depsgraph, data, material_table, warnings):
    """Fills data.meshes and data.instances; returns the sharing key -> mesh index map that
    ``export_instances`` needs (None for objects without faces)."""
    from ..core import load

    Mesh = load().scene.Mesh
    mesh_index = {}
    data.meshes = []
    for obj, matrix, key in _geometry_instances(depsgraph, material_table):
        if key not in mesh_index:
            mesh = _extract(obj, key[1], material_table, warnings)
            mesh_index[key] = None if mesh is None else len(data.meshes)
            if mesh is not None:
                data.meshes.append(Mesh(**mesh))
    export_instances(depsgraph, data, mesh_index, material_table)
    return mesh_index


def export_instances(depsgraph, data, mesh_index, material_table):
    """Refills data.instances (transforms) for the meshes already in ``data``; returns False,
    leaving data alone, if some instance's geometry is not among them."""
    from ..core import load

    Instance = load().scene.Instance
    instances = []
    for _, matrix, key in _geometry_instances(depsgraph, material_table):
        if key not in mesh_index:
            return False
        if mesh_index[key] is not None:
            instances.append(Instance(mesh_index[key], matrix))
    data.instances = instances
    return True


def _geometry_instances(depsgraph, material_table):
    """(evaluated object, object-to-world matrix, sharing key) of every renderable geometry
    instance."""
    for inst in depsgraph.object_instances:
        obj = inst.object
        if obj.type not in GEOMETRY_TYPES or not (inst.is_instance or inst.show_self):
            continue
        slots = tuple(material_table.index(slot.material) for slot in obj.material_slots)
        yield obj, np.array(inst.matrix_world, dtype=np.float64), (_geometry_key(obj), slots)


def _geometry_key(obj):
    """What identifies shared geometry across depsgraph evaluations: the mesh data of
    objects without modifiers (linked duplicates, collection instances share it), else the
    object itself (its modifiers make its geometry its own)."""
    original = obj.original if obj.original is not None else obj
    if obj.type == "MESH" and original.type == "MESH" and not original.modifiers:
        return ("mesh", original.data.name_full)
    return ("object", original.name_full, obj.data.name_full if obj.data is not None else "")


def _extract(obj, slots, material_table, warnings):
    """The object's evaluated geometry as Mesh keyword arguments, or None if it has none."""
    try:
        mesh = obj.to_mesh()
    except RuntimeError:
        mesh = None
    if mesh is None:
        return None
    try:
        return _mesh_arrays(mesh, obj.name, slots, material_table, warnings)
    finally:
        obj.to_mesh_clear()


def _mesh_arrays(mesh, name, slots, material_table, warnings):
    if hasattr(mesh, "calc_loop_triangles"):
        mesh.calc_loop_triangles()
    if hasattr(mesh, "calc_normals_split"):  # Blender < 4.1 computes split normals on request
        mesh.calc_normals_split()
    tris = mesh.loop_triangles
    T, V = len(tris), len(mesh.vertices)
    if T == 0:
        warnings.add(f"object '{name}': no faces, skipped")
        return None
    positions = _get(mesh.vertices, "co", V * 3, np.float32).reshape(V, 3)
    indices = _get(tris, "vertices", T * 3, np.int32).reshape(T, 3)
    loops = _get(tris, "loops", T * 3, np.int32).reshape(T, 3)
    normals = _get(tris, "split_normals", T * 9, np.float32).reshape(T, 3, 3)
    slot_of_triangle = _get(tris, "material_index", T, np.int32)

    uvs = tangents = None
    uv_layer = mesh.uv_layers.active
    if uv_layer is not None:
        loop_uvs = _get(uv_layer.data, "uv", len(mesh.loops) * 2, np.float32).reshape(-1, 2)
        uvs = loop_uvs[loops]
        maps = frozenset().union(*(material_table.tangent_maps(i) for i in slots))
        if maps:
            tangents = _tangents(mesh, uv_layer, maps, name, warnings)
            tangents = tangents[loops] if tangents is not None else None
    attributes = _attributes(mesh, loops, slots, material_table, name, warnings)

    if slots:
        table = np.asarray(slots, dtype=np.int64)
        material_indices = table[np.clip(slot_of_triangle, 0, len(table) - 1)]
    else:
        material_indices = np.full(T, material_table.index(None), dtype=np.int64)

    bad_vertex = ~np.isfinite(positions).all(axis=1)
    keep = ~bad_vertex[indices].any(axis=1) & np.isfinite(normals).reshape(T, -1).all(axis=1)
    if uvs is not None:
        keep &= np.isfinite(uvs).reshape(T, -1).all(axis=1)
    if not keep.all():
        warnings.add(f"object '{name}': {int((~keep).sum())} triangles with NaN/Inf vertices, "
                     "normals or UVs skipped")
        if not keep.any():
            return None
        indices, normals, material_indices = indices[keep], normals[keep], material_indices[keep]
        uvs = uvs[keep] if uvs is not None else None
        tangents = tangents[keep] if tangents is not None else None
        attributes = {slot: values[keep] for slot, values in attributes.items()}
        positions = np.where(bad_vertex[:, None], 0.0, positions).astype(np.float32)
    # Generated texture coordinates' space (Blender keeps the automatic one at the bounds).
    location, size = getattr(mesh, "texspace_location", None), getattr(mesh, "texspace_size", None)
    texspace = (*location, *size) if location is not None and size is not None else None
    if texspace is not None and not np.isfinite(texspace).all():
        texspace = None  # NaN vertices: the bounds of the ones kept
    return dict(positions=positions, indices=indices, normals=normals, uvs=uvs, tangents=tangents,
                attributes=attributes, material_indices=material_indices, name=name, texspace=texspace)


# Blender attribute data types -> (foreach_get property, components).
_ATTRIBUTE_TYPES = {"FLOAT_COLOR": ("color", 4), "BYTE_COLOR": ("color", 4), "FLOAT_VECTOR": ("vector", 3),
                    "FLOAT2": ("vector", 2), "FLOAT": ("value", 1), "INT": ("value", 1), "INT8": ("value", 1),
                    "BOOLEAN": ("value", 1)}


def _attributes(mesh, loops, slots, material_table, name, warnings):
    """{slot: (T, 3, 4)} of the attributes the mesh's materials read (MaterialTable
    attribute_requests): colour attributes (linear), other attributes and UV maps by name, as
    Cycles' Attribute, Color Attribute and UV Map nodes see them. A missing one gets no slot
    data (it reads 0)."""
    from ..core import load

    keys = sorted(frozenset().union(*(material_table.attribute_requests(i) for i in slots)))
    out = {}
    for key in keys:
        values = _attribute_values(mesh, key, name, warnings)
        if values is None:
            continue
        slot = material_table.attribute_slot(key, add=len(material_table.attribute_keys) < load().scene.ATTRIBUTE_SLOTS)
        if slot is None:
            warnings.add(f"object '{name}': more than {load().scene.ATTRIBUTE_SLOTS} attributes and UV maps are read "
                         f"by the scene's materials; '{key[1]}' reads 0")
            continue
        out[slot] = values[loops]
    return out


def _attribute_values(mesh, key, name, warnings):
    """(loops, 4) values of attribute ``key`` (node_graph.attribute_requests), or None."""
    kind, attribute_name = key
    L = len(mesh.loops)
    uv_layer = mesh.uv_layers.get(attribute_name) if attribute_name else None
    attribute = None
    if kind == "attribute":
        if attribute_name:
            attribute = mesh.attributes.get(attribute_name)
        else:  # the default colour attribute (Blender's render colour)
            colors = mesh.color_attributes
            index = getattr(colors, "render_color_index", -1)
            attribute = colors[index] if 0 <= index < len(colors) else getattr(colors, "active_color", None)
    if attribute is None:
        if uv_layer is None:
            return None
        out = np.zeros((L, 4), np.float32)
        out[:, :2] = _get(uv_layer.data, "uv", L * 2, np.float32).reshape(L, 2)
        out[:, 3] = 1.0
        return out
    kind = _ATTRIBUTE_TYPES.get(attribute.data_type)
    if kind is None or attribute.domain not in ("POINT", "CORNER", "FACE"):
        warnings.add(f"object '{name}': attribute '{attribute.name}' ({attribute.data_type}, {attribute.domain}) "
                     "cannot be read by nodes; it reads 0")
        return None
    prop, n = kind
    count = len(attribute.data)
    raw = _get(attribute.data, prop, count * n, np.float32).reshape(count, n)
    values = np.zeros((count, 4), np.float32)
    values[:, 3] = 1.0
    if n == 1:
        values[:, :3] = raw
    else:
        values[:, :n] = raw
    if attribute.domain == "POINT":
        return values[_get(mesh.loops, "vertex_index", L, np.int32)]
    if attribute.domain == "FACE":
        starts = _get(mesh.polygons, "loop_start", len(mesh.polygons), np.int64)
        totals = _get(mesh.polygons, "loop_total", len(mesh.polygons), np.int64)
        order = np.argsort(starts, kind="stable")  # the faces' corners, face after face
        return values[np.repeat(order, totals[order])]
    return values


def _tangents(mesh, uv_layer, maps, name, warnings):
    """(loops, 4) MikkTSpace tangents and bitangent signs of the UV map the mesh's Normal Maps
    name ('' the active one), as Blender computes them for Cycles' Normal Map; None (with a
    warning) where Blender cannot. One set per mesh: Normal Maps naming different maps on one
    mesh use the active map's (or the first named), with a warning."""
    wanted = sorted({m or uv_layer.name for m in maps})
    missing = [m for m in wanted if m not in mesh.uv_layers]
    if missing:
        warnings.add(f"object '{name}': a Normal Map names the UV map '{missing[0]}', which the mesh lacks; "
                     f"the tangents of the active map '{uv_layer.name}' are used")
    present = [m for m in wanted if m in mesh.uv_layers] or [uv_layer.name]
    chosen = uv_layer.name if uv_layer.name in present else present[0]
    if len(present) > 1:
        others = ", ".join(f"'{m}'" for m in present if m != chosen)
        warnings.add(f"object '{name}': its Normal Maps name the UV maps '{chosen}' and {others}; one set of "
                     f"tangents is exported per mesh: those of '{chosen}'")
    try:
        mesh.calc_tangents(uvmap=chosen)
    except RuntimeError as e:
        warnings.add(f"object '{name}': no tangents for its Normal Map ({e}); the surface's normal is used")
        return None
    L = len(mesh.loops)
    out = np.empty((L, 4), np.float32)
    out[:, :3] = _get(mesh.loops, "tangent", L * 3, np.float32).reshape(L, 3)
    out[:, 3] = _get(mesh.loops, "bitangent_sign", L, np.float32)
    return out


def _get(collection, attribute, count, dtype):
    array = np.empty(count, dtype=dtype)
    collection.foreach_get(attribute, array)
    return array
