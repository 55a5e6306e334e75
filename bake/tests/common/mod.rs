//! Shared fixtures of the baker's tests: cameras around a sphere and its exact
//! (supersampled) masks, and a tiny path-traced capture of a procedural head.

#![allow(dead_code)]

use glam::{DVec2, DVec3};
use nelf_format::conventions::PinholeCamera;

/// Sphere centre and radius (metres) of the fixtures.
pub const SPHERE_CENTRE: DVec3 = DVec3::new(0.01, 0.02, -0.01);
/// Sphere radius, metres.
pub const SPHERE_RADIUS: f64 = 0.1;

/// Five cameras like a synthetic capture's: one frontal (+z), four on a ring 25°
/// away, 0.8–1.2 m from the sphere, looking at its centre, `size × size` pixels,
/// the sphere filling about 60 % of the frame.
pub fn five_cameras(size: u32) -> Vec<PinholeCamera> {
    let ring = [
        (0.0f64, 0.0f64, 1.0f64),
        (25.0, 5.0, 0.8),
        (-5.0, 25.0, 1.2),
        (-25.0, -5.0, 0.9),
        (5.0, -25.0, 1.1),
    ];
    ring.iter()
        .map(|&(az, el, dist)| {
            let (a, e) = (az.to_radians(), el.to_radians());
            let dir = DVec3::new(a.sin() * e.cos(), e.sin(), a.cos() * e.cos());
            let eye = SPHERE_CENTRE + dir * dist;
            let half = (SPHERE_RADIUS / dist).asin() / 0.6;
            PinholeCamera::look_at(eye, SPHERE_CENTRE, DVec3::Y, size, size, 2.0 * half)
        })
        .collect()
}

/// Whether the ray through continuous pixel `pixel` of `cam` meets the sphere.
pub fn ray_hits_sphere(cam: &PinholeCamera, pixel: DVec2) -> bool {
    let o = cam.centre();
    let d = cam.ray_direction(pixel);
    let oc = SPHERE_CENTRE - o;
    let t = oc.dot(d);
    t > 0.0 && (oc - d * t).length_squared() <= SPHERE_RADIUS * SPHERE_RADIUS
}

/// The sphere's coverage per pixel (4 × 4 samples per pixel).
pub fn sphere_mask(cam: &PinholeCamera) -> Vec<f32> {
    let mut mask = Vec::with_capacity((cam.width * cam.height) as usize);
    for v in 0..cam.height {
        for u in 0..cam.width {
            let mut hits = 0;
            for sy in 0..4 {
                for sx in 0..4 {
                    let p = DVec2::new(
                        f64::from(u) + (f64::from(sx) + 0.5) / 4.0,
                        f64::from(v) + (f64::from(sy) + 0.5) / 4.0,
                    );
                    hits += u32::from(ray_hits_sphere(cam, p));
                }
            }
            mask.push(hits as f32 / 16.0);
        }
    }
    mask
}

/// Whether `p` is inside the exact visual hull of the sphere seen by `cameras`: in
/// every view, the ray toward `p` meets the sphere (the angle between `p − C` and
/// the sphere centre's direction is at most the sphere's angular radius).
pub fn in_analytic_hull(cameras: &[PinholeCamera], p: DVec3) -> bool {
    cameras.iter().all(|cam| {
        let c = cam.centre();
        let to_centre = SPHERE_CENTRE - c;
        let to_p = p - c;
        let cos = to_centre.normalize().dot(to_p.normalize());
        let cos_max = (1.0 - (SPHERE_RADIUS / to_centre.length()).powi(2)).sqrt();
        cam.camera_from_world(p).z > 0.0 && cos >= cos_max
    })
}

/// Writes a tiny synthetic capture into `dir`: a path-traced procedural head, five
/// 64² views, `targets` held-aside targets under other lightings (direct light
/// only, one sample per texel: seconds).
pub fn tiny_capture(dir: &std::path::Path, targets: usize) {
    tiny_capture_with_sheen(
        dir,
        targets,
        nelf_scene::synth::SynthConfig::default().specular_weight,
    );
}

/// [`tiny_capture`] with the glossy lobe's share of the reflected energy set to
/// `specular_weight` (0: matte).
pub fn tiny_capture_with_sheen(dir: &std::path::Path, targets: usize, specular_weight: f32) {
    let config = nelf_scene::synth::SynthConfig {
        specular_weight,
        width: 64,
        height: 64,
        head_cells: 40,
        targets,
        bounces: 0,
        texel_samples: 1,
        indirect_samples: 0,
        ..nelf_scene::synth::SynthConfig::default()
    };
    if let Err(e) =
        nelf_scene::synth::write_synthetic_capture(&config, dir, &indicatif::ProgressBar::hidden())
    {
        panic!("cannot write the tiny capture: {e}");
    }
}
