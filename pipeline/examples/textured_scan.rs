//! Writes a scan with skin-like texture far finer than a voxel (issue 51's test
//! input): a mesh (default the CGAL head, `data/meshes/head.off`) fitted to a height,
//! its albedo a texture atlas (`nelf_pipeline::photo::atlas`) whose texels take a
//! procedural skin at their 3D points — 6 mm blotches, 0.6 mm pores (±12 %), and
//! dark specks in 0.5 mm cells (stubble, freckles) — written as OBJ + MTL + JPEG, as
//! a scanner delivers it.
//!
//! `cargo run --release -p nelf-pipeline --example textured_scan -- OUT.obj [MESH] [HEIGHT_M] [CELL_TEXELS]`
//! then `nelf capture synth --mesh OUT.obj --mesh-height-m HEIGHT_M …`.

use std::path::PathBuf;

use glam::Vec3;
use nelf_scene::mesh_io::{LoadOptions, load_mesh, write_obj};
use nelf_scene::tracer::mix64;

/// A hash of a lattice point to `[0, 1)`.
fn hash(cell: [i64; 3], seed: u64) -> f32 {
    let z = mix64(mix64(mix64(seed ^ cell[0] as u64) ^ cell[1] as u64) ^ cell[2] as u64);
    (z >> 40) as f32 / (1u64 << 24) as f32
}

/// Value noise in `[−1, 1]` with cells `cell_m` wide (trilinear between hashed corners).
fn noise(p: Vec3, cell_m: f32, seed: u64) -> f32 {
    let g = p / cell_m;
    let base = g.floor();
    let f = g - base;
    let mut sum = 0.0;
    for c in 0..8 {
        let d = [c & 1, (c >> 1) & 1, c >> 2];
        let corner = [0, 1, 2].map(|a| base[a] as i64 + d[a] as i64);
        let w: f32 = (0..3)
            .map(|a| if d[a] == 1 { f[a] } else { 1.0 - f[a] })
            .product();
        sum += w * (2.0 * hash(corner, seed) - 1.0);
    }
    sum
}

/// Skin at point `p` (metres), linear RGB.
fn skin(p: Vec3) -> [f32; 3] {
    let blotch = noise(p, 6e-3, 1);
    let pores = noise(p, 0.6e-3, 2);
    let base = [0.62 + 0.06 * blotch, 0.42 - 0.03 * blotch, 0.33 - 0.02 * blotch];
    let speck_cell = (p / 0.5e-3).floor();
    let speck = hash([speck_cell.x as i64, speck_cell.y as i64, speck_cell.z as i64], 3) > 0.94;
    let shade = (1.0 + 0.12 * pores) * if speck { 0.3 } else { 1.0 };
    base.map(|c| (c * shade).clamp(0.0, 1.0))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let out = PathBuf::from(
        args.get(1)
            .ok_or("usage: textured_scan OUT.obj [MESH] [HEIGHT_M] [CELL_TEXELS]")?,
    );
    let source = args
        .get(2)
        .map_or_else(|| PathBuf::from("data/meshes/head.off"), PathBuf::from);
    let height_m: f32 = args.get(3).map_or(Ok(0.23), |h| h.parse())?;
    let cell: usize = args.get(4).map_or(Ok(48), |c| c.parse())?;
    let mut mesh = load_mesh(&source, &LoadOptions::default())?;
    mesh.fit_height(Vec3::ZERO, height_m);
    let textured = nelf_pipeline::photo::atlas::texture_atlas_from(&mesh, cell, |t, b1, b2| {
        let [a, b, c] = mesh.triangles[t].map(|i| mesh.positions[i as usize]);
        skin(a * (1.0 - b1 - b2) + b * b1 + c * b2)
    });
    write_obj(&textured, &out)?;
    if let nelf_scene::mesh::Albedo::Texture { texture, .. } = &textured.albedo {
        println!(
            "{}: {} triangles, texture {} x {}",
            out.display(),
            mesh.triangles.len(),
            texture.width,
            texture.height
        );
    }
    Ok(())
}
