"""Reads the file metadata of an OpenVDB file and the nelf keys `nelf export vdb` writes
(`export/README.md`, "Metadata"), in plain Python: Blender's Python has no OpenVDB
module, and the PCA mean, basis and light frame live in the file's metadata.

OpenVDB's layout up to the file metadata (little-endian): i64 magic 0x56444220, u32 file
version, u32 library major, u32 library minor, u8 has-grid-offsets, 36 ASCII characters
of UUID, then u32 entry count and per entry: name, type name (each u32 length + bytes),
u32 value size, value bytes.
"""

import json
import math
import struct

MAGIC = 0x56444220
# The oldest file version with the header above (OpenVDB 3 writes 222 or later).
MIN_FILE_VERSION = 222
LAYOUT_VERSION = 1
LT_DIM = 384
# Largest metadata the reader accepts (a rank-64 basis is about 300 kB of JSON).
MAX_VALUE_BYTES = 64 << 20


class VdbMetaError(ValueError):
    """A file that is not an OpenVDB file from `nelf export vdb` (the message says why)."""


def _read_exact(f, n, path, what):
    data = f.read(n)
    if len(data) != n:
        raise VdbMetaError(f"{path}: file ends inside {what}")
    return data


def _string(f, path, what):
    (n,) = struct.unpack("<I", _read_exact(f, 4, path, what))
    if n > MAX_VALUE_BYTES:
        raise VdbMetaError(f"{path}: {what} claims {n} bytes")
    return _read_exact(f, n, path, what).decode("utf-8", errors="replace")


def _value(type_name, data):
    fixed = {
        "bool": ("<?", 1),
        "int32": ("<i", 4),
        "int64": ("<q", 8),
        "float": ("<f", 4),
        "double": ("<d", 8),
        "vec3i": ("<3i", 12),
        "vec3s": ("<3f", 12),
        "vec3d": ("<3d", 24),
    }
    if type_name == "string":
        return data.decode("utf-8", errors="replace")
    if type_name in fixed and len(data) == fixed[type_name][1]:
        value = struct.unpack(fixed[type_name][0], data)
        return value[0] if len(value) == 1 else list(value)
    return data


def read_file_metadata(path):
    """The file-level metadata of an OpenVDB file as a dict (name -> value)."""
    with open(path, "rb") as f:
        (magic,) = struct.unpack("<q", _read_exact(f, 8, path, "the header"))
        if magic != MAGIC:
            raise VdbMetaError(f"{path}: not an OpenVDB file (magic {magic:#x})")
        version, _major, _minor = struct.unpack("<III", _read_exact(f, 12, path, "the header"))
        if version < MIN_FILE_VERSION:
            raise VdbMetaError(f"{path}: OpenVDB file version {version} is older than {MIN_FILE_VERSION}")
        _read_exact(f, 1 + 36, path, "the header")
        (count,) = struct.unpack("<I", _read_exact(f, 4, path, "the metadata count"))
        meta = {}
        for _ in range(count):
            name = _string(f, path, "a metadata name")
            type_name = _string(f, path, f"the type of metadata {name!r}")
            (size,) = struct.unpack("<I", _read_exact(f, 4, path, f"metadata {name!r}"))
            if size > MAX_VALUE_BYTES:
                raise VdbMetaError(f"{path}: metadata {name!r} claims {size} bytes")
            meta[name] = _value(type_name, _read_exact(f, size, path, f"metadata {name!r}"))
        return meta


class NelfVdb:
    """What the relighting needs from a `nelf export vdb` file's metadata."""

    def __init__(self, path, meta):
        def need(key, kind):
            if key not in meta:
                raise VdbMetaError(
                    f"{path}: no {key!r} in the file metadata; this is not a file written by "
                    "`nelf export vdb` (or it was re-saved without its metadata)"
                )
            if not isinstance(meta[key], kind):
                raise VdbMetaError(f"{path}: metadata {key!r} has the wrong type")
            return meta[key]

        def floats(key):
            try:
                return json.loads(need(key, str))
            except json.JSONDecodeError as err:
                raise VdbMetaError(f"{path}: metadata {key!r} is not JSON: {err}") from None

        self.path = path
        self.layout = need("nelf_vdb_layout", int)
        if self.layout != LAYOUT_VERSION:
            raise VdbMetaError(f"{path}: nelf_vdb_layout {self.layout} (this add-on reads {LAYOUT_VERSION})")
        self.scale = float(need("nelf_scale", float))
        self.voxel_size_m = float(need("nelf_voxel_size_m", float))
        if not (self.scale > 0 and self.voxel_size_m > 0 and math.isfinite(self.scale * self.voxel_size_m)):
            raise VdbMetaError(f"{path}: nelf_scale and nelf_voxel_size_m must be positive")
        self.density_grid = need("nelf_density_grid", str)
        # A fine density (format 1.4): the density grid is this many times finer per axis
        # than the other grids, on its own transform; files without the key have none.
        self.density_factor = meta.get("nelf_density_factor", 1)
        if not isinstance(self.density_factor, int) or self.density_factor not in (1, 2, 4):
            raise VdbMetaError(f"{path}: nelf_density_factor {self.density_factor!r} must be 2 or 4")
        self.color_grid = need("nelf_color_grid", str)
        self.color_lighting = need("nelf_color_lighting", str)
        self.pca_grids = floats("nelf_pca_grids")
        # "float: ..." (one component per grid) or "vec3s: ..." (three per grid); files
        # from before the key are float.
        grid_type = meta.get("nelf_pca_grid_type", "float")
        if not isinstance(grid_type, str) or grid_type.split(":")[0] not in ("float", "vec3s"):
            raise VdbMetaError(f"{path}: unknown nelf_pca_grid_type {grid_type!r}")
        self.components_per_grid = 3 if grid_type.startswith("vec3s") else 1
        self.mean = floats("nelf_pca_mean")
        self.basis = floats("nelf_pca_basis")
        rows = floats("nelf_world_from_light")
        if (
            not isinstance(self.pca_grids, list)
            or not all(isinstance(g, str) for g in self.pca_grids)
            or not isinstance(self.mean, list)
            or len(self.mean) != LT_DIM
            or not isinstance(self.basis, list)
            or -(-len(self.basis) // self.components_per_grid) != len(self.pca_grids)
            or any(not isinstance(b, list) or len(b) != LT_DIM for b in self.basis)
            or not (isinstance(rows, list) and len(rows) == 3 and all(isinstance(r, list) and len(r) == 3 for r in rows))
        ):
            raise VdbMetaError(
                f"{path}: the PCA metadata is inconsistent (nelf_pca_grids names {len(self.pca_grids)} grids, "
                f"nelf_pca_basis has {len(self.basis) if isinstance(self.basis, list) else '?'} vectors, "
                f"each must have {LT_DIM} values, nelf_world_from_light must be 3 x 3)"
            )
        if not all(math.isfinite(v) for v in self.mean) or not all(math.isfinite(v) for b in self.basis for v in b):
            raise VdbMetaError(f"{path}: the PCA mean or basis holds a value that is not finite")
        self.world_from_light = rows
        if (need("nelf_env_height", int), need("nelf_env_width", int)) != (8, 16):
            raise VdbMetaError(f"{path}: the light basis must be 8 x 16 texels")

    @property
    def rank(self):
        """PCA components exported (basis vectors in the metadata)."""
        return len(self.basis)

    @property
    def voxel_size(self):
        """Voxel edge in the file's scene units."""
        return self.voxel_size_m * self.scale

    @property
    def density_offset_voxels(self):
        """How far (in voxels, toward -x, -y, -z of the asset) Cycles shows the density grid
        from where `nelf render` puts it once the object is moved by -1/2 voxel: Cycles
        samples each grid half of its *own* voxel off, so a fine density (voxel 1/F) keeps
        1/2 - 1/(2F) of a voxel that one object move cannot undo; 0 without one."""
        return 0.5 - 0.5 / self.density_factor

    def placement_warning(self):
        """What to tell the user about the placement on import (None: nothing to tell)."""
        if self.density_factor == 1:
            return None
        return (
            f"{self.path}: the density grid is the asset's fine density ({self.density_factor} times finer); "
            "Cycles offsets each grid by half of its own voxel and one object move undoes only one: the "
            f"colour and coefficient grids are placed exactly, the density lies {self.density_offset_voxels:g} "
            "voxel toward -x, -y, -z of the asset from where nelf render puts it (export/BLENDER.md)"
        )


def read_nelf_vdb(path):
    """The nelf relighting data of a `nelf export vdb` file (VdbMetaError when it has none)."""
    return NelfVdb(path, read_file_metadata(path))
