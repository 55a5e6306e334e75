//! The reconstruction's albedo as a texture a DCC tool opens: every triangle gets
//! its own square cell of `cell × cell` texels in one atlas image, its corners at
//! `(m, m)`, `(cell − m, m)` and `(m, cell − m)` texels from the cell's lower-left
//! corner (a right isosceles chart; `m` = 1 texel of gutter). Each texel of the cell
//! takes the albedo at its centre's barycentric coordinates, clamped onto the
//! triangle, so the gutter repeats the triangle's edge and nearest-texel or
//! bilinear sampling, mipmaps aside, never reads a neighbour's colour. Charts keep
//! no adjacency (a triangle soup in UV space): the texture holds what the per-vertex
//! albedo holds, in the form OBJ + MTL + image readers take.

use glam::Vec2;
use nelf_scene::mesh::{Albedo, Mesh, Texture};

/// Texels along a cell's side by default: 8, the JPEG block, so that a block never
/// straddles two charts' luminance.
pub const DEFAULT_CELL_TEXELS: usize = 8;

/// `mesh` with its albedo moved into an atlas texture (module docs); a mesh whose
/// albedo is already a texture is returned as it is.
pub fn texture_atlas(mesh: &Mesh, cell_texels: usize) -> Mesh {
    if matches!(mesh.albedo, Albedo::Texture { .. }) {
        return mesh.clone();
    }
    texture_atlas_from(mesh, cell_texels, |t, b1, b2| mesh.albedo_at(t, b1, b2))
}

/// `mesh` with an atlas texture (module docs) whose texels take `albedo(t, b1, b2)`
/// at their centres' barycentric coordinates on triangle `t`.
pub fn texture_atlas_from(
    mesh: &Mesh,
    cell_texels: usize,
    albedo: impl Fn(usize, f32, f32) -> [f32; 3],
) -> Mesh {
    let cell = cell_texels.max(4);
    let margin = 1.0_f32;
    let leg = cell as f32 - 2.0 * margin;
    let count = mesh.triangles.len().max(1);
    let columns = (count as f64).sqrt().ceil() as usize;
    let rows = count.div_ceil(columns);
    let (width, height) = (columns * cell, rows * cell);
    let mut texels = vec![[0.0_f32; 3]; width * height];
    let mut uvs = Vec::with_capacity(3 * mesh.triangles.len());
    for t in 0..mesh.triangles.len() {
        // Cell (column, row), rows counted from the bottom (v up).
        let (column, row) = (t % columns, t / columns);
        let origin = Vec2::new((column * cell) as f32 + margin, (row * cell) as f32 + margin);
        let size = Vec2::new(width as f32, height as f32);
        uvs.push(origin / size);
        uvs.push((origin + Vec2::new(leg, 0.0)) / size);
        uvs.push((origin + Vec2::new(0.0, leg)) / size);
        for dy in 0..cell {
            for dx in 0..cell {
                let x = column * cell + dx;
                let y_up = row * cell + dy;
                // Texel centre in the chart's frame, in legs.
                let mut b1 = ((x as f32 + 0.5) - origin.x) / leg;
                let mut b2 = ((y_up as f32 + 0.5) - origin.y) / leg;
                b1 = b1.max(0.0);
                b2 = b2.max(0.0);
                let sum = b1 + b2;
                if sum > 1.0 {
                    b1 /= sum;
                    b2 /= sum;
                }
                let y_top = height - 1 - y_up;
                texels[y_top * width + x] = albedo(t, b1, b2);
            }
        }
    }
    Mesh {
        positions: mesh.positions.clone(),
        triangles: mesh.triangles.clone(),
        albedo: Albedo::Texture {
            uvs,
            texture: Texture {
                width,
                height,
                texels,
            },
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// A strip of triangles with a colour per vertex.
    fn strip(n: usize) -> Mesh {
        let positions: Vec<Vec3> = (0..n + 2)
            .map(|i| Vec3::new((i / 2) as f32 * 0.01, (i % 2) as f32 * 0.01, 0.0))
            .collect();
        let triangles = (0..n as u32).map(|i| [i, i + 1, i + 2]).collect();
        let colours = (0..n + 2)
            .map(|i| {
                let f = i as f32 / (n + 1) as f32;
                [f, 1.0 - f, 0.25 + 0.5 * (i % 2) as f32]
            })
            .collect();
        Mesh {
            positions,
            triangles,
            albedo: Albedo::PerVertex(colours),
        }
    }

    #[test]
    fn the_atlas_holds_the_vertex_albedo_at_every_point_of_every_triangle() {
        let mesh = strip(37);
        let atlas = texture_atlas(&mesh, DEFAULT_CELL_TEXELS);
        assert!(atlas.validate().is_ok());
        let Albedo::Texture { uvs, texture } = &atlas.albedo else {
            panic!("not a texture")
        };
        assert_eq!(uvs.len(), 3 * mesh.triangles.len());
        assert!(
            uvs.iter()
                .all(|uv| (0.0..=1.0).contains(&uv.x) && (0.0..=1.0).contains(&uv.y))
        );
        assert_eq!(texture.width % DEFAULT_CELL_TEXELS, 0);
        // At corners, edge midpoints and the centroid, the nearest texel's albedo is
        // the interpolated one within a texel's change of colour.
        let leg = (DEFAULT_CELL_TEXELS - 2) as f32;
        for t in 0..mesh.triangles.len() {
            for (b1, b2) in [
                (0.0, 0.0),
                (1.0, 0.0),
                (0.0, 1.0),
                (0.5, 0.5),
                (1.0 / 3.0, 1.0 / 3.0),
                (0.5, 0.0),
            ] {
                let want = mesh.albedo_at(t, b1, b2);
                let got = atlas.albedo_at(t, b1, b2);
                // Neighbouring vertices differ by at most 0.5 here: a texel centre
                // half a texel off in each axis is off by at most 0.5 / leg.
                let tolerance = 0.5 / leg + 1e-4;
                for ch in 0..3 {
                    assert!(
                        (want[ch] - got[ch]).abs() <= tolerance,
                        "t {t} ({b1}, {b2}) ch {ch}: {want:?} vs {got:?}"
                    );
                }
            }
        }
    }
}
