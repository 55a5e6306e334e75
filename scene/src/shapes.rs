//! Simple analytic meshes for tests and benchmarks: UV spheres, quads, boxes, and
//! merging meshes. All are wound counter-clockwise seen from outside (outward
//! normals), in metres, with uniform albedo.

use glam::Vec3;

use crate::mesh::{Albedo, Mesh};

/// A UV sphere with `rings` latitude bands (≥ 2) and `segments` longitude sectors
/// (≥ 3): `2·segments·(rings − 1)` triangles.
pub fn uv_sphere(centre: Vec3, radius: f32, rings: u32, segments: u32, albedo: [f32; 3]) -> Mesh {
    let (rings, segments) = (rings.max(2), segments.max(3));
    let mut positions = Vec::with_capacity(((rings + 1) * segments) as usize);
    for i in 0..=rings {
        let theta = std::f32::consts::PI * i as f32 / rings as f32;
        for j in 0..segments {
            let phi = std::f32::consts::TAU * j as f32 / segments as f32;
            let dir = Vec3::new(theta.sin() * phi.cos(), theta.cos(), theta.sin() * phi.sin());
            positions.push(centre + radius * dir);
        }
    }
    let index = |i: u32, j: u32| i * segments + j % segments;
    let mut triangles = Vec::with_capacity((2 * segments * (rings - 1)) as usize);
    for i in 0..rings {
        for j in 0..segments {
            let (a, b, c, d) = (index(i, j), index(i, j + 1), index(i + 1, j), index(i + 1, j + 1));
            // Ring 0 and ring `rings` are the poles (repeated vertices): one triangle per sector there.
            if i > 0 {
                triangles.push([a, b, c]);
            }
            if i + 1 < rings {
                triangles.push([b, d, c]);
            }
        }
    }
    Mesh {
        positions,
        triangles,
        albedo: Albedo::Uniform(albedo),
    }
}

/// A quad `corner, corner + edge_u, corner + edge_u + edge_v, corner + edge_v`,
/// facing `edge_u × edge_v`, split into `n × n` cells (2 triangles each).
pub fn quad(corner: Vec3, edge_u: Vec3, edge_v: Vec3, n: u32, albedo: [f32; 3]) -> Mesh {
    let n = n.max(1);
    let mut positions = Vec::with_capacity(((n + 1) * (n + 1)) as usize);
    for j in 0..=n {
        for i in 0..=n {
            positions.push(corner + edge_u * (i as f32 / n as f32) + edge_v * (j as f32 / n as f32));
        }
    }
    let index = |i: u32, j: u32| j * (n + 1) + i;
    let mut triangles = Vec::with_capacity((2 * n * n) as usize);
    for j in 0..n {
        for i in 0..n {
            let (a, b, c, d) = (index(i, j), index(i + 1, j), index(i + 1, j + 1), index(i, j + 1));
            triangles.push([a, b, c]);
            triangles.push([a, c, d]);
        }
    }
    Mesh {
        positions,
        triangles,
        albedo: Albedo::Uniform(albedo),
    }
}

/// An axis-aligned box from `min` to `max`, faces split `n × n`. With `inward` the
/// faces point into the box (its interior is the visible side); with `open_top`
/// the `+y` face is left out.
pub fn boxed(min: Vec3, max: Vec3, n: u32, inward: bool, open_top: bool, albedo: [f32; 3]) -> Mesh {
    let e = max - min;
    let (x, y, z) = (
        Vec3::new(e.x, 0.0, 0.0),
        Vec3::new(0.0, e.y, 0.0),
        Vec3::new(0.0, 0.0, e.z),
    );
    // Outward faces as (corner, u, v) with u × v pointing out.
    let mut faces = vec![
        (min, z, y),     // −x
        (min + x, y, z), // +x
        (min, x, z),     // −y
        (min, y, x),     // −z
        (min + z, x, y), // +z
    ];
    if !open_top {
        faces.push((min + y, z, x)); // +y
    }
    let parts: Vec<Mesh> = faces
        .into_iter()
        .map(|(c, u, v)| {
            if inward {
                quad(c, v, u, n, albedo)
            } else {
                quad(c, u, v, n, albedo)
            }
        })
        .collect();
    merge(&parts)
}

/// Concatenates meshes. Albedo becomes per-vertex when the parts' uniform albedos
/// differ (non-uniform parts keep their per-vertex colours; textured parts use
/// their mean texel colour).
pub fn merge(parts: &[Mesh]) -> Mesh {
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    let mut colours = Vec::new();
    for part in parts {
        let offset = positions.len() as u32;
        positions.extend_from_slice(&part.positions);
        triangles.extend(part.triangles.iter().map(|t| t.map(|i| i + offset)));
        match &part.albedo {
            Albedo::Uniform(c) => colours.extend(std::iter::repeat_n(*c, part.positions.len())),
            Albedo::PerVertex(c) => colours.extend_from_slice(c),
            Albedo::Texture { texture, .. } => {
                let n = texture.texels.len().max(1) as f32;
                let mean = texture
                    .texels
                    .iter()
                    .fold([0.0f32; 3], |acc, t| std::array::from_fn(|i| acc[i] + t[i] / n));
                colours.extend(std::iter::repeat_n(mean, part.positions.len()));
            }
        }
    }
    let albedo = match colours.first() {
        Some(first) if colours.iter().all(|c| c == first) => Albedo::Uniform(*first),
        _ => Albedo::PerVertex(colours),
    };
    Mesh {
        positions,
        triangles,
        albedo,
    }
}

/// Rotates every vertex of `mesh` by `rotation` about the origin.
pub fn rotated(mesh: &Mesh, rotation: glam::Mat3) -> Mesh {
    let mut out = mesh.clone();
    for p in &mut out.positions {
        *p = rotation * *p;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shapes_are_valid_and_outward() {
        let s = uv_sphere(Vec3::new(0.1, 0.2, 0.3), 0.5, 8, 12, [0.5; 3]);
        s.validate().unwrap();
        assert_eq!(s.triangles.len(), 2 * 12 * 7);
        for t in 0..s.triangles.len() {
            let [a, b, c] = s.corners(t);
            let centroid = (a + b + c) / 3.0 - Vec3::new(0.1, 0.2, 0.3);
            assert!(s.face_normal(t).dot(centroid) > 0.0, "triangle {t} faces inward");
        }
        let b = boxed(Vec3::ZERO, Vec3::ONE, 2, false, false, [0.5; 3]);
        b.validate().unwrap();
        for t in 0..b.triangles.len() {
            let [p, q, r] = b.corners(t);
            let centroid = (p + q + r) / 3.0 - Vec3::splat(0.5);
            assert!(b.face_normal(t).dot(centroid) > 0.0);
        }
        let inner = boxed(Vec3::ZERO, Vec3::ONE, 1, true, true, [0.5; 3]);
        assert_eq!(inner.triangles.len(), 10);
        let merged = merge(&[s, quad(Vec3::ZERO, Vec3::X, Vec3::NEG_Z, 1, [0.1; 3])]);
        merged.validate().unwrap();
        assert!(matches!(merged.albedo, Albedo::PerVertex(_)));
    }
}
