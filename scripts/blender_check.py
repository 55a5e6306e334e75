"""Renders a `nelf export vdb` file in Blender's Cycles and compares it with `nelf render`.

Not part of CI (Blender as a Python module is ~950 MB): run it by hand.

    python3 -m venv V && V/bin/pip install bpy==4.5.3
    nelf export vdb head.nelf -o head.vdb --envmap data/envmaps/studio.exr
    nelf render head.nelf --orbit 0,0 --envmap data/envmaps/studio.exr --width 128 --height 128 -o ref.exr
    NELF_BLENDER_SAMPLES=16 V/bin/python scripts/blender_check.py head.vdb ref.exr.render.json ref.exr blender.exr [SHIFT]

The camera is the render record's (an orbit at elevation 0 only: Blender's default camera
orientation, looking along -z with +y up; the file is +y up and not turned). The volume
object is moved by SHIFT voxels on each axis, or X,Y,Z voxels (default -0.5: Cycles samples voxel i at
index i + 1/2, OpenVDB centres it on i). Material and settings as export/README.md says.
Prints the PSNR of the linear RGB (peak 1 and peak = the reference's maximum).
"""

import json
import os
import math
import sys
import time

import bpy
import numpy as np

vdb, record, reference, out = sys.argv[1:5]
shift_arg = sys.argv[5] if len(sys.argv) > 5 else "-0.5"
shift = [float(v) for v in shift_arg.split(",")] * (3 if "," not in shift_arg else 1)
cam = json.load(open(record))["camera"]
rotation = cam["world_to_camera"]["rotation"]
if [[round(v) for v in row] for row in rotation] != [[1, 0, 0], [0, -1, 0], [0, 0, -1]]:
    sys.exit("only orbit cameras at (0, 0) are supported")

bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
bpy.ops.object.volume_import(filepath=vdb)
obj = bpy.context.active_object
volume = obj.data
volume.grids.load()
voxel = volume.grids["density"].matrix_object[0][0]
obj.location = tuple(s * voxel for s in shift)
volume.render.precision = "FULL"
color_name = next(g.name for g in volume.grids if g.data_type == "VECTOR_FLOAT")

material = bpy.data.materials.new("nelf")
material.use_nodes = True
nodes, links = material.node_tree.nodes, material.node_tree.links
for node in list(nodes):
    nodes.remove(node)
output = nodes.new("ShaderNodeOutputMaterial")
principled = nodes.new("ShaderNodeVolumePrincipled")
principled.inputs["Color"].default_value = (0, 0, 0, 1)
principled.inputs["Absorption Color"].default_value = (0, 0, 0, 1)
principled.inputs["Density"].default_value = 1.0
principled.inputs["Density Attribute"].default_value = "density"
density = nodes.new("ShaderNodeAttribute")
density.attribute_name = "density"
clamp = nodes.new("ShaderNodeMath")
clamp.operation = "MAXIMUM"
clamp.inputs[1].default_value = 0.0
color = nodes.new("ShaderNodeAttribute")
color.attribute_name = color_name
links.new(density.outputs["Fac"], clamp.inputs[0])
links.new(clamp.outputs[0], principled.inputs["Emission Strength"])
links.new(color.outputs["Color"], principled.inputs["Emission Color"])
links.new(principled.outputs["Volume"], output.inputs["Volume"])
volume.materials.append(material)

t = cam["world_to_camera"]["translation"]
centre = [-sum(rotation[r][c] * t[r] for r in range(3)) for c in range(3)]
camera = bpy.data.cameras.new("camera")
camera.sensor_fit = "HORIZONTAL"
camera.sensor_width = 36.0
camera.lens = cam["intrinsics"]["fx"] * 36.0 / cam["width"]
camera.shift_x = -(cam["intrinsics"]["cx"] - cam["width"] / 2) / max(cam["width"], cam["height"])
camera.shift_y = (cam["intrinsics"]["cy"] - cam["height"] / 2) / max(cam["width"], cam["height"])
camera.clip_start = 0.01
camera_object = bpy.data.objects.new("camera", camera)
scene.collection.objects.link(camera_object)
camera_object.location = centre
scene.camera = camera_object

scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = int(os.environ.get("NELF_BLENDER_SAMPLES", "16"))
scene.cycles.max_bounces = 0
scene.cycles.volume_bounces = 0
scene.cycles.volume_step_rate = 0.5
scene.cycles.volume_max_steps = 4096
scene.cycles.pixel_filter_type = "GAUSSIAN"
scene.cycles.filter_width = 0.01
scene.render.film_transparent = True
world = bpy.data.worlds.new("black")
world.use_nodes = False
world.color = (0, 0, 0)
scene.world = world
scene.view_settings.view_transform = "Standard"
scene.render.resolution_x = cam["width"]
scene.render.resolution_y = cam["height"]
scene.render.resolution_percentage = 100
scene.render.image_settings.file_format = "OPEN_EXR"
scene.render.image_settings.color_depth = "32"
scene.render.filepath = out
start = time.time()
bpy.ops.render.render(write_still=True)
seconds = time.time() - start


def load(path):
    image = bpy.data.images.load(path)
    return np.array(image.pixels[:], dtype=np.float64).reshape(image.size[1], image.size[0], 4)[..., :3]


ours, blender = load(reference), load(out)
mse = ((ours - blender) ** 2).mean()
print(f"Cycles {seconds:.2f} s; shift {shift} voxel; PSNR {10 * math.log10(1 / mse):.2f} dB (peak 1), "
      f"{10 * math.log10(ours.max() ** 2 / mse):.2f} dB (peak {ours.max():.4f})")
