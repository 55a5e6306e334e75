"""nelf relightable volumes: imports a `nelf export vdb` file into Blender and relights it
under the scene's own world.

- File > Import > nelf asset (.vdb): loads the grids, stands the asset up (+90 degrees
  about X: our +y up is Blender's +z), moves it by -1/2 voxel (Cycles samples voxel i at
  index i + 1/2; OpenVDB centres it on i) and builds a volume material whose emission is
  the asset relit: `P_mean + sum_k pca_k * P_k` from the coefficient grids.
- Object properties > nelf: "Relight from world" projects the world's Environment Texture
  (its image times the Background's strength, through a Mapping node's rotation if one
  drives it) onto the asset's 8 x 16 light basis and its PCA basis (`relight.py`, written
  from format/SPEC.md section 8) and writes the `P_k` into the material; with "Auto" on it
  does so whenever the world, its image or the object's rotation changes; a rank slider
  keeps the first K components; "Emission" switches to the colour grid relit at export.

Errors (a file without nelf metadata or PCA grids, a world without an image) go to
Blender's report area. `export/BLENDER.md` is the manual.
"""

import os

import bpy
import mathutils
import numpy as np
from bpy.props import BoolProperty, EnumProperty, IntProperty, PointerProperty, StringProperty
from bpy_extras.io_utils import ImportHelper

from . import relight, vdbmeta

bl_info = {
    "name": "nelf relightable volumes",
    "author": "nelf developers",
    "version": (0, 1, 0),
    "blender": (4, 2, 0),
    "location": "File > Import > nelf asset (.vdb); Properties > Object > nelf",
    "description": "Import nelf OpenVDB exports and relight them under the scene's world",
    "category": "Import-Export",
}

MATERIAL_PREFIX = "nelf "
P_MEAN_NODE = "nelf_P_mean"

# Light projections already computed, by what they depend on (a 4k map takes seconds).
_light_cache = {}
# Metadata already read, by file path and modification time.
_meta_cache = {}


def read_asset(path):
    """The nelf metadata of a `.vdb` (cached while the file is unchanged)."""
    path = bpy.path.abspath(path)
    key = (path, os.path.getmtime(path))
    if key not in _meta_cache:
        _meta_cache.clear()
        _meta_cache[key] = vdbmeta.read_nelf_vdb(path)
    return _meta_cache[key]


# --- the world ------------------------------------------------------------------------


def _linked_from(socket):
    return socket.links[0].from_node if socket.is_linked else None


def _mapping_rotation(node):
    """The rotation a Mapping node applies to a direction (RelightError when it is not one)."""
    kind = node.vector_type
    rotation = np.array(mathutils.Euler(tuple(node.inputs["Rotation"].default_value), "XYZ").to_matrix())
    scale = tuple(node.inputs["Scale"].default_value)
    if max(scale) - min(scale) > 1e-6 * max(abs(v) for v in scale) or min(scale) <= 0:
        raise relight.RelightError("the world's Mapping node scales unevenly or by a negative factor")
    if kind in ("POINT", "TEXTURE") and any(abs(v) > 1e-9 for v in node.inputs["Location"].default_value):
        raise relight.RelightError("the world's Mapping node moves the direction (Location is not zero)")
    if any(node.inputs[name].is_linked for name in ("Location", "Rotation", "Scale")):
        raise relight.RelightError("the world's Mapping node has linked inputs")
    return rotation.T if kind == "TEXTURE" else rotation


def world_environment(world):
    """(image, strength, lookup_from_world) of a world lit by an Environment Texture."""
    if world is None:
        raise relight.RelightError("the scene has no world: add one with an Environment Texture")
    if not world.use_nodes:
        raise relight.RelightError(f"world {world.name!r} does not use nodes: add an Environment Texture")
    outputs = [n for n in world.node_tree.nodes if n.type == "OUTPUT_WORLD"]
    output = next((n for n in outputs if n.is_active_output), outputs[0] if outputs else None)
    background = _linked_from(output.inputs["Surface"]) if output else None
    if background is None or background.type != "BACKGROUND":
        raise relight.RelightError(f"world {world.name!r}: the output's Surface must come from a Background node")
    if background.inputs["Strength"].is_linked:
        raise relight.RelightError(f"world {world.name!r}: the Background's Strength is linked; set it as a number")
    env = _linked_from(background.inputs["Color"])
    if env is None or env.type != "TEX_ENVIRONMENT":
        raise relight.RelightError(f"world {world.name!r}: the Background's Color must come from an Environment Texture")
    if env.image is None:
        raise relight.RelightError(f"world {world.name!r}: the Environment Texture has no image")
    if env.projection != "EQUIRECTANGULAR":
        raise relight.RelightError(f"world {world.name!r}: the Environment Texture must be Equirectangular")
    lookup = np.eye(3)
    mapping = _linked_from(env.inputs["Vector"])
    if mapping is not None:
        if mapping.type != "MAPPING":
            raise relight.RelightError(f"world {world.name!r}: only a Mapping node may drive the Environment Texture's Vector")
        source = _linked_from(mapping.inputs["Vector"])
        if source is not None and source.type != "TEX_COORD":
            raise relight.RelightError(f"world {world.name!r}: the Mapping node's Vector must be a Texture Coordinate")
        lookup = _mapping_rotation(mapping)
    return env.image, float(background.inputs["Strength"].default_value), lookup


def image_latlong(image):
    """A Blender image as our H x W x 3 linear map (row 0 at the zenith)."""
    width, height = image.size
    if width < 1 or height < 1:
        raise relight.RelightError(f"image {image.name!r} has no pixels (is its file missing?)")
    buffer = np.empty(width * height * image.channels, dtype=np.float32)
    image.pixels.foreach_get(buffer)
    texels = relight.blender_pixels_to_latlong(buffer, width, height, image.channels)
    if not image.is_float and image.colorspace_settings.name in ("sRGB",):
        texels = relight.srgb_to_linear(texels)
    return texels


def object_rotation(obj):
    """The object's rotation in the scene (scale removed)."""
    return np.array(obj.matrix_world.to_3x3().normalized())


def lighting_for(obj, asset, world):
    """The asset's 128 x 3 light texels under the world, and a description."""
    image, strength, lookup = world_environment(world)
    e = relight.env_from_light_in_blender(asset.world_from_light, object_rotation(obj), lookup)
    key = (image.name, image.filepath, tuple(image.size), tuple(np.round(e, 9).ravel()))
    if key not in _light_cache:
        if len(_light_cache) > 16:
            _light_cache.clear()
        _light_cache[key] = relight.project_envmap(image_latlong(image), e)
    return _light_cache[key] * strength, f"{image.name} x {strength:g}"


# --- the material ---------------------------------------------------------------------


def build_material(obj, asset, rank, emission):
    """(Re)builds the object's nelf material for `rank` components; returns it."""
    volume = obj.data
    name = MATERIAL_PREFIX + obj.name
    material = bpy.data.materials.get(name) or bpy.data.materials.new(name)
    material.use_nodes = True
    nodes, links = material.node_tree.nodes, material.node_tree.links
    nodes.clear()
    output = nodes.new("ShaderNodeOutputMaterial")
    output.location = (600, 0)
    principled = nodes.new("ShaderNodeVolumePrincipled")
    principled.location = (300, 0)
    principled.inputs["Color"].default_value = (0, 0, 0, 1)
    principled.inputs["Absorption Color"].default_value = (0, 0, 0, 1)
    principled.inputs["Density"].default_value = 1.0
    principled.inputs["Density Attribute"].default_value = asset.density_grid
    density = nodes.new("ShaderNodeAttribute")
    density.attribute_name = asset.density_grid
    density.location = (-300, 200)
    clamp = nodes.new("ShaderNodeMath")
    clamp.operation = "MAXIMUM"
    clamp.inputs[1].default_value = 0.0
    clamp.location = (0, 200)
    links.new(density.outputs["Fac"], clamp.inputs[0])
    links.new(clamp.outputs[0], principled.inputs["Emission Strength"])
    links.new(principled.outputs["Volume"], output.inputs["Volume"])
    if emission == "COLOR":
        color = nodes.new("ShaderNodeAttribute")
        color.attribute_name = asset.color_grid
        color.location = (0, -100)
        links.new(color.outputs["Color"], principled.inputs["Emission Color"])
    elif asset.components_per_grid == 3:
        # radiance_c = P_mean_c + sum_g dot(pca3_g, (P_3g,c, P_3g+1,c, P_3g+2,c)): one
        # lookup per three components, three Dot Products and three Adds per grid.
        channels = []
        groups = -(-rank // 3)
        for c in range(3):
            total = None
            for g in range(groups):
                if c == 0:
                    attribute = nodes.new("ShaderNodeAttribute")
                    attribute.attribute_name = asset.pca_grids[g]
                    attribute.name = f"nelf_pca3_{g}"
                    attribute.location = (-1500, -200 - 200 * g)
                dot = nodes.new("ShaderNodeVectorMath")
                dot.operation = "DOT_PRODUCT"
                dot.name = dot.label = f"nelf_P3_{g}_{c}"
                dot.location = (-1200 + 150 * c, -200 - 200 * g)
                links.new(nodes[f"nelf_pca3_{g}"].outputs["Vector"], dot.inputs[0])
                if total is None:
                    total = dot.outputs["Value"]
                else:
                    add = nodes.new("ShaderNodeMath")
                    add.operation = "ADD"
                    add.location = (-750 + 150 * c, -200 - 200 * g)
                    links.new(total, add.inputs[0])
                    links.new(dot.outputs["Value"], add.inputs[1])
                    total = add.outputs[0]
            channels.append(total)
        combine = nodes.new("ShaderNodeCombineXYZ")
        combine.location = (-300, -200)
        for c, socket in enumerate(channels):
            if socket is not None:
                links.new(socket, combine.inputs[c])
        mean = nodes.new("ShaderNodeVectorMath")
        mean.operation = "ADD"
        mean.name = mean.label = P_MEAN_NODE
        mean.location = (-100, -200)
        links.new(combine.outputs["Vector"], mean.inputs[1])
        links.new(mean.outputs["Vector"], principled.inputs["Emission Color"])
    else:
        # radiance = P_mean + sum_k pca_k * P_k, one Scale and one Add per component.
        total = nodes.new("ShaderNodeVectorMath")
        total.operation = "ADD"
        total.name = total.label = P_MEAN_NODE
        total.inputs[1].default_value = (0, 0, 0)
        total.location = (-600, -200)
        for k in range(rank):
            attribute = nodes.new("ShaderNodeAttribute")
            attribute.attribute_name = asset.pca_grids[k]
            attribute.location = (-1200, -200 - 160 * k)
            term = nodes.new("ShaderNodeVectorMath")
            term.operation = "SCALE"
            term.name = term.label = f"nelf_P_{k}"
            term.location = (-900, -200 - 160 * k)
            links.new(attribute.outputs["Fac"], term.inputs["Scale"])
            if k == 0:
                links.new(term.outputs["Vector"], total.inputs[1])
            else:
                add = nodes.new("ShaderNodeVectorMath")
                add.operation = "ADD"
                add.location = (-600, -200 - 160 * k)
                links.new(total.outputs["Vector"], add.inputs[0])
                links.new(term.outputs["Vector"], add.inputs[1])
                total = add
        links.new(total.outputs["Vector"], principled.inputs["Emission Color"])
    if material.name not in [m.name for m in volume.materials if m]:
        volume.materials.clear()
        volume.materials.append(material)
    return material


def write_terms(material, p_mean, p):
    """Writes P_mean and the P_k (K x 3) into the material's nodes (either layout)."""
    nodes = material.node_tree.nodes
    nodes[P_MEAN_NODE].inputs[0].default_value = tuple(float(v) for v in p_mean)
    for k, row in enumerate(p):
        node = nodes.get(f"nelf_P_{k}")
        if node is not None:
            node.inputs[0].default_value = tuple(float(v) for v in row)
    for g in range(-(-len(p) // 3)):
        for c in range(3):
            node = nodes.get(f"nelf_P3_{g}_{c}")
            if node is not None:
                # Components past the rank get 0: the slider may cut a group.
                node.inputs[1].default_value = tuple(float(p[3 * g + j][c]) if 3 * g + j < len(p) else 0.0 for j in range(3))


def relight_object(obj, scene, force=True):
    """Relights one imported asset under the scene's world (RelightError / VdbMetaError on failure).

    With `force` False nothing is done when nothing it depends on changed (the handler's case).
    """
    settings = obj.nelf
    asset = read_asset(settings.vdb_path)
    rank = max(0, min(settings.rank, asset.rank))
    signature = repr(
        (
            settings.emission,
            rank,
            scene.world.name if scene.world else None,
            tuple(np.round(object_rotation(obj), 9).ravel()),
            _world_signature(scene.world),
        )
    )
    if not force and signature == settings.signature:
        return False
    material = bpy.data.materials.get(MATERIAL_PREFIX + obj.name)
    rebuild = material is None or settings.built != f"{settings.emission}:{rank}"
    if rebuild:
        material = build_material(obj, asset, rank, settings.emission)
        settings.built = f"{settings.emission}:{rank}"
    if settings.emission == "RELIT":
        light, what = lighting_for(obj, asset, scene.world)
        p_mean, p = relight.relight_terms(asset.mean, asset.basis[:rank], light)
        write_terms(material, p_mean, p)
        settings.lighting = what
    else:
        settings.lighting = f"exported colour grid ({asset.color_lighting})"
    settings.signature = signature
    return True


def _world_signature(world):
    try:
        image, strength, lookup = world_environment(world)
    except relight.RelightError as err:
        return str(err)
    return (image.name, image.filepath, tuple(image.size), strength, tuple(np.round(lookup, 9).ravel()))


def place_object(obj, asset):
    """Stands the asset up and moves it by -1/2 voxel along each of its own axes (the
    voxels of the colour and coefficient grids; a fine density grid stays
    `asset.density_offset_voxels` off, see `NelfVdb.placement_warning`)."""
    rotation = mathutils.Matrix(relight.BLENDER_FROM_NELF.tolist())
    obj.rotation_mode = "XYZ"
    obj.rotation_euler = rotation.to_euler("XYZ")
    half = -0.5 * asset.voxel_size
    obj.location = rotation @ mathutils.Vector((half, half, half))


# --- operators and panel --------------------------------------------------------------


def _on_settings_changed(self, context):
    obj = context.object
    if obj is None or not obj.nelf.vdb_path:
        return
    try:
        relight_object(obj, context.scene, force=False)
    except (relight.RelightError, vdbmeta.VdbMetaError, OSError) as err:
        obj.nelf.lighting = f"not relit: {err}"


class NelfObjectSettings(bpy.types.PropertyGroup):
    vdb_path: StringProperty(name="File", description="The .vdb written by `nelf export vdb`", subtype="FILE_PATH")
    rank: IntProperty(
        name="Rank",
        description="PCA components used (fewer: faster, smoother)",
        min=0,
        max=4096,
        default=64,
        update=_on_settings_changed,
    )
    emission: EnumProperty(
        name="Emission",
        items=[
            ("RELIT", "Relit by the world", "P_mean + sum_k pca_k P_k under the scene's world"),
            ("COLOR", "Exported colour grid", "The colour grid, lit by what `nelf export vdb` was given"),
        ],
        default="RELIT",
        update=_on_settings_changed,
    )
    auto_update: BoolProperty(
        name="Auto", description="Relight whenever the world or the object's rotation changes", default=True
    )
    lighting: StringProperty(name="Lit by")
    signature: StringProperty(options={"HIDDEN"})
    built: StringProperty(options={"HIDDEN"})


class IMPORT_OT_nelf_vdb(bpy.types.Operator, ImportHelper):
    """Import a .vdb written by `nelf export vdb` as a relightable volume"""

    bl_idname = "import_scene.nelf_vdb"
    bl_label = "Import nelf asset"
    bl_options = {"REGISTER", "UNDO"}
    filename_ext = ".vdb"
    filter_glob: StringProperty(default="*.vdb", options={"HIDDEN"})

    def execute(self, context):
        try:
            asset = vdbmeta.read_nelf_vdb(self.filepath)
        except (vdbmeta.VdbMetaError, OSError) as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        if asset.rank == 0:
            self.report({"WARNING"}, f"{self.filepath}: no PCA grids; only the exported colour grid can be shown")
        result = bpy.ops.object.volume_import(filepath=self.filepath, align="WORLD", location=(0, 0, 0))
        if "FINISHED" not in result:
            self.report({"ERROR"}, f"Blender could not import {self.filepath}")
            return {"CANCELLED"}
        obj = context.view_layer.objects.active
        volume = obj.data
        volume.grids.load()
        names = {g.name for g in volume.grids}
        missing = [n for n in [asset.density_grid, asset.color_grid, *asset.pca_grids] if n not in names]
        if missing:
            self.report({"ERROR"}, f"{self.filepath}: grids {missing} named in the metadata are not in the file")
            return {"CANCELLED"}
        volume.render.precision = "FULL"
        # Cycles treats |values| under `clipping` (default 0.001) as empty space.
        volume.render.clipping = 0.0
        place_object(obj, asset)
        warning = asset.placement_warning()
        if warning:
            self.report({"WARNING"}, warning)
        settings = obj.nelf
        settings.vdb_path = self.filepath
        settings.rank = asset.rank
        if asset.rank == 0:
            settings.emission = "COLOR"
        try:
            relight_object(obj, context.scene)
        except relight.RelightError as err:
            settings.emission = "COLOR"
            relight_object(obj, context.scene)
            self.report({"WARNING"}, f"Showing the exported colour grid: {err}")
        return {"FINISHED"}


class OBJECT_OT_nelf_relight(bpy.types.Operator):
    """Project the scene world's environment map onto the asset's light basis and write it into its material"""

    bl_idname = "object.nelf_relight"
    bl_label = "Relight from world"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return context.object is not None and bool(context.object.nelf.vdb_path)

    def execute(self, context):
        obj = context.object
        settings = obj.nelf
        try:
            asset = read_asset(settings.vdb_path)
            if asset.rank == 0:
                raise relight.RelightError(f"{asset.path}: no PCA grids to relight with")
            # Check the world before switching, so a failure leaves the material as it was.
            world_environment(context.scene.world)
            settings.emission = "RELIT"
            relight_object(obj, context.scene, force=True)
        except (relight.RelightError, vdbmeta.VdbMetaError, OSError) as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        self.report({"INFO"}, f"{obj.name} relit by {obj.nelf.lighting}")
        return {"FINISHED"}


class OBJECT_PT_nelf(bpy.types.Panel):
    bl_label = "nelf"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "object"

    @classmethod
    def poll(cls, context):
        return context.object is not None and bool(context.object.nelf.vdb_path)

    def draw(self, context):
        settings = context.object.nelf
        layout = self.layout
        layout.prop(settings, "emission")
        layout.prop(settings, "rank")
        row = layout.row()
        row.operator(OBJECT_OT_nelf_relight.bl_idname)
        row.prop(settings, "auto_update")
        layout.label(text=f"Lit by: {settings.lighting}")


def menu_import(self, _context):
    self.layout.operator(IMPORT_OT_nelf_vdb.bl_idname, text="nelf asset (.vdb)")


@bpy.app.handlers.persistent
def _auto_relight(scene, _depsgraph):
    # Cheap when nothing changed: the signature walks the world's few nodes, no pixels.
    for obj in scene.objects:
        settings = getattr(obj, "nelf", None)
        if settings is None or not settings.vdb_path or not settings.auto_update:
            continue
        try:
            relight_object(obj, scene, force=False)
        except (relight.RelightError, vdbmeta.VdbMetaError, OSError) as err:
            settings.lighting = f"not relit: {err}"


CLASSES = (NelfObjectSettings, IMPORT_OT_nelf_vdb, OBJECT_OT_nelf_relight, OBJECT_PT_nelf)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Object.nelf = PointerProperty(type=NelfObjectSettings)
    bpy.types.TOPBAR_MT_file_import.append(menu_import)
    bpy.app.handlers.depsgraph_update_post.append(_auto_relight)


def unregister():
    if _auto_relight in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.remove(_auto_relight)
    bpy.types.TOPBAR_MT_file_import.remove(menu_import)
    del bpy.types.Object.nelf
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)

