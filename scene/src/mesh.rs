//! Triangle meshes with diffuse albedo: the geometry every ground-truth render
//! starts from. Positions in metres, world frame right-handed with +y up.
//! Albedo is one of: uniform, per vertex (interpolated barycentrically), or an
//! RGB texture addressed by per-corner UVs (nearest texel, `v` up as in OBJ).

use glam::{Vec2, Vec3};

/// Errors building or validating a mesh.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// A triangle refers to a vertex that does not exist.
    #[error("triangle {triangle} refers to vertex {index}, but the mesh has {vertices} vertices")]
    IndexOutOfRange {
        /// Triangle number.
        triangle: usize,
        /// The bad index.
        index: u32,
        /// Vertex count.
        vertices: usize,
    },
    /// A position or albedo value is NaN or infinite.
    #[error("{what} {index} is not finite")]
    NotFinite {
        /// Which array.
        what: &'static str,
        /// Element number.
        index: usize,
    },
    /// The albedo arrays do not match the geometry.
    #[error("albedo does not match the mesh: {0}")]
    AlbedoMismatch(String),
    /// No triangles.
    #[error("the mesh has no triangles")]
    Empty,
}

/// An RGB texture in linear colour, row 0 at the top (`v = 1`).
#[derive(Debug, Clone, PartialEq)]
pub struct Texture {
    /// Width in texels.
    pub width: usize,
    /// Height in texels.
    pub height: usize,
    /// Row-major linear RGB texels, row 0 at the top.
    pub texels: Vec<[f32; 3]>,
}

impl Texture {
    /// Nearest texel at `uv` (wrapping), `v = 0` at the bottom row.
    pub fn sample(&self, uv: Vec2) -> [f32; 3] {
        let x = (uv.x.rem_euclid(1.0) * self.width as f32) as usize;
        let y = ((1.0 - uv.y.rem_euclid(1.0)) * self.height as f32) as usize;
        self.texels[y.min(self.height - 1) * self.width + x.min(self.width - 1)]
    }
}

/// Widest box [`Mesh::albedo_footprint`] averages, texels a side.
pub const MAX_FOOTPRINT_TEXELS: usize = 64;

/// Diffuse albedo over a mesh, linear RGB in `[0, 1]`.
#[derive(Debug, Clone, PartialEq)]
pub enum Albedo {
    /// One colour everywhere.
    Uniform([f32; 3]),
    /// One colour per vertex, interpolated.
    PerVertex(Vec<[f32; 3]>),
    /// A texture with three UVs per triangle (`uvs[3·t + corner]`).
    Texture {
        /// Per-corner texture coordinates.
        uvs: Vec<Vec2>,
        /// The image.
        texture: Texture,
    },
}

/// A triangle mesh with albedo.
#[derive(Debug, Clone, PartialEq)]
pub struct Mesh {
    /// Vertex positions, metres.
    pub positions: Vec<Vec3>,
    /// Counter-clockwise (outward-facing) triangles.
    pub triangles: Vec<[u32; 3]>,
    /// Diffuse albedo.
    pub albedo: Albedo,
}

impl Mesh {
    /// Checks indices, finiteness and albedo sizes.
    pub fn validate(&self) -> Result<(), MeshError> {
        if self.triangles.is_empty() {
            return Err(MeshError::Empty);
        }
        let n = self.positions.len();
        for (i, p) in self.positions.iter().enumerate() {
            if !p.is_finite() {
                return Err(MeshError::NotFinite {
                    what: "position",
                    index: i,
                });
            }
        }
        for (t, tri) in self.triangles.iter().enumerate() {
            for &index in tri {
                if index as usize >= n {
                    return Err(MeshError::IndexOutOfRange {
                        triangle: t,
                        index,
                        vertices: n,
                    });
                }
            }
        }
        match &self.albedo {
            Albedo::Uniform(c) => {
                if !c.iter().all(|v| v.is_finite()) {
                    return Err(MeshError::NotFinite {
                        what: "albedo",
                        index: 0,
                    });
                }
            }
            Albedo::PerVertex(colours) => {
                if colours.len() != n {
                    return Err(MeshError::AlbedoMismatch(format!(
                        "{} vertex colours for {n} vertices",
                        colours.len()
                    )));
                }
            }
            Albedo::Texture { uvs, texture } => {
                if uvs.len() != 3 * self.triangles.len() {
                    return Err(MeshError::AlbedoMismatch(format!(
                        "{} UVs for {} triangle corners",
                        uvs.len(),
                        3 * self.triangles.len()
                    )));
                }
                if texture.width == 0
                    || texture.height == 0
                    || texture.texels.len() != texture.width * texture.height
                {
                    return Err(MeshError::AlbedoMismatch(format!(
                        "texture {}×{} holds {} texels",
                        texture.width,
                        texture.height,
                        texture.texels.len()
                    )));
                }
            }
        }
        Ok(())
    }

    /// Axis-aligned bounds `(min, max)`.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        self.positions.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), &p| (lo.min(p), hi.max(p)),
        )
    }

    /// Centre (the bounding-box centre) and radius (the farthest vertex from it) of
    /// a sphere around the mesh, metres: what a camera must frame.
    pub fn bounding_sphere(&self) -> (glam::DVec3, f64) {
        let (lo, hi) = self.bounds();
        let centre = (0.5 * (lo + hi)).as_dvec3();
        let radius = self
            .positions
            .iter()
            .map(|p| (p.as_dvec3() - centre).length())
            .fold(0.0, f64::max);
        (centre, radius)
    }

    /// The three corners of triangle `t`.
    pub fn corners(&self, t: usize) -> [Vec3; 3] {
        self.triangles[t].map(|i| self.positions[i as usize])
    }

    /// Unit geometric normal of triangle `t` (counter-clockwise = outward).
    pub fn face_normal(&self, t: usize) -> Vec3 {
        let [a, b, c] = self.corners(t);
        (b - a).cross(c - a).normalize_or_zero()
    }

    /// Albedo at barycentric coordinates `(b1, b2)` of triangle `t`
    /// (the point is `(1 − b1 − b2)·a + b1·b + b2·c`).
    pub fn albedo_at(&self, t: usize, b1: f32, b2: f32) -> [f32; 3] {
        let b0 = 1.0 - b1 - b2;
        match &self.albedo {
            Albedo::Uniform(c) => *c,
            Albedo::PerVertex(colours) => {
                let [i, j, k] = self.triangles[t].map(|v| colours[v as usize]);
                std::array::from_fn(|ch| b0 * i[ch] + b1 * j[ch] + b2 * k[ch])
            }
            Albedo::Texture { uvs, texture } => {
                let uv = b0 * uvs[3 * t] + b1 * uvs[3 * t + 1] + b2 * uvs[3 * t + 2];
                texture.sample(uv)
            }
        }
    }

    /// Albedo averaged over a square of side `footprint_m` metres around barycentric
    /// `(b1, b2)` of triangle `t`, within that triangle: what a voxel of that size sees
    /// of a texture finer than itself (a box filter in the triangle's texture space).
    /// Read at one point instead ([`Self::albedo_at`]), a pore or stubble texel that
    /// happens to lie there darkens the whole voxel: a speck the surface does not show at
    /// that scale. Texels are averaged whose centres lie in the triangle's UV triangle
    /// and within the square (at most [`MAX_FOOTPRINT_TEXELS`] a side, so a texel from
    /// another island of an atlas never leaks in); with none, or for uniform and
    /// per-vertex albedo, the point value.
    pub fn albedo_footprint(&self, t: usize, b1: f32, b2: f32, footprint_m: f32) -> [f32; 3] {
        let Albedo::Texture { uvs, texture } = &self.albedo else {
            return self.albedo_at(t, b1, b2);
        };
        let [a, b, c] = self.corners(t);
        let world_area = 0.5 * (b - a).cross(c - a).length();
        let size = Vec2::new(texture.width as f32, texture.height as f32);
        // Corners in texel units (x right, y up as v).
        let [p0, p1, p2] = [uvs[3 * t], uvs[3 * t + 1], uvs[3 * t + 2]].map(|uv| uv * size);
        let texel_area = 0.5 * (p1 - p0).perp_dot(p2 - p0).abs();
        if !(world_area > 0.0 && texel_area > 0.0 && footprint_m > 0.0) {
            return self.albedo_at(t, b1, b2);
        }
        let half =
            (0.5 * footprint_m * (texel_area / world_area).sqrt()).min(0.5 * MAX_FOOTPRINT_TEXELS as f32);
        if half < 0.5 {
            return self.albedo_at(t, b1, b2);
        }
        let centre = (1.0 - b1 - b2) * p0 + b1 * p1 + b2 * p2;
        let inside = |q: Vec2| {
            let d0 = (p1 - p0).perp_dot(q - p0);
            let d1 = (p2 - p1).perp_dot(q - p1);
            let d2 = (p0 - p2).perp_dot(q - p2);
            (d0 >= 0.0 && d1 >= 0.0 && d2 >= 0.0) || (d0 <= 0.0 && d1 <= 0.0 && d2 <= 0.0)
        };
        let (x0, x1) = ((centre.x - half).floor() as i64, (centre.x + half).ceil() as i64);
        let (y0, y1) = ((centre.y - half).floor() as i64, (centre.y + half).ceil() as i64);
        let mut sum = [0.0f64; 3];
        let mut count = 0u32;
        for y in y0..y1 {
            for x in x0..x1 {
                let q = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                if (q - centre).abs().max_element() > half || !inside(q) {
                    continue;
                }
                let col = x.rem_euclid(texture.width as i64) as usize;
                // Texel row 0 is the top (v = 1).
                let row = (texture.height as i64 - 1 - y.rem_euclid(texture.height as i64)) as usize;
                let texel = texture.texels[row * texture.width + col];
                for ch in 0..3 {
                    sum[ch] += f64::from(texel[ch]);
                }
                count += 1;
            }
        }
        if count == 0 {
            return self.albedo_at(t, b1, b2);
        }
        sum.map(|v| (v / f64::from(count)) as f32)
    }

    /// Translates and uniformly scales the mesh so its bounding box is centred at
    /// `centre` and its height (y extent) is `height_m` metres.
    pub fn fit_height(&mut self, centre: Vec3, height_m: f32) {
        let (lo, hi) = self.bounds();
        let extent = (hi.y - lo.y).max(f32::MIN_POSITIVE);
        let scale = height_m / extent;
        let mid = 0.5 * (lo + hi);
        for p in &mut self.positions {
            *p = (*p - mid) * scale + centre;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad() -> Mesh {
        Mesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 2.0, 0.0), Vec3::Y * 2.0],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            albedo: Albedo::PerVertex(vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0; 3]]),
        }
    }

    /// A 64 × 64 texture on a right triangle of 1 m legs spanning `uv` (0,0)–(1,0)–(0,1):
    /// texels whose centres lie in the triangle (`col ≤ row`, row 0 at the top) get
    /// `inside(row, col)`, the others (another island of an atlas) grey.
    fn textured_triangle(inside: impl Fn(usize, usize) -> f32) -> Mesh {
        let texels = (0..64 * 64)
            .map(|i| {
                let (row, col) = (i / 64, i % 64);
                if col <= row {
                    [inside(row, col); 3]
                } else {
                    [0.5; 3]
                }
            })
            .collect();
        Mesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            triangles: vec![[0, 1, 2]],
            albedo: Albedo::Texture {
                uvs: vec![Vec2::ZERO, Vec2::X, Vec2::Y],
                texture: Texture {
                    width: 64,
                    height: 64,
                    texels,
                },
            },
        }
    }

    #[test]
    fn footprint_albedo_averages_fine_texture_within_the_triangle() {
        // A checkerboard of 1-texel squares: a point reads black or white.
        let m = textured_triangle(|row, col| ((row + col) % 2) as f32);
        let point = m.albedo_at(0, 0.25, 0.25)[0];
        assert!(point == 0.0 || point == 1.0, "{point}");
        // A 10 cm footprint (6.4 texels) averages it to about one half.
        let box_mean = m.albedo_footprint(0, 0.25, 0.25, 0.1)[0];
        assert!((box_mean - 0.5).abs() < 0.05, "{box_mean}");
        // At the hypotenuse the grey texels outside the triangle do not leak in.
        let white = textured_triangle(|_, _| 1.0);
        assert_eq!(white.albedo_footprint(0, 0.49, 0.49, 0.2), [1.0; 3]);
        // Below a texel, and for other albedo kinds, the point value.
        assert_eq!(m.albedo_footprint(0, 0.25, 0.25, 0.001)[0], point);
        assert_eq!(
            quad().albedo_footprint(0, 0.5, 0.5, 1.0),
            quad().albedo_at(0, 0.5, 0.5)
        );
    }

    #[test]
    fn validates_and_interpolates() {
        let mut m = quad();
        m.validate().unwrap();
        assert_eq!(m.albedo_at(0, 1.0, 0.0), [1.0, 0.0, 0.0]);
        assert_eq!(m.albedo_at(0, 0.5, 0.5), [0.5, 0.5, 0.0]);
        assert!(m.face_normal(0).abs_diff_eq(Vec3::Z, 1e-6));
        m.fit_height(Vec3::new(0.0, 1.0, 0.0), 0.2);
        let (lo, hi) = m.bounds();
        assert!((hi.y - lo.y - 0.2).abs() < 1e-6);
        assert!((0.5 * (lo + hi)).abs_diff_eq(Vec3::Y, 1e-6));
        m.triangles.push([0, 1, 9]);
        assert!(matches!(
            m.validate(),
            Err(MeshError::IndexOutOfRange { index: 9, .. })
        ));
    }
}
