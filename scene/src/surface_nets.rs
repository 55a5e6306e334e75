//! A triangle mesh of the zero level of a scalar field sampled on a regular grid,
//! by naive surface nets (Gibson 1998, "Constrained elastic surface nets"): one
//! vertex per grid cell the surface crosses, at the mean of the zero crossings on
//! the cell's twelve edges (linear interpolation of the samples), and one quad —
//! split into two triangles along its shorter diagonal — for every grid edge whose
//! ends have opposite signs, joining the vertices of the four cells around it.
//!
//! Negative samples are inside. Triangles are wound counter-clockwise seen from
//! outside (their normals point toward increasing values). A field that is
//! negative only strictly inside the grid (every sample on the grid's faces
//! non-negative) gives a closed, oriented surface: every edge is shared by exactly
//! two triangles, except where the net pinches (a cell vertex shared by two sheets),
//! which stays watertight but not manifold.

use glam::{DVec3, Vec3};

/// Samples of a scalar field on a regular grid: `values[(z·ny + y)·nx + x]` at
/// `origin_m + spacing_m·(x, y, z)`.
#[derive(Debug, Clone, Copy)]
pub struct GridSamples<'a> {
    /// Samples, x fastest.
    pub values: &'a [f32],
    /// Samples per axis (at least 2 each).
    pub dims: [usize; 3],
    /// Position of sample (0, 0, 0), metres.
    pub origin_m: DVec3,
    /// Distance between neighbouring samples, metres.
    pub spacing_m: f64,
}

/// The surface: vertex positions (metres) and counter-clockwise triangles.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SurfaceNet {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Triangles, outward (toward positive samples) counter-clockwise.
    pub triangles: Vec<[u32; 3]>,
}

/// Grid-cell corner offsets, bit `i` of the index = offset along axis `i`.
const CORNERS: [[usize; 3]; 8] = [
    [0, 0, 0],
    [1, 0, 0],
    [0, 1, 0],
    [1, 1, 0],
    [0, 0, 1],
    [1, 0, 1],
    [0, 1, 1],
    [1, 1, 1],
];

/// The twelve cell edges as pairs of corner indices.
const EDGES: [[usize; 2]; 12] = [
    [0, 1],
    [2, 3],
    [4, 5],
    [6, 7],
    [0, 2],
    [1, 3],
    [4, 6],
    [5, 7],
    [0, 4],
    [1, 5],
    [2, 6],
    [3, 7],
];

/// The zero level of `grid` as a surface net (see the module documentation).
/// Returns an empty net when `grid` is malformed (fewer than 2 samples on an axis
/// or `values` of the wrong length) or no cell is crossed. Non-finite samples count
/// as outside.
pub fn surface_net(grid: &GridSamples<'_>) -> SurfaceNet {
    let [nx, ny, nz] = grid.dims;
    if nx < 2 || ny < 2 || nz < 2 || grid.values.len() != nx * ny * nz {
        return SurfaceNet::default();
    }
    let value = |x: usize, y: usize, z: usize| {
        let v = grid.values[(z * ny + y) * nx + x];
        if v.is_finite() { v } else { f32::MAX }
    };
    let (cx, cy, cz) = (nx - 1, ny - 1, nz - 1);
    let mut cell_vertex = vec![u32::MAX; cx * cy * cz];
    let mut positions = Vec::new();
    for z in 0..cz {
        for y in 0..cy {
            for x in 0..cx {
                let corner = CORNERS.map(|[dx, dy, dz]| value(x + dx, y + dy, z + dz));
                let inside = corner.iter().filter(|&&v| v < 0.0).count();
                if inside == 0 || inside == 8 {
                    continue;
                }
                let mut sum = DVec3::ZERO;
                let mut crossings = 0.0;
                for [a, b] in EDGES {
                    let (va, vb) = (corner[a], corner[b]);
                    if (va < 0.0) == (vb < 0.0) {
                        continue;
                    }
                    let t = f64::from(va / (va - vb)).clamp(0.0, 1.0);
                    let pa = DVec3::from_array(CORNERS[a].map(|c| c as f64));
                    let pb = DVec3::from_array(CORNERS[b].map(|c| c as f64));
                    sum += pa + (pb - pa) * t;
                    crossings += 1.0;
                }
                let local = sum / crossings;
                let p = grid.origin_m + (DVec3::new(x as f64, y as f64, z as f64) + local) * grid.spacing_m;
                cell_vertex[(z * cy + y) * cx + x] = positions.len() as u32;
                positions.push(p.as_vec3());
            }
        }
    }
    let cell = |x: usize, y: usize, z: usize| cell_vertex[(z * cy + y) * cx + x];
    let mut triangles = Vec::new();
    let mut quad = |q: [u32; 4], outward: bool| {
        if q.contains(&u32::MAX) {
            return;
        }
        let q = if outward { q } else { [q[3], q[2], q[1], q[0]] };
        let p = q.map(|i| positions[i as usize]);
        if p[0].distance_squared(p[2]) <= p[1].distance_squared(p[3]) {
            triangles.push([q[0], q[1], q[2]]);
            triangles.push([q[0], q[2], q[3]]);
        } else {
            triangles.push([q[0], q[1], q[3]]);
            triangles.push([q[1], q[2], q[3]]);
        }
    };
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                let v0 = value(x, y, z) < 0.0;
                // Edge along +x: the cells around it are (x, y-1..y, z-1..z).
                if x + 1 < nx && y >= 1 && z >= 1 && y < cy && z < cz && v0 != (value(x + 1, y, z) < 0.0) {
                    quad(
                        [
                            cell(x, y - 1, z - 1),
                            cell(x, y, z - 1),
                            cell(x, y, z),
                            cell(x, y - 1, z),
                        ],
                        v0,
                    );
                }
                // Edge along +y: cells (x-1..x, y, z-1..z), ordered in the (z, x) plane.
                if y + 1 < ny && x >= 1 && z >= 1 && x < cx && z < cz && v0 != (value(x, y + 1, z) < 0.0) {
                    quad(
                        [
                            cell(x - 1, y, z - 1),
                            cell(x - 1, y, z),
                            cell(x, y, z),
                            cell(x, y, z - 1),
                        ],
                        v0,
                    );
                }
                // Edge along +z: cells (x-1..x, y-1..y, z), ordered in the (x, y) plane.
                if z + 1 < nz && x >= 1 && y >= 1 && x < cx && y < cy && v0 != (value(x, y, z + 1) < 0.0) {
                    quad(
                        [
                            cell(x - 1, y - 1, z),
                            cell(x, y - 1, z),
                            cell(x, y, z),
                            cell(x - 1, y, z),
                        ],
                        v0,
                    );
                }
            }
        }
    }
    SurfaceNet { positions, triangles }
}

/// Each vertex's edge neighbours (sorted, each once), for `vertex_count` vertices;
/// corners out of range are skipped.
pub fn vertex_neighbours(vertex_count: usize, triangles: &[[u32; 3]]) -> Vec<Vec<u32>> {
    let mut neighbours: Vec<Vec<u32>> = vec![Vec::new(); vertex_count];
    for t in triangles {
        for i in 0..3 {
            let (a, b) = (t[i], t[(i + 1) % 3]);
            if (a as usize) < vertex_count && (b as usize) < vertex_count {
                neighbours[a as usize].push(b);
                neighbours[b as usize].push(a);
            }
        }
    }
    for list in &mut neighbours {
        list.sort_unstable();
        list.dedup();
    }
    neighbours
}

/// Taubin's λ|μ smoothing (Taubin 1995): `iterations` pairs of a shrinking
/// (`λ = 0.5`) and an inflating (`μ = −0.53`) umbrella step over the mesh's edge
/// neighbours, which removes the grid's staircase without the shrinkage plain
/// Laplacian smoothing causes. Vertices of no triangle stay where they are.
pub fn taubin_smooth(positions: &mut [Vec3], triangles: &[[u32; 3]], iterations: usize) {
    let neighbours = vertex_neighbours(positions.len(), triangles);
    let mut next = positions.to_vec();
    for _ in 0..iterations {
        for factor in [0.5f32, -0.53] {
            for (i, list) in neighbours.iter().enumerate() {
                if list.is_empty() {
                    continue;
                }
                let mean = list.iter().map(|&j| positions[j as usize]).sum::<Vec3>() / list.len() as f32;
                next[i] = positions[i] + factor * (mean - positions[i]);
            }
            positions.copy_from_slice(&next);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    fn sphere_grid(n: usize, radius: f64) -> (Vec<f32>, GridSamples<'static>) {
        let spacing = 2.0 / (n - 1) as f64;
        let origin = DVec3::splat(-1.0);
        let mut values = Vec::with_capacity(n * n * n);
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    let p = origin + DVec3::new(x as f64, y as f64, z as f64) * spacing;
                    values.push((p.length() - radius) as f32);
                }
            }
        }
        let empty: &'static [f32] = &[];
        (
            values,
            GridSamples {
                values: empty,
                dims: [n; 3],
                origin_m: origin,
                spacing_m: spacing,
            },
        )
    }

    #[test]
    fn a_sphere_becomes_a_closed_outward_mesh_on_its_radius() {
        let (values, mut grid) = sphere_grid(33, 0.6);
        grid.values = &values;
        let net = surface_net(&grid);
        assert!(net.positions.len() > 500, "{} vertices", net.positions.len());
        for p in &net.positions {
            assert!(
                (p.length() - 0.6).abs() < 0.25 * grid.spacing_m as f32,
                "vertex at radius {}",
                p.length()
            );
        }
        // Closed: every directed edge has its reverse exactly once.
        let mut edges: HashMap<(u32, u32), usize> = HashMap::new();
        for t in &net.triangles {
            for i in 0..3 {
                *edges.entry((t[i], t[(i + 1) % 3])).or_default() += 1;
            }
        }
        for (&(a, b), &count) in &edges {
            assert_eq!(count, 1, "edge {a}-{b} used {count} times in one direction");
            assert_eq!(edges.get(&(b, a)), Some(&1), "edge {a}-{b} is open");
        }
        // Outward: every triangle's normal points away from the centre, and the
        // enclosed volume is the sphere's within 2 %.
        let mut volume = 0.0f64;
        for t in &net.triangles {
            let [a, b, c] = t.map(|i| net.positions[i as usize].as_dvec3());
            let normal = (b - a).cross(c - a);
            assert!(normal.dot(a + b + c) > 0.0, "an inward triangle");
            volume += a.dot(b.cross(c)) / 6.0;
        }
        let expected = 4.0 / 3.0 * std::f64::consts::PI * 0.6f64.powi(3);
        assert!(
            (volume / expected - 1.0).abs() < 0.02,
            "volume {volume} vs {expected}"
        );
        // Euler characteristic of a sphere.
        let chi = net.positions.len() as i64 - (edges.len() / 2) as i64 + net.triangles.len() as i64;
        assert_eq!(chi, 2);
    }

    #[test]
    fn smoothing_keeps_a_sphere_near_its_radius_and_its_triangles_even() {
        let (values, mut grid) = sphere_grid(25, 0.6);
        grid.values = &values;
        let mut net = surface_net(&grid);
        // Spread of the triangles' normals about the radial direction: the staircase.
        let normal_error = |p: &[Vec3]| {
            let mut sum = 0.0f64;
            for t in &net.triangles {
                let [a, b, c] = t.map(|i| p[i as usize].as_dvec3());
                let n = (b - a).cross(c - a).normalize();
                sum += n.dot((a + b + c).normalize()).clamp(-1.0, 1.0).acos();
            }
            sum / net.triangles.len() as f64
        };
        let before = normal_error(&net.positions);
        let mut positions = net.positions.clone();
        taubin_smooth(&mut positions, &net.triangles, 10);
        let after = normal_error(&positions);
        let mean = positions.iter().map(|p| f64::from(p.length())).sum::<f64>() / positions.len() as f64;
        assert!((mean - 0.6).abs() < 0.01, "mean radius {mean}");
        assert!(
            after < 0.9 * before,
            "normal error {after} rad after smoothing, {before} before"
        );
        net.positions = positions;
    }

    #[test]
    fn malformed_or_uncrossed_grids_give_nothing() {
        let values = vec![1.0f32; 27];
        let grid = GridSamples {
            values: &values,
            dims: [3, 3, 3],
            origin_m: DVec3::ZERO,
            spacing_m: 1.0,
        };
        assert!(surface_net(&grid).triangles.is_empty());
        let short = GridSamples {
            values: &values[..20],
            ..grid
        };
        assert!(surface_net(&short).positions.is_empty());
    }
}
