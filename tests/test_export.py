"""Tests of engine/blender/export.py: Blender scenes built in code -> Scene, checked by numbers."""
import math
import os
import types

import bpy
import numpy as np
import pytest
from bpy_extras.object_utils import world_to_camera_view
from mathutils import Matrix, Vector

from lanterna.engine.blender import compat
from lanterna.engine.blender.export import export_scene, export_settings
from lanterna.engine.pipeline import RenderSettings
from lanterna.engine.scene import AreaLight, PointLight, SceneError, SpotLight, SunLight


# ---------------------------------------------------------------------------------------------
# Helpers
# ---------------------------------------------------------------------------------------------
def reset():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return bpy.context.scene


def add_camera(scene, location=(0.0, -10.0, 0.0), rotation=(math.pi / 2, 0.0, 0.0)):
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.location = location
    cam.rotation_euler = rotation
    scene.collection.objects.link(cam)
    scene.camera = cam
    return cam


def add_cube(scene, name="Cube", size=2.0, mesh=None):
    if mesh is None:
        bpy.ops.mesh.primitive_cube_add(size=size)
        obj = bpy.context.object
        obj.name = name
        return obj
    obj = bpy.data.objects.new(name, mesh)
    scene.collection.objects.link(obj)
    return obj


def export():
    return export_scene(bpy.context.evaluated_depsgraph_get())


def cube_corners(half=1.0):
    return np.array([[x, y, z] for x in (-half, half) for y in (-half, half) for z in (-half, half)])


def unique_rows(points, decimals=4):
    return np.unique(np.round(np.asarray(points, float).reshape(-1, 3), decimals), axis=0)


def new_material(name):
    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):  # always True (and deprecated) in Blender 5
        mat.use_nodes = True
    return mat


def principled(mat):
    return next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")


def set_surface(mat, node):
    out = next(n for n in mat.node_tree.nodes if n.type == "OUTPUT_MATERIAL")
    mat.node_tree.links.new(node.outputs[0], out.inputs["Surface"])


def material_of(scene, name):
    return next(m for m in scene.materials if m.name == name)


# ---------------------------------------------------------------------------------------------
# Geometry
# ---------------------------------------------------------------------------------------------
def test_transformed_cube_positions_and_normals():
    scene = reset()
    add_camera(scene)
    cube = add_cube(scene)
    # Tilt the mesh itself so that the object's non-uniform scale shears the face normals.
    tilt = Matrix.Rotation(0.4, 4, "Z") @ Matrix.Rotation(0.3, 4, "X")
    cube.data.transform(tilt)
    cube.location = (1.0, 2.0, 3.0)
    cube.rotation_euler = (0.3, 0.5, 0.7)
    cube.scale = (1.0, 2.0, 0.5)
    s = export()
    assert s.triangles.shape == (12, 3, 3) and s.triangles.dtype == np.float32
    assert s.shading_normals.shape == (12, 3, 3) and s.shading_normals.dtype == np.float32
    assert s.material_ids.dtype == np.int32 and s.object_ids.dtype == np.int32
    assert s.object_names == ["Cube"]

    m = np.array(cube.matrix_world) @ np.array(tilt)
    expected = cube_corners() @ m[:3, :3].T + m[:3, 3]
    np.testing.assert_allclose(unique_rows(s.triangles), unique_rows(expected), atol=1e-4)
    # Every triangle lies on one face of the cube: one local coordinate is +-1 on all corners.
    local = (s.triangles.reshape(-1, 3) - m[:3, 3]) @ np.linalg.inv(m[:3, :3]).T
    local = local.reshape(12, 3, 3)
    on_face = np.any(np.all(np.abs(np.abs(local) - 1.0) < 1e-5, axis=1)
                     & (np.ptp(local, axis=1) < 1e-5), axis=1)
    assert on_face.all()
    # Shading normals (non-uniform scale): unit, perpendicular to the face, pointing outwards.
    n = s.shading_normals.astype(float)
    np.testing.assert_allclose(np.linalg.norm(n, axis=2), 1.0, atol=1e-5)
    edges = s.triangles[:, 1] - s.triangles[:, 0], s.triangles[:, 2] - s.triangles[:, 0]
    for e in edges:
        assert np.max(np.abs(np.einsum("tij,tj->ti", n, e))) < 1e-4
    outward = np.einsum("tij,tj->ti", n, s.triangles.mean(axis=1) - m[:3, 3])
    assert np.all(outward > 0)


def test_linked_duplicates_and_collection_instance_read_mesh_once():
    scene = reset()
    add_camera(scene)
    a = add_cube(scene, "A")
    mesh = a.data
    b = add_cube(scene, "B", mesh=mesh)
    b.location = (5.0, 0.0, 0.0)
    source = bpy.data.collections.new("Source")
    source.objects.link(bpy.data.objects.new("Src", mesh))   # not in the scene itself
    inst = bpy.data.objects.new("Inst", None)
    inst.instance_type = "COLLECTION"
    inst.instance_collection = source
    inst.location = (0.0, 0.0, 10.0)
    inst.scale = (2.0, 2.0, 2.0)
    scene.collection.objects.link(inst)
    s = export()
    assert len(s.triangles) == 36
    assert s.stats["meshes_read"] == 1
    assert sorted(s.object_names) == ["A", "B", "Inst/Src"]
    corners = cube_corners()
    for name, expected in (("A", corners), ("B", corners + [5.0, 0, 0]),
                           ("Inst/Src", 2.0 * corners + [0, 0, 10.0])):
        tris = s.triangles[s.object_ids == s.object_names.index(name)]
        assert len(tris) == 12
        np.testing.assert_allclose(unique_rows(tris), unique_rows(expected), atol=1e-5)


def test_vertex_instancing_many_copies():
    scene = reset()
    add_camera(scene)
    child = add_cube(scene, "Child", size=0.2)
    points = bpy.data.meshes.new("Points")
    positions = [(float(i), float(i % 3), 0.0) for i in range(40)]
    points.from_pydata(positions, [], [])
    parent = bpy.data.objects.new("Parent", points)
    scene.collection.objects.link(parent)
    child.parent = parent
    parent.instance_type = "VERTS"
    s = export()
    # 40 copies; the original child and the (face-less) parent are not rendered.
    assert len(s.triangles) == 40 * 12
    assert s.stats["meshes_read"] == 1
    centres = unique_rows(s.triangles.reshape(40, 12 * 3, 3).mean(axis=1))
    np.testing.assert_allclose(centres, unique_rows(positions), atol=1e-5)


def test_subdivision_modifier_is_applied():
    scene = reset()
    add_camera(scene)
    cube = add_cube(scene)
    mod = cube.modifiers.new("Subdivision", "SUBSURF")
    mod.levels = 2
    s = export()
    assert len(s.triangles) == 6 * 16 * 2          # 96 quads
    radius = np.linalg.norm(s.triangles.reshape(-1, 3), axis=1)
    assert radius.max() < math.sqrt(3) - 0.1        # the corners were smoothed in
    mod.levels = 1
    assert len(export().triangles) == 6 * 4 * 2


def test_hidden_in_render_is_skipped_and_curve_is_triangulated():
    scene = reset()
    add_camera(scene)
    add_cube(scene, "Shown")
    hidden = add_cube(scene, "Hidden")
    hidden.hide_render = True
    bpy.ops.curve.primitive_bezier_circle_add()
    circle = bpy.context.object
    circle.data.dimensions = "2D"
    circle.data.fill_mode = "BOTH"
    red = new_material("Red")
    circle.data.materials.append(red)
    circle.location = (0.0, 0.0, 2.0)
    dg = bpy.context.evaluated_depsgraph_get()
    circle_eval = circle.evaluated_get(dg)
    expected = len(circle_eval.to_mesh().loop_triangles)
    circle_eval.to_mesh_clear()
    s = export_scene(dg)
    assert "Hidden" not in s.object_names
    mine = s.object_ids == s.object_names.index(circle.name)
    # Exactly once: Blender 5 lists the curve object and its mesh (as an instance).
    assert expected > 10 and mine.sum() == expected
    np.testing.assert_allclose(s.triangles[mine][..., 2], 2.0, atol=1e-6)   # a flat disc
    assert np.all(s.material_ids[mine] == s.materials.index(material_of(s, "Red")))
    assert np.sum(s.object_ids == s.object_names.index("Shown")) == 12


def test_nan_location_skips_object_with_warning():
    scene = reset()
    add_camera(scene)
    add_cube(scene, "Good")
    bad = add_cube(scene, "Broken")
    bad.location = (float("nan"), 0.0, 0.0)
    s = export()
    assert len(s.triangles) == 12
    assert s.object_names == ["Good"]
    assert np.all(np.isfinite(s.triangles))
    msgs = [w for w in s.warnings if "'Broken'" in w]
    assert len(msgs) == 1 and "not finite" in msgs[0] and "12 triangles" in msgs[0]


def add_curves(scene, name, strands, radius=None, poly=False, materials=()):
    """A Curves object: ``strands`` a list of (n, 3) point arrays; ``radius`` per point (one
    value for all), or None for no radius attribute."""
    data = bpy.data.hair_curves.new(name)
    data.add_curves([len(p) for p in strands])
    points = np.concatenate(strands).astype(np.float32)
    data.position_data.foreach_set("vector", points.reshape(-1))
    if radius is not None:
        if "radius" not in data.attributes:
            data.attributes.new("radius", "FLOAT", "POINT")
        data.attributes["radius"].data.foreach_set("value", np.full(len(points), radius,
                                                                   np.float32))
    elif "radius" in data.attributes:
        data.attributes.remove(data.attributes["radius"])
    if poly:                       # (Blender 4.2 has no set_types: callers check)
        data.set_types(type="POLY")
    for mat in materials:
        data.materials.append(mat)
    obj = bpy.data.objects.new(name, data)
    scene.collection.objects.link(obj)
    return obj


def test_hair_curves_render_as_tubes_as_cycles_reads_them():
    """A Curves object becomes tubes (engine/hair.py) around its control points: the radius
    attribute, or Cycles' 0.005 m without one; every curve with the first material, as
    Cycles' sync_hair; poly curves as straight pieces; Rounded Ribbons reported."""
    scene = reset()
    add_camera(scene)
    red, blue = new_material("Red"), new_material("Blue")
    straight = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    bent = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 1.0], [2.0, 0.0, 1.5]])
    plain = add_curves(scene, "Plain", [straight], materials=(red, blue))
    plain.location = (-3.0, 0.0, 0.0)
    tinted = new_material("Tinted")              # reads a colour attribute hair lacks
    attribute = tinted.node_tree.nodes.new("ShaderNodeVertexColor")
    tinted.node_tree.links.new(attribute.outputs["Color"], principled(tinted).inputs["Base Color"])
    add_curves(scene, "Thick", [bent], radius=0.02, materials=(tinted,))
    has_poly = hasattr(bpy.types.Curves, "set_types")       # Blender 4.3 on
    if has_poly:
        add_curves(scene, "Poly", [bent], radius=0.02, poly=True).location = (0.0, 3.0, 0.0)
    scene.cycles_curves.shape = "THICK"
    s = export()
    assert not [w for w in s.warnings if "curves" in w.lower() or "ribbon" in w.lower()], \
        s.warnings
    for name in ("Plain", "Thick", "Poly") if has_poly else ("Plain", "Thick"):
        assert np.sum(s.object_ids == s.object_names.index(name)) > 0, name
    assert [w for w in s.warnings if w.startswith("Hair ('Plain', 'Thick'")]   # dense hair
    said = [w for w in s.warnings if "which hair does not carry" in w]
    assert len(said) == 1 and "'Thick'" in said[0] and "'Tinted' reads color" in said[0]
    plain_tris = s.triangles[s.object_ids == s.object_names.index("Plain")]
    assert np.all(s.material_ids[s.object_ids == s.object_names.index("Plain")]
                  == s.materials.index(material_of(s, "Red")))
    across = np.hypot(plain_tris[..., 0] + 3.0, plain_tris[..., 1])
    widen = (math.pi / 6) / math.sin(math.pi / 6)
    assert across.max() == pytest.approx(0.005 * widen, rel=1e-4)
    # The spline bends between the points, the poly curve does not: three rings, 2 pieces.
    thick = np.sum(s.object_ids == s.object_names.index("Thick"))
    assert thick > 2 * 6 * 2 + 2 * 4
    if has_poly:
        assert np.sum(s.object_ids == s.object_names.index("Poly")) == 2 * 6 * 2 + 2 * 4
    # Blender's default shape (Rounded Ribbons) is drawn as 3D curves, and said.
    scene.cycles_curves.shape = "RIBBONS"
    s = export()
    said = [w for w in s.warnings if "Rounded Ribbons" in w]
    assert len(said) == 2 + has_poly and "'Plain'" in said[0]


def test_particle_hair_renders_as_tubes_as_cycles_reads_it():
    """A hair particle system: every strand's keys from co_hair (2^steps + 1 of them), radius
    Radius Scale / 2 x Root at the root, closed at the tip, the system's material slot; off
    with its modifier's render switch."""
    scene = reset()
    add_camera(scene)
    cube = add_cube(scene, "Furry")
    cube.data.materials.append(new_material("Skin"))
    cube.data.materials.append(new_material("Fur"))
    modifier = cube.modifiers.new("Fur", "PARTICLE_SYSTEM")
    settings = modifier.particle_system.settings
    settings.type, settings.count, settings.hair_length = "HAIR", 10, 0.5
    settings.radius_scale, settings.root_radius, settings.material = 0.02, 1.0, 2
    settings.display_step = settings.render_step = 2
    s = export()
    assert not [w for w in s.warnings if "not rendered" in w]
    assert [w for w in s.warnings if w.startswith("Hair ('Furry')")]
    mine = s.object_ids == s.object_names.index("Furry")
    fur = mine & (s.material_ids == s.materials.index(material_of(s, "Fur")))
    assert np.sum(mine & ~fur) == 12                       # the cube itself, in Skin
    keys = 2 ** 2 + 1
    dg = bpy.context.evaluated_depsgraph_get()
    evaluated = cube.evaluated_get(dg)
    system = evaluated.particle_systems[0]
    roots = np.array([system.co_hair(evaluated, particle_no=i, step=0) for i in range(10)])
    tips = np.array([system.co_hair(evaluated, particle_no=i, step=keys - 1) for i in range(10)])
    corners = s.triangles[fur].reshape(-1, 3).astype(np.float64)
    widen = (math.pi / 6) / math.sin(math.pi / 6)
    for root, tip in zip(roots, tips):
        near_root = np.linalg.norm(corners - root, axis=1)
        assert near_root.min() == pytest.approx(0.01 * widen, rel=1e-3)     # the root's ring
        assert np.linalg.norm(corners - tip, axis=1).min() < 1e-6            # closed at the tip
    # Beyond MAX_PARTICLE_KEYS keys one strand in k is read, and said.
    from lanterna.engine.blender import export as export_module
    limit = export_module.MAX_PARTICLE_KEYS
    export_module.MAX_PARTICLE_KEYS = 20                      # 10 strands x 5 keys: 1 in 3
    try:
        fewer = export()
    finally:
        export_module.MAX_PARTICLE_KEYS = limit
    said = [w for w in fewer.warnings if "one strand in 3 is drawn" in w]
    assert len(said) == 1 and "'Furry'" in said[0]
    hair_tris = np.sum(fewer.object_ids == fewer.object_names.index("Furry")) - 12
    assert hair_tris == pytest.approx(np.sum(fur) * 4 / 10, rel=0.05)
    modifier.show_viewport = False
    assert np.sum(export().object_ids == s.object_names.index("Furry")) == 12


# ---------------------------------------------------------------------------------------------
# Materials
# ---------------------------------------------------------------------------------------------
def test_principled_material_values():
    scene = reset()
    add_camera(scene)
    cube = add_cube(scene)
    mat = new_material("Paint")
    p = principled(mat)
    p.inputs["Base Color"].default_value = (0.5, 0.4, 0.3, 1.0)
    p.inputs["Metallic"].default_value = 0.25
    p.inputs["Roughness"].default_value = 0.0
    p.inputs["Emission Color"].default_value = (1.0, 0.5, 0.25, 1.0)
    p.inputs["Emission Strength"].default_value = 3.0
    cube.data.materials.append(mat)
    s = export()
    m = material_of(s, "Paint")
    base = np.array([0.5, 0.4, 0.3])
    np.testing.assert_allclose(m.diffuse, base * 0.75, rtol=1e-6)
    np.testing.assert_allclose(m.specular, base * 0.25, rtol=1e-6)
    np.testing.assert_allclose(m.exitance, math.pi * 3.0 * np.array([1.0, 0.5, 0.25]), rtol=1e-6)
    assert m.emit_both_sides
    assert np.all(s.material_ids == s.materials.index(m))


# Every input of Blender 5.2's Principled BSDF and the closure parameter it lands in: set to a
# value other than the default, each must arrive in the exported closure unchanged.
PRINCIPLED_INPUTS = {
    "Base Color": ("base_color", (0.5, 0.4, 0.3)), "Metallic": ("metallic", 0.3),
    "Roughness": ("roughness", 0.7), "IOR": ("ior", 1.33), "Alpha": ("alpha", 0.9),
    "Thin Wall": ("thin_wall", True), "Diffuse Roughness": ("diffuse_roughness", 0.4),
    "Subsurface Weight": ("subsurface_weight", 0.2),
    "Specular IOR Level": ("specular_ior_level", 0.8),
    "Specular Tint": ("specular_tint", (0.9, 0.8, 0.7)), "Anisotropic": ("anisotropic", 0.6),
    "Anisotropic Rotation": ("anisotropic_rotation", 0.25),
    "Transmission Weight": ("transmission", 0.1), "Coat Weight": ("coat_weight", 0.5),
    "Coat Roughness": ("coat_roughness", 0.2), "Coat IOR": ("coat_ior", 1.6),
    "Coat Tint": ("coat_tint", (0.8, 0.9, 1.0)), "Sheen Weight": ("sheen_weight", 0.3),
    "Sheen Roughness": ("sheen_roughness", 0.6), "Sheen Tint": ("sheen_tint", (0.7, 0.6, 0.5)),
    "Thin Film Thickness": ("thin_film_thickness", 250.0),
    "Thin Film IOR": ("thin_film_ior", 1.45),
}


def test_every_principled_input_reaches_its_closure():
    scene = reset()
    add_camera(scene)
    cube = add_cube(scene)
    mat = new_material("AllInputs")
    p = principled(mat)
    present = {}
    for sock_name, (key, value) in PRINCIPLED_INPUTS.items():
        sock = p.inputs.get(sock_name)
        if sock is None:        # an input this Blender does not have yet (4.2: Thin Wall ...)
            continue
        sock.default_value = (*value, 1.0) if isinstance(value, tuple) else value
        present[key] = value
    p.inputs["Emission Color"].default_value = (1.0, 0.5, 0.25, 1.0)
    p.inputs["Emission Strength"].default_value = 2.0
    cube.data.materials.append(mat)
    s = export()
    # Alpha < 1 mixes a Transparent BSDF in, as Cycles does: weights Alpha and 1 - Alpha.
    closure, transparent = material_of(s, "AllInputs").closures
    assert closure.kind == "principled" and closure.node == p.name
    alpha = present.pop("alpha")
    np.testing.assert_allclose(closure.weight, alpha, rtol=1e-6)
    assert transparent.kind == "transparent" and transparent.node == p.name
    np.testing.assert_allclose(transparent.weight, 1 - alpha, rtol=1e-5)
    assert len(present) >= 17
    for key, value in present.items():
        np.testing.assert_allclose(closure.params[key], value, rtol=1e-6, err_msg=key)
    np.testing.assert_allclose(closure.params["emission"], [2.0, 1.0, 0.5], rtol=1e-6)
    # What the renderer shows differently from Cycles is named (the transparent part's
    # shadows); coat and sheen are rendered, unnamed.
    said = " ".join(w for w in s.warnings if "'AllInputs'" in w)
    assert "Transparent BSDF" in said
    assert "Coat" not in said and "Sheen" not in said


def test_mix_and_add_shaders_flatten_into_weighted_closures():
    scene = reset()
    add_camera(scene)
    mat = new_material("Layered")
    tree = mat.node_tree
    diff = tree.nodes.new("ShaderNodeBsdfDiffuse")
    glossy = tree.nodes.new("ShaderNodeBsdfGlossy")
    glossy.inputs["Roughness"].default_value = 0.2
    glass = tree.nodes.new("ShaderNodeBsdfGlass")
    glass.inputs["IOR"].default_value = 1.45
    mix = tree.nodes.new("ShaderNodeMixShader")
    mix.inputs["Fac"].default_value = 0.3
    add = tree.nodes.new("ShaderNodeAddShader")
    tree.links.new(diff.outputs[0], mix.inputs[1])
    tree.links.new(glossy.outputs[0], mix.inputs[2])
    tree.links.new(mix.outputs[0], add.inputs[0])
    tree.links.new(glass.outputs[0], add.inputs[1])
    set_surface(mat, add)
    add_cube(scene).data.materials.append(mat)
    s = export()
    closures = material_of(s, "Layered").closures
    assert [c.kind for c in closures] == ["diffuse", "glossy", "glass"]
    np.testing.assert_allclose([c.weight[0] for c in closures], [0.7, 0.3, 1.0], rtol=1e-6)
    assert closures[1].params["roughness"] == pytest.approx(0.2)
    assert closures[1].distribution == "MULTI_GGX"
    assert closures[2].params["ior"] == pytest.approx(1.45)


def test_default_principled_is_not_emissive_and_no_material_is_cycles_default():
    """Faces without a material render as Cycles renders them: a Diffuse BSDF of 0.8 in
    Blender 4.2 and 4.5, the default Principled BSDF from 5.0 on (measured with Cycles: a
    sunlit plane without a material matches one with a fresh Principled BSDF there, one with
    a Diffuse BSDF of 0.8 before; ``compat.default_surface_is_principled``). On 5.x the
    plain diffuse had the sunlit ground 5-12 % brighter than Cycles."""
    scene = reset()
    add_camera(scene)
    plain = add_cube(scene, "Plain")
    painted = add_cube(scene, "Painted")
    painted.data.materials.append(new_material("Fresh"))
    s = export()
    fresh = material_of(s, "Fresh")
    np.testing.assert_allclose(fresh.diffuse, 0.8, rtol=1e-6)     # Base Color default
    np.testing.assert_allclose(fresh.exitance, 0.0)                # Emission Strength 0
    default = material_of(s, "Default")
    np.testing.assert_allclose(default.diffuse, 0.8, rtol=1e-6)
    np.testing.assert_allclose(default.specular, 0.0)
    if bpy.app.version >= (5, 0, 0):
        (mine,), (theirs,) = default.closures, fresh.closures
        assert mine.kind == theirs.kind == "principled"
        assert mine.distribution == theirs.distribution
        assert set(mine.params) == set(theirs.params)
        for key, value in theirs.params.items():
            np.testing.assert_allclose(mine.params[key], value, rtol=1e-6, err_msg=key)
    else:
        assert not default.closures
    plain_ids = s.material_ids[s.object_ids == s.object_names.index(plain.name)]
    assert np.all(plain_ids == s.materials.index(default))


def test_diffuse_emission_mix_and_add_shaders():
    scene = reset()
    add_camera(scene)
    specs = {}

    mat = new_material("Matte")
    node = mat.node_tree.nodes.new("ShaderNodeBsdfDiffuse")
    node.inputs["Color"].default_value = (0.2, 0.6, 0.9, 1.0)
    set_surface(mat, node)
    specs["Matte"] = ([0.2, 0.6, 0.9], [0, 0, 0], [0, 0, 0])

    mat2 = new_material("Lamp")
    node = mat2.node_tree.nodes.new("ShaderNodeEmission")
    node.inputs["Color"].default_value = (1.0, 1.0, 0.5, 1.0)
    node.inputs["Strength"].default_value = 2.0
    set_surface(mat2, node)
    specs["Lamp"] = ([0, 0, 0], [0, 0, 0], [2 * math.pi, 2 * math.pi, math.pi])

    mat3 = new_material("Mixed")
    tree = mat3.node_tree
    diff = tree.nodes.new("ShaderNodeBsdfDiffuse")
    diff.inputs["Color"].default_value = (1.0, 0.0, 0.0, 1.0)
    glossy = tree.nodes.new("ShaderNodeBsdfGlossy")
    glossy.inputs["Color"].default_value = (0.0, 0.0, 0.8, 1.0)
    glossy.inputs["Roughness"].default_value = 0.0
    mix = tree.nodes.new("ShaderNodeMixShader")
    mix.inputs["Fac"].default_value = 0.25
    tree.links.new(diff.outputs[0], mix.inputs[1])
    tree.links.new(glossy.outputs[0], mix.inputs[2])
    set_surface(mat3, mix)
    specs["Mixed"] = ([0.75, 0, 0], [0, 0, 0.2], [0, 0, 0])

    mat4 = new_material("TooBright")
    tree = mat4.node_tree
    diff = tree.nodes.new("ShaderNodeBsdfDiffuse")
    diff.inputs["Color"].default_value = (0.8, 0.8, 0.8, 1.0)
    glossy = tree.nodes.new("ShaderNodeBsdfGlossy")
    glossy.inputs["Color"].default_value = (0.6, 0.6, 0.0, 1.0)
    glossy.inputs["Roughness"].default_value = 0.0
    add = tree.nodes.new("ShaderNodeAddShader")
    tree.links.new(diff.outputs[0], add.inputs[0])
    tree.links.new(glossy.outputs[0], add.inputs[1])
    set_surface(mat4, add)
    specs["TooBright"] = ([0.8 / 1.4, 0.8 / 1.4, 0.8], [0.6 / 1.4, 0.6 / 1.4, 0.0], [0, 0, 0])

    for i, m in enumerate((mat, mat2, mat3, mat4)):
        obj = add_cube(scene, f"Obj{i}")
        obj.data.materials.append(m)
    s = export()
    for name, (d, sp, e) in specs.items():
        m = material_of(s, name)
        np.testing.assert_allclose(m.diffuse, d, rtol=1e-6, atol=1e-7, err_msg=name)
        np.testing.assert_allclose(m.specular, sp, rtol=1e-6, atol=1e-7, err_msg=name)
        np.testing.assert_allclose(m.exitance, e, rtol=1e-6, atol=1e-7, err_msg=name)
    assert np.all(material_of(s, "TooBright").diffuse + material_of(s, "TooBright").specular
                  <= 1.0 + 1e-9)
    assert sum("'TooBright'" in w and "exceeds 1" in w for w in s.warnings) == 1


def test_a_loop_of_shader_nodes_is_named_in_a_warning():
    """Two Mix Shader nodes feeding each other: Blender marks the link that closes the loop
    invalid and Cycles ignores it; the export did too, without a word (the material came out
    black). Now the warning names the material and both nodes."""
    scene = reset()
    add_camera(scene)
    mat = new_material("Knot")
    tree = mat.node_tree
    first, second = tree.nodes.new("ShaderNodeMixShader"), tree.nodes.new("ShaderNodeMixShader")
    first.name, second.name = "Mix A", "Mix B"
    diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
    tree.links.new(diffuse.outputs[0], first.inputs[2])
    tree.links.new(first.outputs[0], second.inputs[1])
    tree.links.new(second.outputs[0], first.inputs[1])
    set_surface(mat, second)
    cube = add_cube(scene)
    cube.data.materials.append(mat)
    exported = export()
    loops = [w for w in exported.warnings if "closes a loop of nodes" in w]
    assert loops and all("Material 'Knot'" in w for w in loops), exported.warnings
    assert any("'Mix A'" in w and "'Mix B'" in w for w in loops), loops


def test_unsupported_texture_gives_one_warning_and_is_baked():
    """A node outside the evaluator (Brick) on three cubes' material: baked once by Cycles
    through the first cube's UVs (``node_bake``), one warning naming the material, socket,
    node, the fallback and the cubes that share the bake."""
    scene = reset()
    add_camera(scene)
    mat = new_material("Wood")
    p = principled(mat)
    p.inputs["Base Color"].default_value = (0.3, 0.2, 0.1, 1.0)
    tex = mat.node_tree.nodes.new("ShaderNodeTexBrick")     # not in the node evaluator
    mat.node_tree.links.new(tex.outputs["Color"], p.inputs["Base Color"])
    for name in ("Plank1", "Plank2", "Plank3"):
        add_cube(scene, name).data.materials.append(mat)
    s = export()
    wood = [w for w in s.warnings if "Wood" in w and "driven by" in w]
    assert len(wood) == 1       # one per material and socket, not one per object
    assert "Material 'Wood'" in wood[0] and "Base Color" in wood[0] and "Brick" in wood[0]
    assert "baked by Cycles" in wood[0] and "of 'Plank1'" in wood[0], wood[0]
    assert "'Plank2', 'Plank3' read the same image" in wood[0], wood[0]
    np.testing.assert_allclose(material_of(s, "Wood").diffuse, [0.3, 0.2, 0.1], rtol=1e-6)
    assert "base_color" in material_of(s, "Wood").closures[0].textures
    assert len(s.materials) == 1


def test_unsupported_texture_without_uvs_gives_one_warning_and_default_colour():
    scene = reset()
    add_camera(scene)
    mat = new_material("Wood")
    p = principled(mat)
    p.inputs["Base Color"].default_value = (0.3, 0.2, 0.1, 1.0)
    tex = mat.node_tree.nodes.new("ShaderNodeTexBrick")     # not in the node evaluator
    mat.node_tree.links.new(tex.outputs["Color"], p.inputs["Base Color"])
    for name in ("Plank1", "Plank2"):
        cube = add_cube(scene, name)
        cube.data.materials.append(mat)
        while len(cube.data.uv_layers):
            cube.data.uv_layers.remove(cube.data.uv_layers[0])
    s = export()
    wood = [w for w in s.warnings if "Wood" in w and "driven by" in w]
    assert len(wood) == 1
    assert "using its default colour" in wood[0] and "no mesh object" in wood[0], wood[0]
    np.testing.assert_allclose(material_of(s, "Wood").diffuse, [0.3, 0.2, 0.1], rtol=1e-6)
    assert not material_of(s, "Wood").closures[0].textures


def test_image_texture_on_base_color_is_per_hit():
    """An Image Texture on Base Color: no warning, the closure's base_color is node-driven,
    the UV map goes onto the scene and the material's mean is the texture's (a uniform 8-bit
    sRGB image of 0.5, stored as the byte 128: 0.2159 linear)."""
    from lanterna.engine.bsdf import MaterialTable
    scene = reset()
    add_camera(scene)
    mat = new_material("Wood")
    p = principled(mat)
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = bpy.data.images.new("Grey", 2, 2)
    tex.image.pixels.foreach_set(np.full(16, 0.5, np.float32))
    mat.node_tree.links.new(tex.outputs["Color"], p.inputs["Base Color"])
    add_cube(scene, "Plank").data.materials.append(mat)
    s = export()
    assert not [w for w in s.warnings if "Wood" in w and "driven by" in w]
    wood = material_of(s, "Wood")
    assert "base_color" in wood.closures[0].textures and wood.graph is not None
    assert set(s.corner_attributes) == {"uv"}
    assert s.corner_attributes["uv"].shape == (len(s.triangles), 3, 2)
    table = MaterialTable(s)
    mid = s.materials.index(wood)
    np.testing.assert_allclose(table.diffuse[mid], ((128 / 255 + 0.055) / 1.055) ** 2.4, rtol=1e-6)


def test_material_slots_map_per_face():
    scene = reset()
    add_camera(scene)
    cube = add_cube(scene)
    red, blue = new_material("Red"), new_material("Blue")
    principled(red).inputs["Base Color"].default_value = (1, 0, 0, 1)
    principled(blue).inputs["Base Color"].default_value = (0, 0, 1, 1)
    cube.data.materials.append(red)
    cube.data.materials.append(blue)
    z = np.array([p.center.z for p in cube.data.polygons])
    idx = (z > 0.5).astype(np.int32)            # the top face uses slot 1
    cube.data.polygons.foreach_set("material_index", idx)
    cube.data.update()
    s = export()
    top = s.triangles[:, :, 2].min(axis=1) > 0.99
    assert top.sum() == 2
    assert np.all(s.material_ids[top] == s.materials.index(material_of(s, "Blue")))
    assert np.all(s.material_ids[~top] == s.materials.index(material_of(s, "Red")))


def test_lanterna_material_properties_override_nodes():
    created = False
    if not hasattr(bpy.types.Material, "lanterna"):
        class TestMaterialProps(bpy.types.PropertyGroup):
            derive_from_nodes: bpy.props.BoolProperty(default=True)
            diffuse: bpy.props.FloatVectorProperty(size=3, default=(0.8, 0.8, 0.8))
            specular: bpy.props.FloatVectorProperty(size=3, default=(0.0, 0.0, 0.0))
            exitance: bpy.props.FloatVectorProperty(size=3, default=(0.0, 0.0, 0.0))
        bpy.utils.register_class(TestMaterialProps)
        bpy.types.Material.lanterna = bpy.props.PointerProperty(type=TestMaterialProps)
        created = True
    try:
        scene = reset()
        add_camera(scene)
        mat = new_material("Manual")
        mat.lanterna.derive_from_nodes = False
        mat.lanterna.diffuse = (0.1, 0.2, 0.3)
        mat.lanterna.specular = (0.4, 0.3, 0.2)
        mat.lanterna.exitance = (5.0, 6.0, 7.0)
        add_cube(scene).data.materials.append(mat)
        m = material_of(export(), "Manual")
        np.testing.assert_allclose(m.diffuse, [0.1, 0.2, 0.3], rtol=1e-6)
        np.testing.assert_allclose(m.specular, [0.4, 0.3, 0.2], rtol=1e-6)
        np.testing.assert_allclose(m.exitance, [5.0, 6.0, 7.0], rtol=1e-6)
        mat.lanterna.derive_from_nodes = True
        mat.update_tag()            # a viewport depsgraph re-evaluates only tagged IDs
        np.testing.assert_allclose(material_of(export(), "Manual").diffuse, 0.8, rtol=1e-6)
    finally:
        if created:
            del bpy.types.Material.lanterna
            bpy.utils.unregister_class(TestMaterialProps)


# ---------------------------------------------------------------------------------------------
# Lights and world
# ---------------------------------------------------------------------------------------------
def add_light(scene, name, kind, location=(0.0, 0.0, 0.0), rotation=(0.0, 0.0, 0.0)):
    light = bpy.data.lights.new(name, kind)
    obj = bpy.data.objects.new(name, light)
    obj.location = location
    obj.rotation_euler = rotation
    scene.collection.objects.link(obj)
    return light, obj


def test_light_conversion():
    scene = reset()
    add_camera(scene)
    point, point_obj = add_light(scene, "Point", "POINT", location=(1.0, 2.0, 3.0))
    point_obj_visible = point_obj.visible_camera     # as Blender made it
    point.energy = 100.0
    point.color = (1.0, 0.5, 0.25)
    point.shadow_soft_size = 0.0

    spot, _ = add_light(scene, "Spot", "SPOT", location=(0, 0, 4), rotation=(math.pi / 2, 0, 0))
    spot.energy = 40.0
    spot.spot_size = 1.0
    spot.spot_blend = 0.3
    spot.shadow_soft_size = 0.1
    if hasattr(spot, "exposure"):               # Blender 4.3+: x 2
        spot.exposure = 1.0
    else:
        spot.energy = 80.0

    sun, _ = add_light(scene, "Sun", "SUN", rotation=(0.0, math.pi / 2, 0.0))
    sun.energy = 3.0
    sun.angle = 0.1
    sun.color = (0.5, 1.0, 1.0)

    area, area_obj = add_light(scene, "Area", "AREA", location=(0, 0, 2))
    area.shape = "RECTANGLE"
    area.size = 2.0
    area.size_y = 0.5
    area.energy = 50.0
    area.spread = 0.0
    area_obj.scale = (1.0, 2.0, 1.0)

    disk, disk_obj = add_light(scene, "Disk", "AREA", location=(0, 0, 3))
    disk_obj.visible_camera = True              # Visibility > Camera (off for a new light)
    disk.shape = "DISK"
    disk.size = 1.0
    disk.energy = 10.0
    disk.spread = math.radians(90)
    has_normalize = hasattr(disk, "normalize")  # Blender 4.3+
    if has_normalize:
        disk.normalize = False

    dark, _ = add_light(scene, "Dark", "POINT")
    dark.energy = 0.0

    s = export()
    lights = {l.name: l for l in s.lights}
    assert set(lights) == {"Point", "Spot", "Sun", "Area", "Disk"}

    p = lights["Point"]
    assert isinstance(p, PointLight)
    np.testing.assert_allclose(p.position, [1, 2, 3], atol=1e-6)
    np.testing.assert_allclose(p.flux, [100, 50, 25], rtol=1e-6)
    assert not any("'Point'" in w for w in s.warnings)

    sp = lights["Spot"]
    assert isinstance(sp, SpotLight)
    np.testing.assert_allclose(sp.direction, [0, 1, 0], atol=1e-6)   # -Z turned by X 90 deg
    np.testing.assert_allclose(sp.position, [0, 0, 4], atol=1e-6)
    np.testing.assert_allclose(sp.flux, 80.0, rtol=1e-6)
    assert sp.half_angle == pytest.approx(0.5, rel=1e-6)
    assert sp.blend == pytest.approx(0.3, rel=1e-6)
    assert sp.radius == pytest.approx(0.1, rel=1e-6)        # a sphere light, no warning
    assert sp.soft_falloff == bool(getattr(spot, "use_soft_falloff", True))
    assert not any("'Spot'" in w for w in s.warnings)
    assert p.radius == 0.0

    su = lights["Sun"]
    assert isinstance(su, SunLight)
    np.testing.assert_allclose(su.direction, [-1, 0, 0], atol=1e-6)  # -Z turned by Y 90 deg
    np.testing.assert_allclose(su.irradiance, [1.5, 3.0, 3.0], rtol=1e-6)
    assert su.angle == pytest.approx(0.1, rel=1e-6)

    ar = lights["Area"]
    assert isinstance(ar, AreaLight)
    assert ar.shape == "RECTANGLE" and ar.collimated
    assert (ar.size_x, ar.size_y) == pytest.approx((2.0, 0.5))
    np.testing.assert_allclose(ar.power, 50.0, rtol=1e-6)
    assert ar.area == pytest.approx(2.0 * 0.5 * 2.0, rel=1e-6)   # object scale applied
    np.testing.assert_allclose(ar.normal, [0, 0, -1], atol=1e-6)
    np.testing.assert_allclose(ar.center, [0, 0, 2], atol=1e-6)

    dk = lights["Disk"]
    assert dk.shape == "DISK" and not dk.collimated
    # Normalize off: Power is per square metre of the light.
    np.testing.assert_allclose(dk.power, 10.0 * math.pi * 0.25 if has_normalize else 10.0,
                               rtol=1e-6)
    assert any("'Disk'" in w and "Spread 90" in w for w in s.warnings)
    assert dk.camera_visible and not ar.camera_visible
    assert p.camera_visible == point_obj_visible


def light_emission_node(light):
    """The Emission node of a light's tree (Blender 5.1+: always there; before: made by Use
    Nodes, which compat.ensure_node_tree switches on)."""
    return next(n for n in compat.ensure_node_tree(light).nodes if n.type == "EMISSION")


def test_light_node_tree_read_as_cycles_reads_it():
    scene = reset()
    add_camera(scene)
    plain, _ = add_light(scene, "Plain", "POINT")          # the default tree (or none)
    plain.energy, plain.shadow_soft_size = 100.0, 0.0
    default, _ = add_light(scene, "Default", "POINT")      # the default tree, switched on
    default.energy, default.shadow_soft_size = 100.0, 0.0
    light_emission_node(default)
    strong, _ = add_light(scene, "Strong", "POINT")        # Emission strength 2, a colour
    strong.energy, strong.shadow_soft_size = 100.0, 0.0
    strong.color = (1.0, 0.8, 0.5)
    em = light_emission_node(strong)
    em.inputs["Strength"].default_value = 2.0
    em.inputs["Color"].default_value = (1.0, 0.5, 0.25, 1.0)
    area, _ = add_light(scene, "Panel", "AREA", location=(0, 0, 2))
    area.energy = 10.0
    em = light_emission_node(area)                          # a constant RGB node: its value
    rgb = area.node_tree.nodes.new("ShaderNodeRGB")
    rgb.outputs[0].default_value = (0.5, 0.5, 1.0, 1.0)
    area.node_tree.links.new(rgb.outputs[0], em.inputs["Color"])

    s = export()
    lights = {l.name: l for l in s.lights}
    np.testing.assert_allclose(lights["Plain"].flux, 100.0, rtol=1e-6)
    np.testing.assert_allclose(lights["Default"].flux, 100.0, rtol=1e-6)
    # Twice the power, in the node's colour times the light's.
    np.testing.assert_allclose(lights["Strong"].flux, [200.0, 80.0, 25.0], rtol=1e-6)
    np.testing.assert_allclose(lights["Panel"].power, [5.0, 5.0, 10.0], rtol=1e-6)
    assert [w for w in s.warnings if w.startswith("Light ")] == []      # all read exactly

    # Anything else warns, naming the light and the node.
    bb = strong.node_tree.nodes.new("ShaderNodeBlackbody")
    strong.node_tree.links.new(bb.outputs[0], light_emission_node(strong).inputs["Color"])
    diffuse = default.node_tree.nodes.new("ShaderNodeBsdfDiffuse")
    out = next(n for n in default.node_tree.nodes if n.type == "OUTPUT_LIGHT")
    default.node_tree.links.new(diffuse.outputs[0], out.inputs["Surface"])
    s = export()
    lights = {l.name: l for l in s.lights}
    light_warnings = [w for w in s.warnings if w.startswith("Light ")]
    assert len(light_warnings) == 2, light_warnings
    assert any("Light 'Strong'" in w and "Blackbody" in w and "'Emission'" in w
               for w in light_warnings), light_warnings
    assert any("Light 'Default'" in w and "Diffuse BSDF node 'Diffuse BSDF'" in w
               for w in light_warnings), light_warnings
    np.testing.assert_allclose(lights["Strong"].flux, [200.0, 80.0, 25.0], rtol=1e-6)
    np.testing.assert_allclose(lights["Default"].flux, 100.0, rtol=1e-6)   # Color x Power

    # Nothing at the Light Output: Cycles gives the light no emission; so does the export.
    for link in list(default.node_tree.links):
        if link.to_node == out:
            default.node_tree.links.remove(link)
    s = export()
    assert "Default" not in {l.name for l in s.lights}
    assert any("Light 'Default'" in w and "the light is dark" in w for w in s.warnings)


def test_light_node_tree_off_where_use_nodes_still_counts():
    """Blender 4.2 to 5.0: a light's tree counts only with Use Nodes on (5.1+: always)."""
    scene = reset()
    add_camera(scene)
    light, _ = add_light(scene, "Lamp", "POINT")
    light.energy, light.shadow_soft_size = 100.0, 0.0
    light_emission_node(light).inputs["Strength"].default_value = 3.0
    np.testing.assert_allclose(export().lights[0].flux, 300.0, rtol=1e-6)
    if compat.nodes_always_on(light):
        pytest.skip(f"Blender {bpy.app.version_string}: light nodes are always on")
    light.use_nodes = False
    np.testing.assert_allclose(export().lights[0].flux, 100.0, rtol=1e-6)


def test_no_deprecated_blender_api_from_lanterna():
    """Under a Blender that deprecates ``use_nodes`` (materials and worlds from 5.0, lights from
    5.1), exporting lights, a world and materials, and making node trees, warns nothing from
    Lanterna's own modules; reading ``use_nodes`` there would (the control below)."""
    import warnings

    import lanterna

    scene = reset()
    add_camera(scene)
    for kind in ("POINT", "SPOT", "SUN", "AREA"):
        light, _ = add_light(scene, kind.title(), kind, location=(0, 0, 3))
        light.energy = 10.0
    world = bpy.data.worlds.new("World")
    compat.ensure_node_tree(world)
    scene.world = world
    add_cube(scene)
    mat = new_material("Painted")
    bpy.context.object.data.materials.append(mat)
    plain = bpy.data.materials.new("Plain")
    own = os.path.dirname(lanterna.__file__)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        s = export()
        for block in (mat, plain, world, *bpy.data.lights):
            compat.ensure_node_tree(block)
            compat.uses_nodes(block)
        compat.nodes_always_on(bpy.data.lights[0])
        from lanterna.engine.blender.export import material_from_nodes
        material_from_nodes(plain)
    assert len(s.lights) == 4 and not s.world.is_black
    ours = [f"{w.filename}:{w.lineno}: {w.message}" for w in caught
            if issubclass(w.category, DeprecationWarning) and w.filename.startswith(own)
            and not w.filename.startswith(os.path.join(own, "tests"))]
    assert ours == []
    # Control: the deprecated property itself warns where Blender deprecates it.
    light = bpy.data.lights[0]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        light.use_nodes
    deprecated = [w for w in caught if issubclass(w.category, DeprecationWarning)]
    assert bool(deprecated) == compat.nodes_always_on(light)


def test_deprecation_warnings_of_lanterna_fail_the_suite_and_blenders_do_not():
    """pyproject's filterwarnings: a DeprecationWarning from Lanterna's modules is an error in
    every test, one from Blender's own modules (or a test's) is not."""
    import warnings

    with pytest.raises(DeprecationWarning):
        warnings.warn_explicit("old API", DeprecationWarning, "export.py", 1,
                               module="lanterna.engine.blender.export")
    with warnings.catch_warnings(record=True) as caught:
        warnings.warn_explicit("old API", DeprecationWarning, "bpy_types.py", 1,
                               module="bpy_types")
        warnings.warn_explicit("old API", DeprecationWarning, "addon_utils.py", 1,
                               module="addon_utils")
    assert len(caught) == 2


def test_world_colour():
    scene = reset()
    add_camera(scene)
    assert export().world.is_black                 # no world
    world = bpy.data.worlds.new("World")            # Blender 5: Background node, grey 0.05
    compat.ensure_node_tree(world)                  # 4.2, 4.5: the same, switched on
    scene.world = world
    np.testing.assert_allclose(export().world.radiance, 0.05, rtol=1e-6)
    bg = next(n for n in world.node_tree.nodes if n.type == "BACKGROUND")
    bg.inputs["Color"].default_value = (0.2, 0.4, 0.6, 1.0)
    bg.inputs["Strength"].default_value = 2.0
    np.testing.assert_allclose(export().world.radiance, [0.4, 0.8, 1.2], rtol=1e-6)
    # A Sky Texture is Blender's sky baked by Cycles into an image world (issue 24); the
    # Background's Strength scales it (the second export reads the cached bake).
    sky = world.node_tree.nodes.new("ShaderNodeTexSky")
    world.node_tree.links.new(sky.outputs[0], bg.inputs["Color"])
    s = export()
    assert s.world.environment is not None and not s.warnings, s.warnings
    assert np.all(s.world.radiance > 0)
    bg.inputs["Strength"].default_value = 1.0
    np.testing.assert_allclose(export().world.radiance, s.world.radiance / 2, rtol=1e-6)
    # Anything else on the colour: the flat colour, with a warning naming world and node.
    gamma = world.node_tree.nodes.new("ShaderNodeGamma")
    world.node_tree.links.new(sky.outputs[0], gamma.inputs["Color"])
    world.node_tree.links.new(gamma.outputs[0], bg.inputs["Color"])
    s = export()
    assert s.world.environment is None
    np.testing.assert_allclose(s.world.radiance, [0.2, 0.4, 0.6], rtol=1e-6)
    assert sum("World 'World'" in w and "Gamma" in w for w in s.warnings) == 1


# ---------------------------------------------------------------------------------------------
# Camera
# ---------------------------------------------------------------------------------------------
def project(camera, points):
    """Frame coordinates (0..1, y up) of world points through the exported camera."""
    inv = np.linalg.inv(camera.matrix)
    pc = np.c_[points, np.ones(len(points))] @ inv.T
    x, y = pc[:, 0] / -pc[:, 2], pc[:, 1] / -pc[:, 2]
    u = ((x - camera.shift_x) / camera.tan_half_x + 1) / 2
    v = ((y - camera.shift_y) / camera.tan_half_y + 1) / 2
    return np.c_[u, v]


@pytest.mark.parametrize("res, fit, aspect", [
    ((1920, 1080), "AUTO", (1.0, 1.0)),
    ((800, 1200), "AUTO", (1.0, 1.0)),
    ((800, 1200), "HORIZONTAL", (1.0, 1.0)),
    ((1920, 1080), "VERTICAL", (1.0, 1.0)),
    ((640, 480), "AUTO", (1.0, 2.0)),             # non-square pixels: taller than wide
    ((640, 480), "VERTICAL", (3.0, 2.0)),
])
def test_camera_matches_world_to_camera_view(res, fit, aspect):
    scene = reset()
    cam = add_camera(scene, location=(1.0, -8.0, 3.0), rotation=(1.2, 0.1, 0.3))
    cam.scale = (1.5, 1.5, 1.5)                     # ignored by Blender's projection
    cam.data.lens = 35.0
    cam.data.sensor_width = 36.0
    cam.data.sensor_height = 20.0
    cam.data.sensor_fit = fit
    cam.data.shift_x = 0.2
    cam.data.shift_y = -0.15
    scene.render.resolution_x, scene.render.resolution_y = res
    scene.render.resolution_percentage = 50
    scene.render.pixel_aspect_x, scene.render.pixel_aspect_y = aspect
    s = export()
    c = s.camera
    assert c.resolution == (res[0] // 2, res[1] // 2)
    assert c.clip_start == pytest.approx(cam.data.clip_start)
    assert c.clip_end == pytest.approx(cam.data.clip_end)
    rng = np.random.default_rng(1)
    cam_m = np.array(cam.matrix_world.normalized())
    local = np.c_[rng.uniform(-3, 3, (20, 2)), rng.uniform(-9, -2, 20)]
    points = local @ cam_m[:3, :3].T + cam_m[:3, 3]
    ours = project(c, points)
    theirs = np.array([world_to_camera_view(scene, cam, Vector(p))[:2] for p in points])
    np.testing.assert_allclose(ours, theirs, atol=1e-5)
    assert np.ptp(theirs[:, 0]) > 0.5               # the points spread over the frame


@pytest.mark.parametrize("res, fit", [((640, 400), "AUTO"), ((400, 640), "AUTO"),
                                      ((640, 400), "VERTICAL")])
def test_orthographic_camera_matches_world_to_camera_view(res, fit):
    from lanterna.engine.passes import project_to_window

    scene = reset()
    cam = add_camera(scene, location=(1.0, -8.0, 3.0), rotation=(1.2, 0.1, 0.3))
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = 7.5
    cam.data.sensor_fit = fit
    cam.data.shift_x, cam.data.shift_y = 0.2, -0.15
    scene.render.resolution_x, scene.render.resolution_y = res
    scene.render.resolution_percentage = 10
    c = export().camera
    assert c.orthographic and not any("orthographic" in w for w in export().warnings)
    rng = np.random.default_rng(2)
    cam_m = np.array(cam.matrix_world.normalized())
    local = np.c_[rng.uniform(-3, 3, (40, 2)), rng.uniform(-9, -2, 40)]
    points = local @ cam_m[:3, :3].T + cam_m[:3, 3]
    theirs = np.array([world_to_camera_view(scene, cam, Vector(p))[:2] for p in points])
    w, h = c.resolution
    pixel, depth = project_to_window(c, points)
    inside = (theirs[:, 0] > 0) & (theirs[:, 0] < 1) & (theirs[:, 1] > 0) & (theirs[:, 1] < 1)
    assert inside.sum() > 10
    expected = np.where(inside, (np.floor((1 - theirs[:, 1]) * h) * w
                                 + np.floor(theirs[:, 0] * w)), -1).astype(int)
    # Blender's projection and ours agree to the pixel (points within 1e-4 of a pixel edge
    # may fall either side).
    frac = np.abs(np.c_[theirs[:, 0] * w, theirs[:, 1] * h] % 1 - 0.5)
    clear = np.all(frac < 0.4999, axis=1)
    np.testing.assert_array_equal(pixel[clear], expected[clear])
    np.testing.assert_allclose(depth, -local[:, 2], rtol=1e-6)


def test_depth_of_field_is_read_as_cycles_reads_it():
    scene = reset()
    cam = add_camera(scene)                      # at (0, -10, 0) looking along +y
    dof = cam.data.dof
    cam.data.lens = 40.0
    assert export().camera.aperture_radius == 0.0          # depth of field off
    dof.use_dof = True
    dof.aperture_fstop = 2.0
    dof.focus_distance = 6.5
    dof.aperture_blades = 0                     # a round lens (Blender makes 1 and 2 into 3)
    dof.aperture_rotation = 0.4
    dof.aperture_ratio = 1.5
    c = export().camera
    assert c.aperture_radius == pytest.approx(0.040 / (2 * 2.0))   # lens [m] / (2 F-stop)
    assert c.focus_distance == pytest.approx(6.5)
    assert c.aperture_blades == 0 and c.aperture_rotation == pytest.approx(0.4)
    assert c.aperture_ratio == pytest.approx(1.5)
    dof.aperture_blades = 7
    assert export().camera.aperture_blades == 7
    # A focus object: its distance along the camera's axis, not along the line of sight.
    target = bpy.data.objects.new("Target", None)
    scene.collection.objects.link(target)
    target.location = (3.0, 2.0, 1.0)
    dof.focus_object = target
    assert export().camera.focus_distance == pytest.approx(12.0)
    # Orthographic: the lens is 1 / (2 F-stop) metres (Cycles' convention).
    cam.data.type = "ORTHO"
    assert export().camera.aperture_radius == pytest.approx(0.25)
    # Nothing can be in focus at distance 0: depth of field off, with a warning.
    dof.focus_object = None
    dof.focus_distance = 0.0
    s = export()
    assert s.camera.aperture_radius == 0.0
    assert sum("Camera 'Camera'" in w and "depth of field is off" in w for w in s.warnings) == 1


def test_panoramic_cameras_equirectangular_read_others_reported():
    scene = reset()
    cam = add_camera(scene)
    cam.data.type = "PANO"
    settings = cam.data
    settings.panorama_type = "EQUIRECTANGULAR"
    settings.longitude_min, settings.latitude_max = -2.0, 1.2
    s = export()
    c = s.camera
    assert c.panorama == "EQUIRECTANGULAR" and not s.warnings
    assert (c.longitude_min, c.latitude_max) == pytest.approx((-2.0, 1.2))
    assert (c.longitude_max, c.latitude_min) == pytest.approx((math.pi, -math.pi / 2))
    cam.data.shift_x = 0.1
    assert any("shift of a panoramic camera" in w for w in export().warnings)
    settings.panorama_type = "MIRRORBALL"
    s = export()
    assert not s.camera.panorama
    assert any("Camera 'Camera'" in w and "MIRRORBALL" in w and "perspective" in w
               for w in s.warnings)


def test_visibility_flags_lanterna_does_not_follow_are_named():
    scene = reset()
    add_camera(scene)
    cube = add_cube(scene)
    light, light_obj = add_light(scene, "Lamp", "POINT")
    light.energy = 10.0
    assert not any("Visibility" in w or "not supported" in w for w in export().warnings)
    cube.visible_shadow = cube.visible_glossy = False
    cube.is_holdout = True
    light_obj.visible_diffuse = False
    light.use_shadow = False
    warnings = export().warnings
    assert "Object 'Cube': Ray Visibility Glossy, Shadow off is not supported; rendered as " \
        "if on" in warnings
    assert any("Object 'Cube': Holdout is not supported" in w for w in warnings)
    assert any("Object 'Lamp': Ray Visibility Diffuse off" in w for w in warnings)
    assert any("Light 'Lamp': Cast Shadow off is not supported" in w for w in warnings)


def test_border_and_resolution_override():
    scene = reset()
    add_camera(scene)
    r = scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = 640, 480, 50
    assert export().camera.border == (0, 0, 320, 240)
    r.use_border = True
    r.border_min_x, r.border_max_x = 0.127, 0.803
    r.border_min_y, r.border_max_y = 0.2049, 0.9
    # Blender truncates: 40.64 -> 40, 256.96 -> 256, 49.18 -> 49, 216 (checked against a
    # cropped Cycles render of this setup: 216 x 167 pixels).
    assert export().camera.border == (40, 49, 256, 216)
    dg = bpy.context.evaluated_depsgraph_get()
    c = export_scene(dg, resolution=(100, 50)).camera
    assert c.resolution == (100, 50) and c.border == (12, 10, 80, 45)
    c = export_scene(dg, resolution=(100, 50), border=(5, 6, 70, 40)).camera
    assert c.border == (5, 6, 70, 40) and c.window_size == (65, 34)


def test_missing_camera_raises():
    scene = reset()
    add_cube(scene)
    with pytest.raises(SceneError, match="no active camera"):
        export()
    cam = add_camera(scene)
    cam.location = (0.0, float("nan"), 0.0)
    with pytest.raises(SceneError, match="Camera 'Camera'.*not finite"):
        export()


# ---------------------------------------------------------------------------------------------
# Settings
# ---------------------------------------------------------------------------------------------
def test_export_settings():
    scene = reset()
    if not hasattr(bpy.types.Scene, "lanterna"):
        defaults = export_settings(scene)
        assert defaults.samples == RenderSettings.samples
        assert defaults.light_samples == RenderSettings.light_samples
        assert defaults.bounces == RenderSettings.bounces
        assert defaults.threads == os.cpu_count()
    fake = types.SimpleNamespace(lanterna=types.SimpleNamespace(
        samples=64, light_samples=8, bounces=3, seed=7, threads=0))
    st = export_settings(fake)
    assert (st.samples, st.light_samples, st.bounces, st.seed) == (64, 8, 3, 7)
    assert st.threads == os.cpu_count()
    fake.lanterna.threads = 1
    assert export_settings(fake).threads == 1
    # Enum identifiers become the core's names.
    fake.lanterna.mode, fake.lanterna.photon_filter = "PHOTON_MAP", "CONE"
    fake.lanterna.photons, fake.lanterna.photon_k, fake.lanterna.photon_radius = 5000, 20, 0.25
    st = export_settings(fake)
    assert (st.mode, st.photon_filter, st.photons, st.photon_k, st.photon_radius) == \
        ("photon-map", "cone", 5000, 20, 0.25)


def test_mirrored_object_keeps_outward_normals():
    scene = reset()
    add_camera(scene)
    cube = add_cube(scene)
    cube.scale = (-1.0, 2.0, 1.0)
    s = export()
    assert len(s.triangles) == 12
    outward = np.einsum("tij,tj->ti", s.shading_normals.astype(float), s.triangles.mean(axis=1))
    assert np.all(outward > 0)
    np.testing.assert_allclose(unique_rows(s.triangles),
                               unique_rows(cube_corners() * [1.0, 2.0, 1.0]), atol=1e-6)
