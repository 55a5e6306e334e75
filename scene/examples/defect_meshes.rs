//! Writes the defect test meshes of `nelf_scene::defects` as textured OBJ files
//! (OBJ + MTL + JPEG, as scanners ship them), for captures and bakes of material
//! with the defects real scans have:
//!
//! ```sh
//! cargo run --release -p nelf-scene --example defect_meshes -- OUT_DIR
//! ```
//!
//! * `head_and_shoulders.obj`: the scanned head (`data/meshes/head.off`) on a
//!   striped shirt whose collar is a one-sided open band with flaps on the chest;
//! * `sheet.obj`, `torn_sphere.obj`, `textured_quad.obj`, `flipped_fin.obj`.

use std::path::PathBuf;

use glam::Vec3;
use nelf_scene::defects::{
    head_and_shoulders, striped_texture, textured_quad, torn_sphere, with_fin, with_flipped_triangles,
};
use nelf_scene::mesh_io::{LoadOptions, load_mesh, write_obj};
use nelf_scene::shapes::{quad, uv_sphere};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = PathBuf::from(std::env::args().nth(1).unwrap_or_else(|| "out/defects".into()));
    std::fs::create_dir_all(&out)?;
    let head_path = concat!(env!("CARGO_MANIFEST_DIR"), "/../data/meshes/head.off");
    let head = load_mesh(head_path, &LoadOptions::head_off())?;
    let meshes = [
        ("head_and_shoulders", head_and_shoulders(&head)),
        (
            "sheet",
            quad(
                Vec3::new(-0.08, -0.06, 0.0),
                Vec3::new(0.16, 0.0, 0.03),
                Vec3::new(0.0, 0.12, 0.0),
                8,
                [0.8, 0.7, 0.6],
            ),
        ),
        (
            "torn_sphere",
            torn_sphere(
                Vec3::ZERO,
                0.08,
                &[
                    (Vec3::new(0.3, 0.2, 1.0), 0.5),
                    (Vec3::X, 0.2),
                    (Vec3::NEG_Y, 0.08),
                ],
                [0.6, 0.6, 0.7],
            ),
        ),
        (
            "textured_quad",
            textured_quad(
                Vec3::new(-0.08, -0.08, 0.0),
                Vec3::new(0.16, 0.0, 0.0),
                Vec3::new(0.0, 0.16, 0.02),
                4,
                striped_texture(16, 16, 4, [[0.9, 0.9, 0.85], [0.2, 0.3, 0.6], [0.05, 0.05, 0.1]]),
            ),
        ),
        (
            "flipped_fin",
            with_fin(
                with_flipped_triangles(uv_sphere(Vec3::ZERO, 0.07, 16, 32, [0.7, 0.6, 0.5]), 13),
                0.02,
            ),
        ),
    ];
    for (name, mesh) in &meshes {
        let path = out.join(format!("{name}.obj"));
        write_obj(mesh, &path)?;
        let (lo, hi) = mesh.bounds();
        println!(
            "{}: {} vertices, {} triangles, {} open edges, box {lo:.3} .. {hi:.3} m",
            path.display(),
            mesh.positions.len(),
            mesh.triangles.len(),
            mesh.edge_defects()
        );
    }
    Ok(())
}
