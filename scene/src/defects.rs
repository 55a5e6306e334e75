//! Test meshes with the defects real scans have, generated in code so that tests
//! and benchmarks never depend on our own watertight procedural heads alone:
//!
//! * one-sided open sheets with boundary edges ([`crate::shapes::quad`], [`open_band`]);
//! * holes of many sizes in a closed surface ([`torn_sphere`]);
//! * pieces not connected to the rest, and surfaces that cross each other
//!   ([`crate::shapes::merge`]);
//! * flipped triangles ([`with_flipped_triangles`]) and non-manifold edges ([`with_fin`]);
//! * textured albedo through per-corner UVs ([`textured_quad`], [`head_and_shoulders`]);
//! * a head-and-shoulders figure whose shirt collar is a thin open sheet around the
//!   neck, flaps lying on the chest, and a striped shirt texture ([`head_and_shoulders`]).
//!
//! Every generator is deterministic. Units are metres, +y up, the face toward +z.

use glam::{Vec2, Vec3};

use crate::mesh::{Albedo, Mesh, Texture};
use crate::shapes::uv_sphere;

/// A UV sphere with the triangles removed whose centroids lie within the given
/// angles (radians) of the given directions from the centre: holes of any sizes.
pub fn torn_sphere(centre: Vec3, radius: f32, holes: &[(Vec3, f32)], albedo: [f32; 3]) -> Mesh {
    let mut mesh = uv_sphere(centre, radius, 24, 48, albedo);
    let holes: Vec<(Vec3, f32)> = holes
        .iter()
        .map(|&(dir, angle)| (dir.normalize_or(Vec3::Y), angle.cos()))
        .collect();
    let positions = mesh.positions.clone();
    mesh.triangles.retain(|t| {
        let c = t.iter().map(|&i| positions[i as usize]).sum::<Vec3>() / 3.0;
        let dir = (c - centre).normalize_or_zero();
        holes.iter().all(|&(h, cos_max)| dir.dot(h) < cos_max)
    });
    mesh
}

/// A one-sided, open cylindrical band (a collar) around the vertical axis through
/// `centre`: radius `radius`, from `centre.y` up to `centre.y + height`, its top
/// ring `flare` further out than its bottom, facing outward, with a gap of
/// `gap_rad` radians centred on +z (the collar's opening at the throat).
pub fn open_band(centre: Vec3, radius: f32, height: f32, flare: f32, gap_rad: f32, segments: u32) -> Mesh {
    let segments = segments.max(3);
    let span = std::f32::consts::TAU - gap_rad.clamp(0.0, std::f32::consts::PI);
    let mut positions = Vec::with_capacity(2 * (segments as usize + 1));
    for j in 0..=segments {
        // Azimuth measured from +z, going around through +x; the gap is around +z.
        let phi = 0.5 * gap_rad + span * j as f32 / segments as f32;
        let out = Vec3::new(phi.sin(), 0.0, phi.cos());
        positions.push(centre + radius * out);
        positions.push(centre + (radius + flare) * out + Vec3::Y * height);
    }
    let mut triangles = Vec::with_capacity(2 * segments as usize);
    for j in 0..segments {
        let (b0, t0, b1, t1) = (2 * j, 2 * j + 1, 2 * j + 2, 2 * j + 3);
        // Counter-clockwise seen from outside: the normal points away from the axis.
        triangles.push([b0, t1, t0]);
        triangles.push([b0, b1, t1]);
    }
    Mesh {
        positions,
        triangles,
        albedo: Albedo::Uniform([0.8; 3]),
    }
}

/// A deterministic RGB texture of `width × height` texels: two colours in stripes
/// `stripe` texels wide along x, crossed by thin lines of a third colour every
/// `4·stripe` rows (a shirt's check).
pub fn striped_texture(width: usize, height: usize, stripe: usize, colours: [[f32; 3]; 3]) -> Texture {
    let stripe = stripe.max(1);
    let texels = (0..height)
        .flat_map(|y| {
            (0..width).map(move |x| {
                if y % (4 * stripe) < stripe / 2 + 1 {
                    colours[2]
                } else if (x / stripe) % 2 == 0 {
                    colours[0]
                } else {
                    colours[1]
                }
            })
        })
        .collect();
    Texture {
        width: width.max(1),
        height: height.max(1),
        texels,
    }
}

/// A quad like [`crate::shapes::quad`] with `texture` mapped once over it (UV (0, 0)
/// at `corner`, (1, 1) at the far corner).
pub fn textured_quad(corner: Vec3, edge_u: Vec3, edge_v: Vec3, n: u32, texture: Texture) -> Mesh {
    let mut mesh = crate::shapes::quad(corner, edge_u, edge_v, n, [0.0; 3]);
    let (u2, v2) = (
        edge_u.length_squared().max(f32::MIN_POSITIVE),
        edge_v.length_squared().max(f32::MIN_POSITIVE),
    );
    let uv_of = |p: Vec3| Vec2::new((p - corner).dot(edge_u) / u2, (p - corner).dot(edge_v) / v2);
    let uvs = mesh
        .triangles
        .iter()
        .flat_map(|t| t.map(|i| uv_of(mesh.positions[i as usize])))
        .collect();
    mesh.albedo = Albedo::Texture { uvs, texture };
    mesh
}

/// `mesh` with the winding of every `every`-th triangle reversed (inward normals
/// scattered over the surface, as inconsistent scans have).
pub fn with_flipped_triangles(mut mesh: Mesh, every: usize) -> Mesh {
    for t in mesh.triangles.iter_mut().step_by(every.max(1)) {
        t.swap(1, 2);
    }
    mesh
}

/// `mesh` with a fin: one extra triangle on an edge of its first triangle, sticking
/// out along that triangle's normal by `height`, so the edge is shared by three
/// triangles (non-manifold).
pub fn with_fin(mut mesh: Mesh, height: f32) -> Mesh {
    let Some(&[a, b, _]) = mesh.triangles.first() else {
        return mesh;
    };
    let normal = mesh.face_normal(0);
    let mid = 0.5 * (mesh.positions[a as usize] + mesh.positions[b as usize]);
    let apex = mesh.positions.len() as u32;
    mesh.positions.push(mid + normal * height);
    if let Albedo::PerVertex(colours) = &mut mesh.albedo {
        colours.push(colours[a as usize]);
    }
    if let Albedo::Texture { uvs, .. } = &mut mesh.albedo {
        let uv = uvs[0];
        uvs.extend_from_slice(&[uv, uv, uv]);
    }
    mesh.triangles.push([a, b, apex]);
    mesh
}

/// `parts` concatenated into one textured mesh: each part's texture (or uniform
/// colour, as a 1 × 1 texture) is placed side by side in one atlas, and its UVs
/// (wrapped into `[0, 1)`) are remapped into its column of the atlas.
pub fn merge_textured(parts: &[Mesh]) -> Mesh {
    let textures: Vec<Texture> = parts
        .iter()
        .map(|p| match &p.albedo {
            Albedo::Texture { texture, .. } => texture.clone(),
            Albedo::Uniform(c) => Texture {
                width: 1,
                height: 1,
                texels: vec![*c],
            },
            Albedo::PerVertex(c) => {
                let n = c.len().max(1) as f32;
                let mean = c
                    .iter()
                    .fold([0.0f32; 3], |acc, t| std::array::from_fn(|i| acc[i] + t[i] / n));
                Texture {
                    width: 1,
                    height: 1,
                    texels: vec![mean],
                }
            }
        })
        .collect();
    // Every part gets a column `cell` texels wide (its texture scaled by nearest texel).
    let cell = textures.iter().map(|t| t.width.max(t.height)).max().unwrap_or(1);
    let width = cell * parts.len().max(1);
    let mut texels = vec![[0.0f32; 3]; width * cell];
    for (k, t) in textures.iter().enumerate() {
        for y in 0..cell {
            for x in 0..cell {
                texels[y * width + k * cell + x] =
                    t.texels[(y * t.height / cell) * t.width + x * t.width / cell];
            }
        }
    }
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    let mut uvs = Vec::new();
    for (k, part) in parts.iter().enumerate() {
        let offset = positions.len() as u32;
        positions.extend_from_slice(&part.positions);
        triangles.extend(part.triangles.iter().map(|t| t.map(|i| i + offset)));
        let column = |uv: Vec2| {
            // Stay inside the column: half a texel from its edges.
            let inset = 0.5 / cell as f32;
            let u = uv.x.rem_euclid(1.0).clamp(inset, 1.0 - inset);
            let v = uv.y.rem_euclid(1.0).clamp(inset, 1.0 - inset);
            Vec2::new((k as f32 + u) / parts.len() as f32, v)
        };
        match &part.albedo {
            Albedo::Texture { uvs: part_uvs, .. } => uvs.extend(part_uvs.iter().map(|&uv| column(uv))),
            _ => uvs.extend(std::iter::repeat_n(
                column(Vec2::splat(0.5)),
                3 * part.triangles.len(),
            )),
        }
    }
    Mesh {
        positions,
        triangles,
        albedo: Albedo::Texture {
            uvs,
            texture: Texture {
                width,
                height: cell,
                texels,
            },
        },
    }
}

/// The small defect cases the bake is tested on (`bake/tests/defects.rs`) and the
/// `defect_meshes` example writes, by name, each about 0.16 m across:
///
/// * `sheet`: a bent one-sided sheet (two quads at an angle), open edges;
/// * `torn_sphere`: a sphere torn by holes of three sizes (0.5, 0.2, 0.08 rad);
/// * `loose_piece`: a sphere with a small sphere not connected to it;
/// * `textured_quad`: a quad with a striped texture;
/// * `flipped_fin`: a sphere with every 13th triangle flipped and a non-manifold fin.
pub fn test_cases() -> Vec<(&'static str, Mesh)> {
    let sheet_colour = [0.8, 0.7, 0.6];
    let sheet = crate::shapes::merge(&[
        crate::shapes::quad(
            Vec3::new(-0.08, -0.06, 0.0),
            Vec3::new(0.08, 0.0, 0.03),
            Vec3::new(0.0, 0.12, 0.0),
            6,
            sheet_colour,
        ),
        crate::shapes::quad(
            Vec3::new(0.0, -0.06, 0.03),
            Vec3::new(0.08, 0.0, -0.03),
            Vec3::new(0.0, 0.12, 0.0),
            6,
            sheet_colour,
        ),
    ]);
    let torn = torn_sphere(
        Vec3::ZERO,
        0.08,
        &[
            (Vec3::new(0.3, 0.2, 1.0), 0.5),
            (Vec3::X, 0.2),
            (Vec3::NEG_Y, 0.08),
        ],
        [0.6, 0.6, 0.7],
    );
    let loose = crate::shapes::merge(&[
        uv_sphere(Vec3::ZERO, 0.07, 16, 32, [0.7, 0.55, 0.45]),
        uv_sphere(Vec3::new(0.1, 0.06, 0.02), 0.02, 8, 16, [0.3, 0.4, 0.8]),
    ]);
    let quad = textured_quad(
        Vec3::new(-0.08, -0.08, 0.0),
        Vec3::new(0.16, 0.0, 0.0),
        Vec3::new(0.0, 0.16, 0.02),
        4,
        striped_texture(16, 16, 4, [[0.9, 0.9, 0.85], [0.2, 0.3, 0.6], [0.05, 0.05, 0.1]]),
    );
    let flipped = with_fin(
        with_flipped_triangles(uv_sphere(Vec3::ZERO, 0.07, 16, 32, [0.7, 0.6, 0.5]), 13),
        0.02,
    );
    vec![
        ("sheet", sheet),
        ("torn_sphere", torn),
        ("loose_piece", loose),
        ("textured_quad", quad),
        ("flipped_fin", flipped),
    ]
}

/// A shirt texture: white and pale blue stripes with a darker check line.
fn shirt_texture() -> Texture {
    striped_texture(
        64,
        64,
        4,
        [[0.85, 0.85, 0.82], [0.45, 0.55, 0.75], [0.15, 0.2, 0.35]],
    )
}

/// Shoulders and chest: an ellipsoid (a closed surface) under the neck, with the
/// shirt texture wrapped around it (u with the azimuth, v with the height).
fn torso(centre: Vec3, radii: Vec3) -> Mesh {
    let mut mesh = uv_sphere(Vec3::ZERO, 1.0, 16, 40, [0.0; 3]);
    let unit = mesh.positions.clone();
    for p in &mut mesh.positions {
        *p = centre + *p * radii;
    }
    let uv_of = |d: Vec3| Vec2::new(0.5 + d.x.atan2(d.z) / std::f32::consts::TAU, 0.5 + 0.5 * d.y);
    let uvs = mesh
        .triangles
        .iter()
        .flat_map(|t| t.map(|i| uv_of(unit[i as usize])))
        .collect();
    mesh.albedo = Albedo::Texture {
        uvs,
        texture: shirt_texture(),
    };
    mesh
}

/// A head-and-shoulders figure with the defects of a real textured scan: `head` (a
/// closed head and neck, 0.23 m tall, centred at the origin, facing +z, e.g.
/// `data/meshes/head.off` loaded with `LoadOptions::head_off()` or a procedural
/// head), a closed torso that the neck pierces (crossing surfaces), a **shirt
/// collar made of one-sided open sheets** (a band around the neck with an opening
/// at the throat, and two flaps lying on the chest, not connected to anything), and
/// one texture atlas: the head keeps its mean colour, the shirt and collar are
/// striped. About 0.42 m tall.
pub fn head_and_shoulders(head: &Mesh) -> Mesh {
    let (lo, hi) = head.bounds();
    let neck_y = lo.y + 0.1 * (hi.y - lo.y);
    let torso = torso(Vec3::new(0.0, neck_y - 0.075, -0.01), Vec3::new(0.19, 0.1, 0.11));
    // The band rises from just under the shoulders' surface to 4 cm above it.
    let collar = open_band(Vec3::new(0.0, neck_y + 0.005, -0.01), 0.058, 0.04, 0.01, 0.9, 64);
    let collar = textured(
        collar,
        Texture {
            width: 1,
            height: 1,
            texels: vec![[0.9, 0.9, 0.88]],
        },
    );
    // Two collar points lying on the chest, each a separate one-sided piece.
    let flap = |side: f32| {
        textured_quad(
            Vec3::new(side * 0.01, neck_y + 0.014, 0.066),
            Vec3::new(side * 0.045, -0.03, 0.012),
            Vec3::new(side * -0.008, -0.022, 0.02),
            4,
            shirt_texture(),
        )
    };
    // Each flap faces forward (+z): flip the one whose edges make it face back.
    let orient = |m: Mesh| {
        if m.face_normal(0).z < 0.0 {
            with_flipped_triangles(m, 1)
        } else {
            m
        }
    };
    merge_textured(&[head.clone(), torso, collar, orient(flap(1.0)), orient(flap(-1.0))])
}

/// `mesh` with `texture` over every triangle (all UVs at the texture's centre when
/// it is 1 × 1, which is all this module needs).
fn textured(mut mesh: Mesh, texture: Texture) -> Mesh {
    let uvs = vec![Vec2::splat(0.5); 3 * mesh.triangles.len()];
    mesh.albedo = Albedo::Texture { uvs, texture };
    mesh
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defect_meshes_are_valid_and_have_their_defects() {
        let torn = torn_sphere(
            Vec3::ZERO,
            0.1,
            &[(Vec3::Z, 0.3), (Vec3::X, 0.12), (Vec3::NEG_Y, 0.6)],
            [0.5; 3],
        );
        torn.validate().unwrap();
        let whole = uv_sphere(Vec3::ZERO, 0.1, 24, 48, [0.5; 3]);
        assert!(torn.triangles.len() < whole.triangles.len());
        // (A UV sphere repeats its pole vertices: those edges count as defects too.)
        assert!(
            torn.edge_defects() > whole.edge_defects(),
            "holes have boundary edges"
        );

        let band = open_band(Vec3::ZERO, 0.05, 0.04, 0.01, 0.9, 32);
        band.validate().unwrap();
        // Faces away from the axis.
        for t in 0..band.triangles.len() {
            let [a, b, c] = band.corners(t);
            let radial = ((a + b + c) / 3.0) * Vec3::new(1.0, 0.0, 1.0);
            assert!(band.face_normal(t).dot(radial) > 0.0, "triangle {t}");
        }
        assert!(band.edge_defects() > 0);

        // The fin shares an edge with a triangle of the sphere and has two open edges.
        let fin = with_fin(whole.clone(), 0.03);
        fin.validate().unwrap();
        assert!(fin.edge_defects() > whole.edge_defects());

        let flipped = with_flipped_triangles(whole.clone(), 7);
        assert!(flipped.signed_volume() < whole.signed_volume());

        let tq = textured_quad(
            Vec3::ZERO,
            Vec3::X,
            Vec3::Y,
            2,
            striped_texture(8, 8, 2, [[1.0; 3], [0.0; 3], [0.5; 3]]),
        );
        tq.validate().unwrap();
        // Texture lookups at corners of the quad: (0, 0) is the bottom-left texel.
        assert_eq!(tq.albedo_at(0, 0.0, 0.0), [1.0; 3]);
    }

    #[test]
    fn head_and_shoulders_is_a_textured_figure_with_an_open_collar() {
        let head = crate::shapes::uv_sphere(Vec3::ZERO, 0.1, 12, 24, [0.7, 0.5, 0.4]);
        let figure = head_and_shoulders(&head);
        figure.validate().unwrap();
        assert!(matches!(figure.albedo, Albedo::Texture { .. }));
        let (lo, hi) = figure.bounds();
        assert!(hi.y - lo.y > 0.25 && hi.x - lo.x > 0.3, "{lo} {hi}");
        // The collar and the flaps are open sheets: boundary edges.
        assert!(figure.edge_defects() > 64);
        // The head keeps its colour.
        assert_eq!(figure.albedo_at(0, 0.3, 0.3), [0.7, 0.5, 0.4]);
    }
}
