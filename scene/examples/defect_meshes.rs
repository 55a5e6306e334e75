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
//! * the small cases of `nelf_scene::defects::test_cases` (`sheet.obj`,
//!   `torn_sphere.obj`, `loose_piece.obj`, `textured_quad.obj`, `flipped_fin.obj`).

use std::path::PathBuf;

use nelf_scene::defects::{head_and_shoulders, test_cases};
use nelf_scene::mesh_io::{LoadOptions, load_mesh, write_obj};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = PathBuf::from(std::env::args().nth(1).unwrap_or_else(|| "out/defects".into()));
    std::fs::create_dir_all(&out)?;
    let head_path = concat!(env!("CARGO_MANIFEST_DIR"), "/../data/meshes/head.off");
    let head = load_mesh(head_path, &LoadOptions::head_off())?;
    let mut meshes = vec![("head_and_shoulders", head_and_shoulders(&head))];
    meshes.extend(test_cases());
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
