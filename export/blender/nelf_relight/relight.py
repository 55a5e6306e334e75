"""The relighting math of the nelf Blender add-on, written from `format/SPEC.md` section 8
and `export/README.md` ("Relighting in an engine"), in numpy without Blender.

An asset exported by `nelf export vdb` stores, per voxel, PCA coefficients `c_k` of its
light-transport vector `T = m + sum_k c_k B_k` (384 values: RGB x 128 texels of an 8 x 16
lat-long light basis in the asset's *light frame*). Under lighting `L` (the mean radiance
of each light texel, per channel) a voxel sends

    radiance_c = P_mean_c + sum_k c_k P_k_c,
    P_mean_c = sum_t m[c*128 + t] L[t][c],   P_k_c = sum_t B_k[c*128 + t] L[t][c].

`L` comes from a lat-long map by the rule of SPEC.md section 8 ("Lighting from a user's
map"): each light texel gets the solid-angle-weighted mean of the map over the region the
rotation `E = env_from_light` maps it onto, exactly (overlaps in cos(theta) and phi) when
`E` turns about +y, else by splatting sub-texels. This module follows those steps; the
tests (`export/tests/blender_addon.rs`) compare it with `nelf_format::conventions::
project_envmap` and with the colour grid `nelf export vdb` writes.

Frames. Our lat-long maps put row 0 at the zenith (+y) and, along the horizon, look
along +z, -x, -z, +x from left to right. Blender is +z up; its Environment Texture
looks up direction `d` at `u = 1/2 - atan2(d_y, d_x) / 2pi`, `v = 1/2 + asin(d_z) / pi`
(pixel rows stored bottom-up): the same image seen from our frame through
`ENV_FROM_BLENDER_MAP`. The add-on stands an asset up by turning it +90 degrees about X
(`BLENDER_FROM_NELF`): our +y becomes Blender's +z.
"""

import math

import numpy as np

ENV_H = 8
ENV_W = 16
ENV_TEXELS = ENV_H * ENV_W
LT_DIM = 3 * ENV_TEXELS

# Our env-frame direction from the direction Blender's Environment Texture looks up with
# the same image: x_env = -y_B, y_env = z_B, z_env = -x_B.
ENV_FROM_BLENDER_MAP = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]])

# The rotation the importer gives an asset: +90 degrees about X (our +y up to Blender's +z).
BLENDER_FROM_NELF = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])

# Sub-texels that cover the sphere in the splat rule (SPEC.md section 8, rule b).
SPLAT_TARGET = 4.0e6


class RelightError(ValueError):
    """A map or rotation the relighting cannot use (the message says which and why)."""


def is_rotation(m, tol=1e-6):
    """Whether `m` is a proper rotation to `tol` (orthonormal, determinant +1)."""
    m = np.asarray(m, dtype=np.float64)
    return (
        m.shape == (3, 3)
        and bool(np.all(np.isfinite(m)))
        and bool(np.all(np.abs(m.T @ m - np.eye(3)) <= tol))
        and abs(np.linalg.det(m) - 1.0) < tol
    )


def direction(theta, phi):
    """Unit direction(s) `(sin t sin p, cos t, -sin t cos p)`; theta from +y."""
    st = np.sin(theta)
    return np.stack([st * np.sin(phi), np.cos(theta) * np.ones_like(phi), -st * np.cos(phi)], axis=-1)


def texel_of_direction(d):
    """Light texel index `row * 16 + col` of each direction (rows of `d`; need not be unit)."""
    length = np.linalg.norm(d, axis=-1)
    theta = np.arccos(np.clip(d[..., 1] / length, -1.0, 1.0))
    phi = np.arctan2(d[..., 0], -d[..., 2])
    row = np.clip(np.floor(theta / math.pi * ENV_H).astype(np.int64), 0, ENV_H - 1)
    col = np.mod(np.floor((phi + math.pi) / (2.0 * math.pi) * ENV_W).astype(np.int64), ENV_W)
    return row * ENV_W + col


def sanitize_map(texels):
    """An `H x W x 3` map as f64 with NaN, infinities and negative values set to 0 (as our loaders do)."""
    env = np.asarray(texels, dtype=np.float64)
    if env.ndim != 3 or env.shape[2] != 3 or env.shape[0] < 1 or env.shape[1] < 1:
        raise RelightError(f"an environment map must be H x W x 3 texels, not {env.shape}")
    env = np.where(np.isfinite(env) & (env > 0.0), env, 0.0)
    return env


def rotation_about_y(env_from_light):
    """The angle alpha when `E` turns about +y to 1e-12 (rule a), else None."""
    e = env_from_light
    if (
        abs(e[1][1] - 1.0) < 1e-12
        and abs(e[0][1]) < 1e-12
        and abs(e[1][0]) < 1e-12
        and abs(e[1][2]) < 1e-12
        and abs(e[2][1]) < 1e-12
    ):
        return math.atan2(e[0][2], e[0][0])
    return None


def project_envmap(texels, env_from_light):
    """The 8 x 16 light texels (128 x 3, float32, index `row * 16 + col`) of a lat-long map.

    `texels` is `H x W x 3` linear RGB radiance, row 0 at the zenith (our convention);
    `env_from_light` the rotation taking light-frame directions to the map's frame.
    """
    env = sanitize_map(texels)
    e = np.asarray(env_from_light, dtype=np.float64)
    if not is_rotation(e):
        raise RelightError(f"env_from_light is not a rotation: {e.tolist()}")
    alpha = rotation_about_y(e)
    out = _project_about_y(env, alpha) if alpha is not None else _project_splat(env, e)
    return out.astype(np.float32)


def _overlap(a0, a1, b0, b1):
    return np.maximum(0.0, np.minimum(a1, b1) - np.maximum(a0, b0))


def _project_about_y(env, alpha):
    """Rule a: the overlaps in cos(theta) and phi factor into row and column weights."""
    height, width = env.shape[:2]
    two_pi = 2.0 * math.pi
    in_rows = np.arange(height)
    s0, s1 = in_rows * math.pi / height, (in_rows + 1) * math.pi / height
    row_w = np.zeros((ENV_H, height))
    for row in range(ENV_H):
        t0, t1 = row * math.pi / ENV_H, (row + 1) * math.pi / ENV_H
        row_w[row] = _overlap(math.cos(t1), math.cos(t0), np.cos(s1), np.cos(s0))
    step = two_pi / width
    col_w = np.zeros((ENV_W, width))
    for col in range(ENV_W):
        p0 = col * two_pi / ENV_W - math.pi
        start = math.fmod(p0 - alpha + math.pi, two_pi)
        if start < 0.0:
            start += two_pi
        end = start + two_pi / ENV_W
        first, last = math.floor(start / step), math.ceil(end / step)
        for j in range(first, last):
            lo = j * step
            w = float(_overlap(start, end, lo, lo + step))
            if w > 0.0:
                col_w[col, j % width] += w
    out = np.zeros((ENV_TEXELS, 3))
    for row in range(ENV_H):
        # (ENV_W x width) weights per input row: sum_r w_r sum_c w_c L(r, c).
        per_row = np.einsum("r,rcx->cx", row_w[row], env)  # width x 3
        acc = col_w @ per_row  # ENV_W x 3
        total = row_w[row].sum() * col_w.sum(axis=1)
        out[row * ENV_W : (row + 1) * ENV_W] = acc / total[:, None]
    return out


def splat_subdivisions(width, height):
    """Sub-texels per map texel side: about SPLAT_TARGET in all, between 1 and 256."""
    return int(min(256, max(1, math.ceil(math.sqrt(SPLAT_TARGET / (width * height))))))


def _project_splat(env, env_from_light):
    """Rule b: every map texel cut into n x n pieces uniform in cos(theta) and phi."""
    height, width = env.shape[:2]
    n = splat_subdivisions(width, height)
    light_from_env = env_from_light.T
    acc = np.zeros((ENV_TEXELS, 3))
    weight = np.zeros(ENV_TEXELS)
    frac = (np.arange(n) + 0.5) / n
    col_phi0 = np.arange(width) * (2.0 * math.pi / width) - math.pi
    # phi of every piece of one map row: width x n, column-major as the texels.
    phi = col_phi0[:, None] + (2.0 * math.pi / width) * frac[None, :]
    for row in range(height):
        c0, c1 = math.cos(row * math.pi / height), math.cos((row + 1) * math.pi / height)
        theta = np.arccos(np.clip(c0 + (c1 - c0) * frac, -1.0, 1.0))  # n
        sub_omega = (2.0 * math.pi / width) * (c0 - c1) / (n * n)
        d = direction(theta[:, None, None], phi[None, :, :])  # n x width x n x 3
        k = texel_of_direction(d @ light_from_env.T)  # n x width x n
        radiance = np.broadcast_to(env[row][None, :, None, :], k.shape + (3,))
        flat = k.ravel()
        weight += sub_omega * np.bincount(flat, minlength=ENV_TEXELS)
        for ch in range(3):
            acc[:, ch] += sub_omega * np.bincount(flat, weights=radiance[..., ch].ravel(), minlength=ENV_TEXELS)
    out = np.zeros((ENV_TEXELS, 3))
    seen = weight > 0.0
    out[seen] = acc[seen] / weight[seen][:, None]
    return out


def relight_terms(mean, basis, light):
    """`P_mean` (3,) and `P` (K x 3) from the PCA mean (384,), basis (K x 384) and light (128 x 3)."""
    mean = np.asarray(mean, dtype=np.float64)
    basis = np.asarray(basis, dtype=np.float64).reshape(-1, LT_DIM)
    light = np.asarray(light, dtype=np.float64)
    if mean.shape != (LT_DIM,) or light.shape != (ENV_TEXELS, 3):
        raise RelightError(f"mean must have {LT_DIM} values and the light {ENV_TEXELS} x 3, not {mean.shape} and {light.shape}")
    p_mean = np.array([mean[c * ENV_TEXELS : (c + 1) * ENV_TEXELS] @ light[:, c] for c in range(3)])
    p = np.stack([basis[:, c * ENV_TEXELS : (c + 1) * ENV_TEXELS] @ light[:, c] for c in range(3)], axis=1)
    return p_mean, p


def blender_pixels_to_latlong(pixels, width, height, channels=4):
    """A Blender image's flat pixel buffer (rows bottom-up) as our `H x W x 3` map (row 0 at the zenith)."""
    px = np.asarray(pixels, dtype=np.float64).reshape(height, width, channels)
    return px[::-1, :, :3]


def srgb_to_linear(v):
    """The sRGB transfer function's inverse (for 8-bit images Blender stores encoded)."""
    v = np.asarray(v, dtype=np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def env_from_light_in_blender(world_from_light, blender_from_object, lookup_from_world=None):
    """`E = env_from_light` for an asset object in a Blender scene.

    `world_from_light`: the asset's light frame in its own (nelf world) frame, from the file;
    `blender_from_object`: the object's rotation in the scene (`BLENDER_FROM_NELF` as
    imported, times whatever turn the user gives it); `lookup_from_world`: the rotation a
    Mapping node applies to the direction before the Environment Texture looks it up
    (identity without one).
    """
    m = np.eye(3) if lookup_from_world is None else np.asarray(lookup_from_world, dtype=np.float64)
    e = ENV_FROM_BLENDER_MAP @ m @ np.asarray(blender_from_object, dtype=np.float64) @ np.asarray(world_from_light, dtype=np.float64)
    return e


def nelf_rotate_deg(env_from_light, world_from_light):
    """The `nelf render --rotate-deg` that gives the same `E`, or None when `E` is not such a turn.

    `nelf render` uses `world_from_env = R_y(alpha)`, so `E = R_y(alpha)^T world_from_light`.
    """
    world_from_env = np.asarray(world_from_light, dtype=np.float64) @ np.asarray(env_from_light, dtype=np.float64).T
    alpha = math.atan2(world_from_env[0][2], world_from_env[0][0])
    c, s = math.cos(alpha), math.sin(alpha)
    r_y = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    if np.max(np.abs(world_from_env - r_y)) > 1e-9:
        return None
    return math.degrees(alpha)


def rotation_to_blender_euler_z(deg):
    """Rotation matrix about Blender's +z by `deg` degrees (a Mapping node's Z rotation)."""
    a = math.radians(deg)
    return np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])
