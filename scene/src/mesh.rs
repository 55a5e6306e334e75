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
