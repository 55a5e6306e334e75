//! The network's lighting: its 8 × 16 environment-map layout, the per-view light
//! estimates and their confidence-weighted aggregation (official `encode`), and the
//! exact map from its layout to the project's conventions (`docs/CONVENTIONS.md`,
//! `nelf_format::conventions`).
//!
//! **Network layout.** Texel `(i, j)` has `θ = (i + ½)π/8`, `φ = (j + ½)·2π/16` and
//! direction, in view-0 camera coordinates (OpenCV axes),
//! `n(i, j) = (−sin θ sin φ, −cos θ, sin θ cos φ)`; its solid angle is taken as
//! `sin θ · 2π²/128`.
//!
//! **Ours.** Texel `(i, j')` of a light frame has direction
//! `d(i, j') = (sin θ sin φ', cos θ, −sin θ cos φ')` at `φ' = (j' + ½)·2π/16 − π`.
//! With `j' = 15 − j` we get `φ' = π − φ`, hence `d = (sin θ sin φ, cos θ, sin θ cos φ)`
//! and `n(i, j) = F·d(i, 15 − j)` with `F = diag(−1, −1, 1)`, a rotation by π about
//! the camera's z axis. The texel *regions* coincide too (`φ ↦ π − φ` maps column
//! `j`'s interval onto column `15 − j`'s). So no resampling is needed: the network's
//! texels are our texels in the light frame `cam0_from_light = F`, i.e.
//! `world_from_light = R₀ᵀ·F` (`R₀` view 0's world-to-camera rotation), with the
//! columns reversed.
//!
//! **Aggregation** (per source patch `n = (v·h + i)·w + j` of view `v`): the 512
//! light channels are 4 maps (RGB estimate, confidence) of 8 × 16, `k·128 + row·16 +
//! col`. Each view-0 direction is rotated into view `v`, `c = R_v R₀ᵀ n`, and view
//! `v`'s maps are sampled there with `grid_sample` at `x = atan2(c_x, −c_z)/π`,
//! `y = 2·acos(−c_y)/π − 1` (no wrap in φ). Confidences are normalised over all
//! `V·h·w` patches per texel and `source_light = Σ_n est_n · conf_n`.

use glam::DMat3;
use nelf_format::conventions::{ENV_H, ENV_TEXELS, ENV_W, LT_DIM, LatLong};

use crate::error::NetError;
use crate::geometry::Taps;

/// `cam0_from_light`: the network's texel directions are our light frame's
/// (with columns reversed) turned by π about the view-0 camera's z axis.
pub const CAM0_FROM_LIGHT: DMat3 = DMat3::from_cols_array(&[-1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0]);

/// Channels of one patch's light feature: 4 maps × 128 texels.
pub const LIGHT_CHANNELS: usize = 4 * ENV_TEXELS;

/// Polar angle and azimuth of the network's texel `(row, col)`.
fn net_theta_phi(row: usize, col: usize) -> (f32, f32) {
    let theta = (row as f32 + 0.5) * std::f32::consts::PI / ENV_H as f32;
    let phi = (col as f32 + 0.5) * 2.0 * std::f32::consts::PI / ENV_W as f32;
    (theta, phi)
}

/// Direction of the network's texel `(row, col)` in view-0 camera coordinates (the
/// official `light_coord` buffer).
pub fn net_texel_direction(row: usize, col: usize) -> [f32; 3] {
    let (theta, phi) = net_theta_phi(row, col);
    [-theta.sin() * phi.sin(), -theta.cos(), theta.sin() * phi.cos()]
}

/// The network's solid angle of a texel in `row`: `sin θ · 2π²/128` (the official
/// `solid_angle` buffer; its 128 values sum to about 4π).
pub fn net_solid_angle(row: usize) -> f32 {
    let (theta, _) = net_theta_phi(row, 0);
    theta.sin() * 2.0 * std::f32::consts::PI * std::f32::consts::PI / ENV_TEXELS as f32
}

/// Our column of the network's column `col` (and back: the map is an involution).
pub const fn our_col(col: usize) -> usize {
    ENV_W - 1 - col
}

/// Reorders a light-transport (or light) vector from the network's layout
/// (`c·128 + row·16 + col`) to ours in the light frame [`world_from_light`].
pub fn net_to_ours(net: &[f32], ours: &mut [f32]) {
    debug_assert_eq!(net.len(), LT_DIM);
    debug_assert_eq!(ours.len(), LT_DIM);
    for c in 0..3 {
        for row in 0..ENV_H {
            for col in 0..ENV_W {
                ours[c * ENV_TEXELS + row * ENV_W + our_col(col)] = net[c * ENV_TEXELS + row * ENV_W + col];
            }
        }
    }
}

/// `world_from_light` of a capture whose view 0 has world-to-camera rotation `r0`:
/// `R₀ᵀ·F` (see the module documentation).
pub fn world_from_light(r0: DMat3) -> DMat3 {
    r0.transpose() * CAM0_FROM_LIGHT
}

/// A network-layout light `(3, 8, 16)` (radiance per texel) as an 8 × 16 map in our
/// light frame ([`world_from_light`]).
pub fn net_light_to_latlong(net: &[f32]) -> Result<LatLong, NetError> {
    if net.len() != LT_DIM {
        return Err(NetError::input(format!(
            "a light has {LT_DIM} values, got {}",
            net.len()
        )));
    }
    let mut ours = vec![0.0f32; LT_DIM];
    net_to_ours(net, &mut ours);
    let texels = (0..ENV_TEXELS)
        .map(|k| [ours[k], ours[ENV_TEXELS + k], ours[2 * ENV_TEXELS + k]])
        .collect();
    Ok(LatLong::new(ENV_W, ENV_H, texels)?)
}

/// An 8 × 16 map in our light frame as the network's `(3, 8, 16)` layout.
pub fn latlong_to_net_light(map: &LatLong) -> Result<Vec<f32>, NetError> {
    if map.width() != ENV_W || map.height() != ENV_H {
        return Err(NetError::input(format!(
            "the network's light is {ENV_W}×{ENV_H}, got {}×{}",
            map.width(),
            map.height()
        )));
    }
    let mut net = vec![0.0f32; LT_DIM];
    for row in 0..ENV_H {
        for col in 0..ENV_W {
            let t = map.get(row, our_col(col));
            for (c, v) in t.iter().enumerate() {
                net[c * ENV_TEXELS + row * ENV_W + col] = *v;
            }
        }
    }
    Ok(net)
}

/// An 8 × 16 map in a light frame resampled into a `width × height` lat-long map in
/// the world (`world_from_light`), each output texel the mean of 4 × 4 equal-area
/// sub-samples of the (piecewise-constant) light map. Written at a resolution well
/// above 8 × 16, projecting it back into the light frame
/// (`project_envmap(map, world_from_light)`) recovers the light map up to the
/// texels straddling its borders.
pub fn light_map_in_world(
    light: &LatLong,
    world_from_light: DMat3,
    width: usize,
    height: usize,
) -> Result<LatLong, NetError> {
    const SUB: usize = 4;
    let (width, height) = (width.max(1), height.max(1));
    let light_from_world = world_from_light.transpose();
    let mut texels = Vec::with_capacity(width * height);
    for row in 0..height {
        let (t0, t1) = nelf_format::conventions::row_theta_bounds(row, height);
        let (u0, u1) = (t0.cos(), t1.cos());
        for col in 0..width {
            let (p0, p1) = nelf_format::conventions::col_phi_bounds(col, width);
            let mut acc = [0.0f64; 3];
            for a in 0..SUB {
                let u = u0 + (u1 - u0) * (a as f64 + 0.5) / SUB as f64;
                let theta = u.clamp(-1.0, 1.0).acos();
                for b in 0..SUB {
                    let phi = p0 + (p1 - p0) * (b as f64 + 0.5) / SUB as f64;
                    let d = light_from_world * nelf_format::conventions::direction(theta, phi);
                    let t = light.lookup(d);
                    for (s, v) in acc.iter_mut().zip(t) {
                        *s += f64::from(v);
                    }
                }
            }
            texels.push(acc.map(|s| (s / (SUB * SUB) as f64) as f32));
        }
    }
    Ok(LatLong::new(width, height, texels)?)
}

/// Where each view's light maps are sampled to align them with view 0: for view
/// `v` and view-0 texel `t`, the normalised grid point `(x, y)` (`(V, 8, 16, 2)`) and
/// its bilinear taps (`V·128`) in view `v`'s 8 × 16 maps (module docs).
pub fn alignment_taps(rotations: &[[[f32; 3]; 3]]) -> (Vec<f32>, Vec<Taps>) {
    let views = rotations.len();
    let Some(&r0) = rotations.first() else {
        return (Vec::new(), Vec::new());
    };
    let mut sample_grid = vec![0.0f32; views * ENV_TEXELS * 2];
    let mut taps = vec![Taps::NONE; views * ENV_TEXELS];
    for (v, rv) in rotations.iter().enumerate() {
        // M = R_v R₀ᵀ.
        let mut m = [[0.0f32; 3]; 3];
        for (a, row) in m.iter_mut().enumerate() {
            for (b, val) in row.iter_mut().enumerate() {
                *val = (0..3).map(|k| rv[a][k] * r0[b][k]).sum();
            }
        }
        for t in 0..ENV_TEXELS {
            let d = net_texel_direction(t / ENV_W, t % ENV_W);
            let c = m.map(|row| row[0] * d[0] + row[1] * d[1] + row[2] * d[2]);
            let x = c[0].atan2(-c[2]) / std::f32::consts::PI;
            let y = 2.0 * (-c[1]).clamp(-1.0, 1.0).acos() / std::f32::consts::PI - 1.0;
            sample_grid[(v * ENV_TEXELS + t) * 2] = x;
            sample_grid[(v * ENV_TEXELS + t) * 2 + 1] = y;
            taps[v * ENV_TEXELS + t] = Taps::bilinear(x, y, ENV_W, ENV_H);
        }
    }
    (sample_grid, taps)
}

/// Everything the light aggregation computes, in the fixtures' layouts.
#[derive(Debug, Clone, PartialEq)]
pub struct LightAggregation {
    /// `(V, 8, 16, 2)`: normalised `(x, y)` where each view's maps are sampled.
    pub sample_grid: Vec<f32>,
    /// `(V·h·w, 4, 8, 16)`: the light feature per patch.
    pub feature_reshaped: Vec<f32>,
    /// `(V·h·w, 4, 8, 16)`: the same, rotated into view 0.
    pub aligned: Vec<f32>,
    /// `(V·h·w, 1, 8, 16)`: confidences normalised over patches.
    pub confidence_norm: Vec<f32>,
    /// `(3, 8, 16)`: the estimated source lighting (radiance), network layout.
    pub source_light: Vec<f32>,
}

/// Aggregates the light feature `(V, 512, h, w)` of views with world-to-camera
/// rotations `rotations` (network world) into the source light (module docs).
pub fn aggregate_light(
    light_feature: &[f32],
    rotations: &[[[f32; 3]; 3]],
    h: usize,
    w: usize,
) -> Result<LightAggregation, NetError> {
    let views = rotations.len();
    let patches = views * h * w;
    if views == 0 || light_feature.len() != patches * LIGHT_CHANNELS {
        return Err(NetError::input(format!(
            "light feature of {} values for {views} views of {h}×{w} patches",
            light_feature.len()
        )));
    }
    // (V, 512, h, w) → (V, h, w, 512) = (V·h·w, 4, 8, 16).
    let mut feature_reshaped = vec![0.0f32; light_feature.len()];
    for v in 0..views {
        for ch in 0..LIGHT_CHANNELS {
            for p in 0..h * w {
                feature_reshaped[(v * h * w + p) * LIGHT_CHANNELS + ch] =
                    light_feature[(v * LIGHT_CHANNELS + ch) * h * w + p];
            }
        }
    }
    let (sample_grid, taps) = alignment_taps(rotations);
    // Rotate every patch's four maps into view 0.
    let mut aligned = vec![0.0f32; feature_reshaped.len()];
    for n in 0..patches {
        let v = n / (h * w);
        let src = &feature_reshaped[n * LIGHT_CHANNELS..(n + 1) * LIGHT_CHANNELS];
        let dst = &mut aligned[n * LIGHT_CHANNELS..(n + 1) * LIGHT_CHANNELS];
        for k in 0..4 {
            let plane = &src[k * ENV_TEXELS..(k + 1) * ENV_TEXELS];
            for t in 0..ENV_TEXELS {
                dst[k * ENV_TEXELS + t] = taps[v * ENV_TEXELS + t].sample_scalar(plane);
            }
        }
    }
    // Normalise confidences over patches, per texel; weight the estimates.
    let mut total = vec![0.0f64; ENV_TEXELS];
    for n in 0..patches {
        for (t, s) in total.iter_mut().enumerate() {
            *s += f64::from(aligned[n * LIGHT_CHANNELS + 3 * ENV_TEXELS + t]);
        }
    }
    let mut confidence_norm = vec![0.0f32; patches * ENV_TEXELS];
    let mut light = vec![0.0f64; LT_DIM];
    for n in 0..patches {
        let a = &aligned[n * LIGHT_CHANNELS..(n + 1) * LIGHT_CHANNELS];
        for t in 0..ENV_TEXELS {
            let conf = if total[t] > 0.0 {
                (f64::from(a[3 * ENV_TEXELS + t]) / total[t]) as f32
            } else {
                0.0
            };
            confidence_norm[n * ENV_TEXELS + t] = conf;
            for c in 0..3 {
                light[c * ENV_TEXELS + t] += f64::from(a[c * ENV_TEXELS + t]) * f64::from(conf);
            }
        }
    }
    Ok(LightAggregation {
        sample_grid,
        feature_reshaped,
        aligned,
        confidence_norm,
        source_light: light.iter().map(|v| *v as f32).collect(),
    })
}

/// The network's solid angles `(8, 16)` as used by its shading, row-major.
pub fn net_solid_angles() -> [f32; ENV_TEXELS] {
    std::array::from_fn(|t| net_solid_angle(t / ENV_W))
}

/// The total of [`net_solid_angles`], close to (not exactly) 4π.
pub fn net_total_solid_angle() -> f64 {
    net_solid_angles().iter().map(|v| f64::from(*v)).sum()
}

#[cfg(test)]
mod tests {
    use std::f64::consts::PI;

    use glam::DVec3;
    use nelf_format::conventions::{texel_center_direction, texel_of_direction};

    use super::*;

    #[test]
    fn network_texels_are_a_rotation_of_ours() {
        // n(i, j) = F · d(i, 15 − j) at every texel centre, and the texel regions
        // coincide: points anywhere inside a network texel land in our texel (i, 15 − j).
        assert!(nelf_format::conventions::is_rotation(CAM0_FROM_LIGHT, 1e-12));
        for row in 0..ENV_H {
            for col in 0..ENV_W {
                let n = net_texel_direction(row, col);
                let d = CAM0_FROM_LIGHT * texel_center_direction(row, our_col(col), ENV_H, ENV_W);
                for k in 0..3 {
                    assert!((f64::from(n[k]) - d[k]).abs() < 1e-6, "({row},{col})");
                }
                for (a, b) in [(0.05, 0.05), (0.95, 0.1), (0.1, 0.95), (0.9, 0.9)] {
                    let theta = (row as f64 + a) * PI / ENV_H as f64;
                    let phi = (col as f64 + b) * 2.0 * PI / ENV_W as f64;
                    let cam = DVec3::new(-theta.sin() * phi.sin(), -theta.cos(), theta.sin() * phi.cos());
                    let light = CAM0_FROM_LIGHT.transpose() * cam;
                    assert_eq!(texel_of_direction(light, ENV_H, ENV_W), (row, our_col(col)));
                }
            }
        }
    }

    #[test]
    fn light_layout_round_trips() {
        let net: Vec<f32> = (0..LT_DIM).map(|v| v as f32).collect();
        let map = net_light_to_latlong(&net).unwrap();
        assert_eq!(map.get(2, our_col(5))[1], net[ENV_TEXELS + 2 * ENV_W + 5]);
        assert_eq!(latlong_to_net_light(&map).unwrap(), net);
    }

    #[test]
    fn world_map_projects_back_to_the_light_map() {
        use nelf_format::conventions::project_envmap;
        // A smooth light map, a tilted light frame: writing it in the world at 256 × 128
        // and projecting back recovers it to a few percent and keeps its power.
        let texels: Vec<[f32; 3]> = (0..ENV_TEXELS)
            .map(|t| {
                let (r, c) = ((t / ENV_W) as f32, (t % ENV_W) as f32);
                [1.0 + 0.5 * (c * 0.4).sin(), 1.0 + 0.1 * r, 2.0 - 0.1 * r]
            })
            .collect();
        let light = LatLong::new(ENV_W, ENV_H, texels).unwrap();
        let world_from_light = DMat3::from_rotation_x(0.3) * DMat3::from_rotation_y(2.0) * CAM0_FROM_LIGHT;
        let world = light_map_in_world(&light, world_from_light, 256, 128).unwrap();
        let back = project_envmap(&world, world_from_light).unwrap();
        for (a, b) in light.texels().iter().zip(back.texels()) {
            for c in 0..3 {
                assert!((a[c] - b[c]).abs() < 0.05 * a[c], "{a:?} vs {b:?}");
            }
        }
        let (p0, p1) = (light.integral(), world.integral());
        for c in 0..3 {
            assert!((p0[c] - p1[c]).abs() < 2e-3 * p0[c], "{p0:?} vs {p1:?}");
        }
    }

    #[test]
    fn solid_angles_sum_near_four_pi() {
        assert!((net_total_solid_angle() - 4.0 * PI).abs() < 0.05 * 4.0 * PI);
    }
}
