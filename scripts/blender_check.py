"""Imports a `.nelf` asset into Blender with the add-on (export/blender/nelf_relight),
relights it under three worlds and renders it with Cycles, beside `nelf render` under the
same maps: the check behind export/BLENDER.md. Not part of CI (Blender as a Python module
is about 950 MB): run it by hand or in a slow job.

    python3 -m venv V && V/bin/pip install bpy==4.5.3
    cargo build --release
    V/bin/python scripts/blender_check.py ASSET.nelf OUT_DIR [options]

Options (KEY=VALUE):
  maps=studio:0,forest:0,interior:90   world maps of data/envmaps and the world's Mapping
                                        Z rotation in degrees (one per relit render)
  size=256  samples=16  orbit=AZ,EL     image size, Cycles samples, camera (nelf render --orbit)
  fov=30                                the camera's horizontal field of view, degrees
  shift=-0.5 or X,Y,Z                   the object's offset in voxels along the asset's axes
  nelf=target/release/nelf  rank=K      the nelf binary; components kept (default all)
  pca_grids=vec3                        nelf export vdb --pca-grids (vec3 or float)
  scene=1                               also renders the head in front of the world (screenshots)
  pixel_grid=N                          compare pixel means (Cycles' 1-pixel box filter, nelf render --pixel-grid N)
                                        instead of one ray through each pixel centre
  only=color|relit  interp=LINEAR|CUBIC  seed=N   one kind only; the material's volume interpolation; Cycles' seed

For the first map it also checks the exported colour grid. Prints one JSON line per render:
linear PSNR (peak 1) of the whole image and of the foreground (nelf render's alpha > 0.5),
render and import seconds, and the nelf render --rotate-deg the world corresponds to.
Images go to OUT_DIR (ref_*.exr, blender_*.exr, and PNG previews).
"""

import json
import math
import os
import subprocess
import sys
import time

import bpy
import mathutils
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "export", "blender"))
import nelf_relight  # noqa: E402
from nelf_relight import relight  # noqa: E402

asset_path, out_dir = os.path.abspath(sys.argv[1]), os.path.abspath(sys.argv[2])
options = dict(arg.split("=", 1) for arg in sys.argv[3:])
maps = [(m.split(":")[0], float(m.split(":")[1])) for m in options.get("maps", "studio:0,forest:0,interior:90").split(",")]
size = int(options.get("size", "256"))
samples = int(options.get("samples", "16"))
orbit = options.get("orbit", "0,0")
fov = options.get("fov", "30")
shift_arg = options.get("shift", "-0.5")
shift = [float(v) for v in shift_arg.split(",")] * (3 if "," not in shift_arg else 1)
nelf = os.path.abspath(options.get("nelf", os.path.join(ROOT, "target", "release", "nelf")))
rank = options.get("rank")
scene_shots = options.get("scene", "0") == "1"
only = options.get("only")  # "color" or "relit": skip the other kind
interpolation = options.get("interp", "LINEAR")  # the material's volume interpolation
os.makedirs(out_dir, exist_ok=True)


def run(*args):
    subprocess.run([nelf, *args], check=True, stdout=subprocess.DEVNULL)


def nelf_rotate(beta_deg):
    """nelf render --rotate-deg for a world whose Mapping turns Z by beta (object as imported)."""
    e = relight.env_from_light_in_blender(np.eye(3), relight.BLENDER_FROM_NELF, relight.rotation_to_blender_euler_z(beta_deg))
    return relight.nelf_rotate_deg(e, np.eye(3))


def load(path):
    image = bpy.data.images.load(path, check_existing=False)
    px = np.empty(image.size[0] * image.size[1] * 4, dtype=np.float32)
    image.pixels.foreach_get(px)
    out = px.reshape(image.size[1], image.size[0], 4).astype(np.float64)
    bpy.data.images.remove(image)
    return out


def psnr(a, b, mask=None):
    d = (a[..., :3] - b[..., :3]) ** 2
    mse = d[mask].mean() if mask is not None else d.mean()
    return 10 * math.log10(1 / max(mse, 1e-30))


def set_world(scene, name, beta_deg):
    world = bpy.data.worlds.new(f"{name} {beta_deg:g}")
    world.use_nodes = True
    nodes, links = world.node_tree.nodes, world.node_tree.links
    env = nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(os.path.join(ROOT, "data", "envmaps", f"{name}.exr"), check_existing=True)
    coords = nodes.new("ShaderNodeTexCoord")
    mapping = nodes.new("ShaderNodeMapping")
    mapping.inputs["Rotation"].default_value = (0, 0, math.radians(beta_deg))
    links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
    links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    links.new(env.outputs["Color"], nodes["Background"].inputs["Color"])
    scene.world = world
    return world


def camera_from_record(scene, record):
    cam = record["camera"]
    rotation = np.array(cam["world_to_camera"]["rotation"])
    t = np.array(cam["world_to_camera"]["translation"])
    centre = -rotation.T @ t
    # Blender's camera looks along -z with +y up: our camera's axes (x, -y, -z).
    camera_to_world = relight.BLENDER_FROM_NELF @ rotation.T @ np.diag([1.0, -1.0, -1.0])
    matrix = mathutils.Matrix(camera_to_world.tolist()).to_4x4()
    matrix.translation = mathutils.Vector((relight.BLENDER_FROM_NELF @ centre).tolist())
    data = bpy.data.cameras.new("camera")
    data.sensor_fit = "HORIZONTAL"
    data.sensor_width = 36.0
    data.lens = cam["intrinsics"]["fx"] * 36.0 / cam["width"]
    data.shift_x = -(cam["intrinsics"]["cx"] - cam["width"] / 2) / max(cam["width"], cam["height"])
    data.shift_y = (cam["intrinsics"]["cy"] - cam["height"] / 2) / max(cam["width"], cam["height"])
    data.clip_start = 0.01
    obj = bpy.data.objects.new("camera", data)
    obj.matrix_world = matrix
    scene.collection.objects.link(obj)
    scene.camera = obj


def render(scene, path, transparent=True):
    scene.render.film_transparent = transparent
    scene.render.image_settings.file_format = "OPEN_EXR" if path.endswith(".exr") else "PNG"
    scene.render.filepath = path
    start = time.time()
    bpy.ops.render.render(write_still=True)
    return time.time() - start


def save_png(pixels, path):
    srgb = np.where(pixels <= 0.0031308, 12.92 * pixels, 1.055 * np.clip(pixels, 0, None) ** (1 / 2.4) - 0.055)
    image = bpy.data.images.new(os.path.basename(path), pixels.shape[1], pixels.shape[0], alpha=True)
    rgba = np.concatenate([np.clip(srgb[..., :3], 0, 1), np.ones(pixels.shape[:2] + (1,))], axis=2)
    image.pixels.foreach_set(rgba.astype(np.float32).ravel())
    image.filepath_raw = path
    image.file_format = "PNG"
    image.save()
    bpy.data.images.remove(image)


first_name, first_beta = maps[0]
vdb = os.path.join(out_dir, "asset.vdb")
export_args = ["export", "vdb", asset_path, "-o", vdb, "--envmap", os.path.join(ROOT, "data", "envmaps", f"{first_name}.exr")]
export_args += ["--rotate-deg", f"{nelf_rotate(first_beta):.12g}"]
if rank:
    export_args += ["--rank", rank]
export_args += ["--pca-grids", options.get("pca_grids", "vec3")]
run(*export_args)

bpy.ops.wm.read_factory_settings(use_empty=True)
nelf_relight.register()
scene = bpy.context.scene
scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = samples
scene.cycles.seed = int(options.get("seed", "0"))
scene.cycles.max_bounces = 0
scene.cycles.volume_bounces = 0
scene.cycles.volume_step_rate = float(options.get("step_rate", "0.5"))
scene.cycles.volume_max_steps = 4096
# pixel=point: one ray through each pixel's centre, as `nelf render`; pixel=box: the mean
# over the pixel's square, as `nelf render --pixel-grid N` (N x N rays).
pixel_grid = int(options.get("pixel_grid", "0"))
scene.cycles.pixel_filter_type = "BOX" if pixel_grid else "GAUSSIAN"
scene.cycles.filter_width = 1.0 if pixel_grid else 0.01
scene.view_settings.view_transform = "Standard"
scene.render.resolution_x = scene.render.resolution_y = size
scene.render.resolution_percentage = 100
scene.render.image_settings.file_format = "OPEN_EXR"
scene.render.image_settings.color_depth = "32"

set_world(scene, first_name, first_beta)
start = time.time()
result = bpy.ops.import_scene.nelf_vdb(filepath=vdb)
import_seconds = time.time() - start
if "FINISHED" not in result:
    sys.exit(f"import failed: {result}")
obj = bpy.context.view_layer.objects.active
voxel = nelf_relight.read_asset(vdb).voxel_size
obj.location = mathutils.Vector((relight.BLENDER_FROM_NELF @ (np.array(shift) * voxel)).tolist())

camera_done = False
jobs = [("color", first_name, first_beta)] + [("relit", name, beta) for name, beta in maps]
jobs = [job for job in jobs if only in (None, job[0])]
for kind, name, beta in jobs:
    alpha = nelf_rotate(beta)
    tag = f"{kind}_{name}_{beta:g}"
    ref = os.path.join(out_dir, f"ref_{name}_{beta:g}{f'_grid{pixel_grid}' if pixel_grid else ''}.exr")
    render_args = ["render", asset_path, "--orbit", orbit, "--width", str(size), "--height", str(size), "--fov-deg", fov]
    render_args += ["--envmap", os.path.join(ROOT, "data", "envmaps", f"{name}.exr"), "--rotate-deg", f"{alpha:.12g}", "-o", ref]
    if rank:
        render_args += ["--rank", rank]
    if pixel_grid:
        render_args += ["--pixel-grid", str(pixel_grid)]
    if not os.path.exists(ref):
        run(*render_args)
    if not camera_done:
        camera_from_record(scene, json.load(open(ref + ".render.json")))
        camera_done = True
    set_world(scene, name, beta)
    obj.nelf.emission = "COLOR" if kind == "color" else "RELIT"
    start = time.time()
    nelf_relight.relight_object(obj, scene, force=True)
    obj.data.materials[0].cycles.volume_interpolation = interpolation
    relight_seconds = time.time() - start
    out = os.path.join(out_dir, f"blender_{tag}.exr")
    seconds = render(scene, out)
    ours, theirs = load(ref), load(out)
    # Foreground: what either renderer covers (nelf render's EXR alpha is 1 everywhere).
    mask = (theirs[..., 3] > 0.5) | (ours[..., :3].sum(axis=2) > 0)
    save_png(ours[..., :3], os.path.join(out_dir, f"ref_{name}_{beta:g}.png"))
    save_png(theirs[..., :3], os.path.join(out_dir, f"blender_{tag}.png"))
    diff = np.abs(ours[..., :3] - theirs[..., :3]).sum(axis=2)
    save_png(np.repeat((diff / max(diff.max(), 1e-9))[..., None], 3, axis=2), os.path.join(out_dir, f"diff_{tag}.png"))
    print(
        json.dumps(
            {
                "what": kind,
                "map": name,
                "world_mapping_z_deg": beta,
                "nelf_rotate_deg": round(alpha, 6),
                "psnr_whole_db": round(psnr(ours, theirs), 2),
                "psnr_foreground_db": round(psnr(ours, theirs, mask), 2),
                "render_seconds": round(seconds, 2),
                "relight_seconds": round(relight_seconds, 3),
                "import_seconds": round(import_seconds, 2),
                "samples": samples,
                "size": size,
                "shift_voxels": shift,
            }
        ),
        flush=True,
    )
    sys.stdout.flush()
    if scene_shots and kind == "relit":
        render(scene, os.path.join(out_dir, f"scene_{tag}.png"), transparent=False)

# Blender as a Python module can hang at interpreter exit after Cycles renders.
sys.stdout.flush()
os._exit(0)
