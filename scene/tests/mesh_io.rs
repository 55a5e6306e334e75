//! Mesh loaders: the shared scanned head, OFF edge cases, OBJ + MTL + texture.

#![allow(clippy::unwrap_used)] // Test helpers outside #[test] functions unwrap too.

use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};
use nelf_scene::error::SceneError;
use nelf_scene::mesh::{Albedo, Mesh};
use nelf_scene::mesh_io::{DEFAULT_SKIN_ALBEDO, LoadOptions, load_mesh, parse_off, srgb_to_linear};

fn shared_head() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/meshes/head.off")
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

/// How far the midline (|x| < 1 cm) sticks out along `sign · z` beyond the
/// surface 2.5–3.5 cm to the side, over the face's height band: the nose makes
/// this large on the face side and small on the back of a round skull.
fn midline_protrusion(mesh: &Mesh, sign: f32) -> f32 {
    let band = |lo: f32, hi: f32| {
        mesh.positions
            .iter()
            .filter(|p| p.x.abs() >= lo && p.x.abs() < hi && p.y > -0.02 && p.y < 0.07)
            .map(|p| sign * p.z)
            .fold(f32::NEG_INFINITY, f32::max)
    };
    band(0.0, 0.01) - band(0.025, 0.035)
}

#[test]
fn shared_head_loads_validates_and_faces_plus_z() {
    let raw = load_mesh(
        shared_head(),
        &LoadOptions {
            orient_outward: false,
            close_holes: false,
            ..LoadOptions::default()
        },
    )
    .unwrap();
    assert_eq!(raw.positions.len(), 1487);
    assert_eq!(raw.triangles.len(), 2918);
    raw.validate().unwrap();
    assert_eq!(raw.albedo, Albedo::Uniform(DEFAULT_SKIN_ALBEDO));
    assert!(
        raw.signed_volume() < 0.0,
        "head.off is stored with clockwise triangles"
    );
    // Open at the neck and the eyes: 58 boundary edges, nothing else wrong.
    assert_eq!(raw.edge_defects(), 58);

    let mut closed = raw.clone();
    let loops = closed.close_holes();
    assert_eq!(loops, 3, "the neck and two eyes");
    assert_eq!(closed.edge_defects(), 0, "watertight once closed");
    assert_eq!(closed.triangles.len(), 2918 + 58);
    assert_eq!(closed.positions.len(), 1487 + 3);
    assert_eq!(closed.close_holes(), 0, "nothing left to close");

    let head = load_mesh(shared_head(), &LoadOptions::head_off()).unwrap();
    assert_eq!(head.triangles.len(), 2918 + 58, "holes closed by default");
    assert_eq!(head.edge_defects(), 0);
    assert!(head.signed_volume() > 0.0, "oriented outward");
    let (lo, hi) = head.bounds();
    assert!((hi.y - lo.y - 0.23).abs() < 1e-5, "fitted to 0.23 m");
    assert!((0.5 * (lo + hi)).length() < 1e-5, "centred");
    // Nose along +z: the face side protrudes at the midline, the back does not.
    let front = midline_protrusion(&head, 1.0);
    let back = midline_protrusion(&head, -1.0);
    assert!(
        front > 0.012 && front > back + 0.008,
        "front {front} m, back {back} m"
    );
    // Without the turn the nose points along −x.
    let unturned = load_mesh(
        shared_head(),
        &LoadOptions {
            rotate_y_deg: 0.0,
            ..LoadOptions::head_off()
        },
    )
    .unwrap();
    let nose = unturned
        .positions
        .iter()
        .copied()
        .fold(Vec3::splat(f32::INFINITY), |a, p| if p.x < a.x { p } else { a });
    assert!(
        nose.z.abs() < 0.005,
        "extreme −x point lies on the midline: {nose:?}"
    );
}

#[test]
fn off_comments_counts_on_header_and_polygons() {
    let text = "# a comment\n\nOFF 5 3 0 # counts on the header line\n\
                0 0 0\n1 0 0\n1 1 0 # trailing comment\n0 1 0\n\n0.5 1.5 0\n\
                3 0 1 2\n4 0 1 2 3 0.1 0.2 0.3 # face colour ignored\n5 0 1 4 2 3\n";
    let mesh = parse_off(text, Path::new("inline.off"), [0.3, 0.2, 0.1]).unwrap();
    assert_eq!(mesh.positions.len(), 5);
    // 1 + 2 (quad fan) + 3 (pentagon fan).
    assert_eq!(mesh.triangles.len(), 6);
    assert_eq!(mesh.triangles[1], [0, 1, 2]);
    assert_eq!(mesh.triangles[2], [0, 2, 3]);
    assert_eq!(mesh.triangles[5], [0, 2, 3]);
    assert_eq!(mesh.albedo, Albedo::Uniform([0.3, 0.2, 0.1]));
    mesh.validate().unwrap();
}

#[test]
fn coff_colours_become_linear_per_vertex_albedo() {
    let text = "COFF\n3 1 0\n0 0 0 255 0 0 255\n1 0 0 0 128 0 255\n0 1 0 0 0 255 255\n3 0 1 2\n";
    let mesh = parse_off(text, Path::new("c.off"), [0.5; 3]).unwrap();
    let Albedo::PerVertex(colours) = &mesh.albedo else {
        panic!("expected per-vertex albedo, got {:?}", mesh.albedo)
    };
    assert_eq!(colours[0], [1.0, 0.0, 0.0]);
    assert!((colours[1][1] - srgb_to_linear(128.0 / 255.0)).abs() < 1e-6);
    // Float colours in [0, 1] are read as they are (then linearised).
    let floats = "COFF\n3 1 0\n0 0 0 0.5 0.5 0.5\n1 0 0 1 1 1\n0 1 0 0 0 0\n3 0 1 2\n";
    let mesh = parse_off(floats, Path::new("f.off"), [0.5; 3]).unwrap();
    let Albedo::PerVertex(colours) = &mesh.albedo else {
        panic!("expected per-vertex albedo")
    };
    assert!((colours[0][0] - srgb_to_linear(0.5)).abs() < 1e-6);
}

#[test]
fn off_errors_name_the_file_and_line() {
    let bad_index = "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n# comment on line 6\n3 0 1 7\n";
    let err = parse_off(bad_index, Path::new("bad.off"), [0.5; 3]).unwrap_err();
    assert!(matches!(err, SceneError::Parse { line: 7, .. }), "{err:?}");
    let message = err.to_string();
    assert!(message.starts_with("bad.off:7:"), "{message}");
    assert!(message.contains("vertex 7"), "{message}");

    let not_a_number = "OFF\n3 1 0\n0 0 0\n1 zero 0\n0 1 0\n3 0 1 2\n";
    let err = parse_off(not_a_number, Path::new("nan.off"), [0.5; 3]).unwrap_err();
    assert!(matches!(err, SceneError::Parse { line: 4, .. }), "{err}");

    let short = "OFF\n3 1 0\n0 0 0\n1 0 0\n";
    let err = parse_off(short, Path::new("short.off"), [0.5; 3]).unwrap_err();
    assert!(err.to_string().contains("after 2 of 3 vertices"), "{err}");

    let degenerate_face = "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n";
    let err = parse_off(degenerate_face, Path::new("two.off"), [0.5; 3]).unwrap_err();
    assert!(matches!(err, SceneError::Parse { line: 6, .. }), "{err}");

    for header in ["PLY\n", "4OFF\n3 1 0\n", "OFF BINARY\n", ""] {
        assert!(
            parse_off(header, Path::new("h.off"), [0.5; 3]).is_err(),
            "{header:?}"
        );
    }
}

#[test]
fn load_mesh_dispatches_and_reports_files() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.off");
    let err = load_mesh(&missing, &LoadOptions::default()).unwrap_err();
    assert!(matches!(err, SceneError::Io(_)));
    assert!(err.to_string().contains("missing.off"));
    let ply = write(dir.path(), "mesh.ply", "ply\n");
    assert!(matches!(
        load_mesh(&ply, &LoadOptions::default()),
        Err(SceneError::UnsupportedExtension { .. })
    ));
    // Upper-case extension, clockwise triangle: oriented, turned and fitted.
    let off = write(
        dir.path(),
        "TRI.OFF",
        "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n3 0 3 1\n3 0 2 3\n3 1 3 2\n",
    );
    let mesh = load_mesh(
        &off,
        &LoadOptions {
            fit_height_m: Some(0.5),
            rotate_y_deg: 90.0,
            ..LoadOptions::default()
        },
    )
    .unwrap();
    assert!(mesh.signed_volume() > 0.0);
    assert_eq!(mesh.edge_defects(), 0);
    let (lo, hi) = mesh.bounds();
    assert!((hi.y - lo.y - 0.5).abs() < 1e-6);
    let bad_fit = LoadOptions {
        fit_height_m: Some(-1.0),
        ..LoadOptions::default()
    };
    assert!(load_mesh(&off, &bad_fit).is_err());
}

/// A 2 × 2 sRGB PNG: red, green / blue, white (top row first).
fn write_texture(dir: &Path, name: &str) {
    let mut image = image::RgbImage::new(2, 2);
    image.put_pixel(0, 0, image::Rgb([255, 0, 0]));
    image.put_pixel(1, 0, image::Rgb([0, 128, 0]));
    image.put_pixel(0, 1, image::Rgb([0, 0, 255]));
    image.put_pixel(1, 1, image::Rgb([255, 255, 255]));
    image.save(dir.join(name)).unwrap();
}

/// OBJ tests load open sheets: keep the file's winding.
fn keep_winding() -> LoadOptions {
    LoadOptions {
        orient_outward: false,
        close_holes: false,
        ..LoadOptions::default()
    }
}

const QUAD_OBJ: &str = "mtllib quad.mtl\n\
    v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n\
    vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n\
    usemtl skin\nf 1/1 2/2 3/3 4/4\n";

#[test]
fn obj_with_mtl_texture_gives_texture_albedo() {
    let dir = tempfile::tempdir().unwrap();
    write_texture(dir.path(), "skin.png");
    write(
        dir.path(),
        "quad.mtl",
        "newmtl skin\nKd 0.8 0.8 0.8\nmap_Kd skin.png\n",
    );
    let obj = write(dir.path(), "quad.obj", QUAD_OBJ);
    let mesh = load_mesh(&obj, &keep_winding()).unwrap();
    assert_eq!(mesh.positions.len(), 4);
    assert_eq!(mesh.triangles.len(), 2);
    let Albedo::Texture { uvs, texture } = &mesh.albedo else {
        panic!("expected a texture, got {:?}", mesh.albedo)
    };
    assert_eq!(uvs.len(), 6);
    assert_eq!((texture.width, texture.height), (2, 2));
    // Triangle 0 is (v1, v2, v3) with UVs (0,0), (1,0), (1,1). The point at UV
    // (0.75, 0.25) — bottom right, the white texel — has barycentrics b1 = 0.5, b2 = 0.25.
    let uv = (1.0 - 0.5 - 0.25) * uvs[0] + 0.5 * uvs[1] + 0.25 * uvs[2];
    assert!(uv.abs_diff_eq(Vec2::new(0.75, 0.25), 1e-6));
    assert_eq!(mesh.albedo_at(0, 0.5, 0.25), [1.0, 1.0, 1.0]);
    // UV (0.25, 0.75), top left: red. Triangle 1 is (v1, v3, v4), UVs (0,0), (1,1), (0,1).
    assert_eq!(mesh.albedo_at(1, 0.25, 0.5), [1.0, 0.0, 0.0]);
    // UV (0.75, 0.75), top right: sRGB 128 green, linearised.
    let green = mesh.albedo_at(1, 0.75, 0.0);
    assert!(
        (green[1] - srgb_to_linear(128.0 / 255.0)).abs() < 1e-6,
        "{green:?}"
    );
    assert_eq!(green[0], 0.0);
}

#[test]
fn obj_textured_and_flat_materials_share_an_atlas() {
    let dir = tempfile::tempdir().unwrap();
    write_texture(dir.path(), "skin.png");
    write(
        dir.path(),
        "quad.mtl",
        "newmtl skin\nmap_Kd skin.png\nnewmtl paint\nKd 0.2 0.4 0.6\n",
    );
    let text = format!("{QUAD_OBJ}o second\nv 0 0 1\nv 1 0 1\nv 1 1 1\nusemtl paint\nf 5 6 7\n");
    let obj = write(dir.path(), "two.obj", &text);
    let mesh = load_mesh(&obj, &keep_winding()).unwrap();
    assert_eq!(mesh.triangles.len(), 3);
    assert!(matches!(mesh.albedo, Albedo::Texture { .. }));
    assert_eq!(mesh.albedo_at(0, 0.5, 0.25), [1.0, 1.0, 1.0]);
    assert_eq!(mesh.albedo_at(1, 0.25, 0.5), [1.0, 0.0, 0.0]);
    assert_eq!(mesh.albedo_at(2, 0.3, 0.3), [0.2, 0.4, 0.6]);
}

#[test]
fn obj_without_texture_or_mtl_falls_back() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "quad.mtl", "newmtl skin\nKd 0.6 0.4 0.3\n");
    let obj = write(dir.path(), "kd.obj", QUAD_OBJ);
    let mesh = load_mesh(&obj, &LoadOptions::default()).unwrap();
    assert_eq!(mesh.albedo, Albedo::Uniform([0.6, 0.4, 0.3]));

    // No MTL file at all: the default albedo, no error.
    let lonely = tempfile::tempdir().unwrap();
    let obj = write(lonely.path(), "quad.obj", QUAD_OBJ);
    let options = LoadOptions {
        default_albedo: [0.1, 0.2, 0.3],
        ..LoadOptions::default()
    };
    let mesh = load_mesh(&obj, &options).unwrap();
    assert_eq!(mesh.albedo, Albedo::Uniform([0.1, 0.2, 0.3]));

    // A texture the MTL names but that is missing is an error naming it.
    write(lonely.path(), "quad.mtl", "newmtl skin\nmap_Kd gone.png\n");
    let err = load_mesh(&obj, &options).unwrap_err();
    assert!(err.to_string().contains("gone.png"), "{err}");
}

#[test]
fn obj_vertex_colours_are_used_when_there_is_no_texture() {
    let dir = tempfile::tempdir().unwrap();
    let obj = write(
        dir.path(),
        "vc.obj",
        "v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 1\nf 1 2 3\n",
    );
    let mesh = load_mesh(&obj, &keep_winding()).unwrap();
    assert_eq!(
        mesh.albedo,
        Albedo::PerVertex(vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    );
}

#[test]
fn write_obj_round_trips_a_textured_open_mesh() {
    use nelf_scene::defects::{head_and_shoulders, striped_texture, textured_quad};
    use nelf_scene::mesh_io::write_obj;
    let dir = tempfile::tempdir().unwrap();
    let head = nelf_scene::shapes::uv_sphere(Vec3::ZERO, 0.1, 8, 16, [0.7, 0.5, 0.4]);
    for (name, mesh) in [
        ("figure", head_and_shoulders(&head)),
        (
            "quad",
            textured_quad(
                Vec3::ZERO,
                Vec3::X,
                Vec3::Y,
                3,
                striped_texture(16, 16, 4, [[0.9; 3], [0.1; 3], [0.5; 3]]),
            ),
        ),
    ] {
        let path = dir.path().join(format!("{name}.obj"));
        write_obj(&mesh, &path).unwrap();
        assert!(dir.path().join(format!("{name}_albedo.jpg")).is_file());
        let options = LoadOptions {
            close_holes: false,
            orient_outward: false,
            ..LoadOptions::default()
        };
        let back = load_mesh(&path, &options).unwrap();
        // The loader may split vertices by texture coordinate: compare corners.
        assert_eq!(back.triangles.len(), mesh.triangles.len(), "{name}");
        for t in 0..mesh.triangles.len() {
            let (a, b) = (back.corners(t), mesh.corners(t));
            assert!(
                (0..3).all(|k| a[k].abs_diff_eq(b[k], 1e-6)),
                "{name}: triangle {t}"
            );
        }
        // Albedo at each triangle's centroid agrees within JPEG's rounding (linear).
        let mut worst = 0.0f32;
        for t in 0..mesh.triangles.len() {
            let (x, y) = (
                mesh.albedo_at(t, 1.0 / 3.0, 1.0 / 3.0),
                back.albedo_at(t, 1.0 / 3.0, 1.0 / 3.0),
            );
            worst = (0..3).map(|c| (x[c] - y[c]).abs()).fold(worst, f32::max);
        }
        assert!(worst < 0.06, "{name}: albedo differs by {worst}");
    }
}

#[test]
fn close_holes_closes_holes_but_not_the_rims_of_open_sheets() {
    use nelf_scene::defects::{open_band, torn_sphere};
    // A UV sphere repeats its pole vertices: each pole is a zero-area loop, closed.
    let poles = nelf_scene::shapes::uv_sphere(Vec3::ZERO, 0.1, 24, 48, [0.5; 3]).close_holes();
    // Small holes (the neck and eyes of a scan) are closed...
    let mut torn = torn_sphere(Vec3::ZERO, 0.1, &[(Vec3::Z, 0.3), (Vec3::X, 0.15)], [0.5; 3]);
    assert_eq!(torn.close_holes(), poles + 2);
    // ...a shell torn wide open (around its north pole) is a sheet: its rim stays open.
    let mut bowl = torn_sphere(Vec3::ZERO, 0.1, &[(Vec3::Y, 1.3)], [0.5; 3]);
    assert_eq!(bowl.close_holes(), poles - 1);
    // So do a flat sheet and a collar band, whatever else the mesh holds.
    let sheet = nelf_scene::shapes::quad(
        Vec3::new(0.2, 0.0, 0.0),
        Vec3::X * 0.1,
        Vec3::Y * 0.1,
        4,
        [0.5; 3],
    );
    let band = open_band(Vec3::new(0.0, -0.2, 0.0), 0.06, 0.04, 0.01, 0.9, 32);
    let head = torn_sphere(Vec3::ZERO, 0.1, &[(Vec3::NEG_Z, 0.3)], [0.5; 3]);
    let mut figure = nelf_scene::shapes::merge(&[head, sheet, band]);
    assert_eq!(figure.close_holes(), poles + 1, "only the head's hole");
}
