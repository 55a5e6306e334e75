"""The add-on inside Blender (4.2+; checked with bpy 4.5.3 as a Python module), without
rendering: registration, the import operator, relighting by operator and automatically,
the rank slider, the colour-grid switch and the errors a user sees. Run by hand (bpy is
about 950 MB, not in CI):

    V/bin/python export/blender/tests/addon_in_blender.py HEAD.vdb

HEAD.vdb is any `nelf export vdb` file. Prints one line per check and exits 1 on the first
failure.
"""

import math
import os
import sys
import tempfile

import bpy
import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
import nelf_relight  # noqa: E402

vdb = os.path.abspath(sys.argv[1])
failures = 0


def check(what, ok, detail=""):
    global failures
    print(f"{'ok  ' if ok else 'FAIL'} {what}{': ' + detail if detail else ''}", flush=True)
    if not ok:
        failures += 1


def terms(obj):
    nodes = bpy.data.materials[nelf_relight.MATERIAL_PREFIX + obj.name].node_tree.nodes
    p_mean = tuple(nodes[nelf_relight.P_MEAN_NODE].inputs[0].default_value)
    p = [tuple(n.inputs[0].default_value) for n in nodes if n.name.startswith("nelf_P_") and n.name != nelf_relight.P_MEAN_NODE]
    # Grids of three components (`nelf export vdb --pca-grids vec3`): three dot products each.
    p += [tuple(n.inputs[1].default_value) for n in nodes if n.name.startswith("nelf_P3_")]
    return p_mean, p


def expected_terms(rank):
    return rank if asset.components_per_grid == 1 else 3 * -(-rank // 3)


def world_with_image(name, pixels, width, height, z_deg=0.0):
    image = bpy.data.images.new(name, width, height, float_buffer=True)
    image.pixels.foreach_set(pixels.astype(np.float32).ravel())
    world = bpy.data.worlds.new(name)
    world.use_nodes = True
    nodes, links = world.node_tree.nodes, world.node_tree.links
    env = nodes.new("ShaderNodeTexEnvironment")
    env.image = image
    mapping = nodes.new("ShaderNodeMapping")
    mapping.inputs["Rotation"].default_value = (0, 0, math.radians(z_deg))
    coords = nodes.new("ShaderNodeTexCoord")
    links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
    links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    links.new(env.outputs["Color"], nodes["Background"].inputs["Color"])
    return world, mapping


bpy.ops.wm.read_factory_settings(use_empty=True)
nelf_relight.register()
scene = bpy.context.scene

# A world without an image: the import still works and shows the colour grid, with a warning.
scene.world = bpy.data.worlds.new("plain")
result = bpy.ops.import_scene.nelf_vdb(filepath=vdb)
check("import with a world that has no image finishes", "FINISHED" in result, str(result))
obj = bpy.context.view_layer.objects.active
asset = nelf_relight.read_asset(vdb)
check("the object is stood up (+90 deg about X)", abs(obj.rotation_euler.x - math.pi / 2) < 1e-6)
half = 0.5 * asset.voxel_size
check("moved by -1/2 voxel on the asset's axes", np.allclose(tuple(obj.location), (-half, half, -half), atol=1e-9))
check("falls back to the colour grid", obj.nelf.emission == "COLOR", obj.nelf.lighting)
try:
    bpy.ops.object.nelf_relight()
    check("Relight from world without an image is refused", False)
except RuntimeError as err:
    check("Relight from world without an image reports why", "Environment Texture" in str(err), str(err).strip())

# A world with an image: relight by operator.
height, width = 8, 16
sky = np.zeros((height, width, 4))
sky[..., 3] = 1
sky[height // 2 :, :, :3] = (1.0, 0.8, 0.6)  # upper half bright (Blender's rows are bottom-up)
sky[height // 2 :, : width // 4, :3] = (8.0, 6.0, 4.0)  # and a sun on one side, so turning matters
world, mapping = world_with_image("sky", sky, width, height)
scene.world = world
obj.nelf.emission = "RELIT"
p_mean, p = terms(obj)
check("switching to relit builds the terms of every component", len(p) == expected_terms(asset.rank), f"{len(p)} terms, rank {asset.rank}")
check("and relights from the world", any(abs(v) > 0 for v in p_mean), str(p_mean))

# Automatic: turning the world's mapping changes the terms after a depsgraph update. Blender's
# window manager calls depsgraph_update_post handlers after each update; a background
# session does not, so the check calls the add-on's handler as Blender would.
def depsgraph_update():
    bpy.context.view_layer.update()
    nelf_relight._auto_relight(scene, bpy.context.evaluated_depsgraph_get())


before = terms(obj)
mapping.inputs["Rotation"].default_value = (0, 0, math.radians(90))
depsgraph_update()
after = terms(obj)
check("turning the world relights automatically", before != after)
obj.nelf.auto_update = False
mapping.inputs["Rotation"].default_value = (0, 0, math.radians(180))
depsgraph_update()
check("with Auto off it does not", terms(obj) == after)
bpy.ops.object.nelf_relight()
check("and Relight from world does", terms(obj) != after)
obj.nelf.auto_update = True
obj.rotation_euler.z = math.radians(30)
before = terms(obj)
depsgraph_update()
check("turning the object relights automatically", terms(obj) != before)

# Rank slider.
obj.nelf.rank = 3
check("rank 3 keeps three components", len(terms(obj)[1]) == expected_terms(min(3, asset.rank)))
obj.nelf.rank = asset.rank

# A file that is not ours: a clear error in the report, nothing imported.
with tempfile.NamedTemporaryFile(suffix=".vdb", delete=False) as f:
    f.write(b"not a vdb")
count = len(bpy.data.objects)
try:
    bpy.ops.import_scene.nelf_vdb(filepath=f.name)
    check("a file that is not OpenVDB is refused", False)
except RuntimeError as err:
    check("a file that is not OpenVDB is refused with the reason", "not an OpenVDB file" in str(err), str(err).strip())
check("and nothing is imported", len(bpy.data.objects) == count)
os.unlink(f.name)

nelf_relight.unregister()
check("unregisters", not hasattr(bpy.types.Object, "nelf"))
sys.stdout.flush()
os._exit(1 if failures else 0)
