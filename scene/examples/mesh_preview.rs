//! Looks at a mesh: rasterises orthographic views (front from +z, right side from
//! +x, three-quarter, top) with a z-buffer, shading albedo × (ambient + Lambert)
//! under a light near the viewer. Triangles seen from behind are painted magenta,
//! so inside-out winding or holes show at once.
//!
//! ```text
//! cargo run --release -p nelf-scene --example mesh_preview -- MESH OUT.png [ROTATE_Y_DEG]
//! ```
//! `MESH` is a `.off`/`.obj` file (loaded with orientation fixed and fitted to
//! 0.23 m; `data/meshes/head.off` is turned by its documented angle
//! unless `ROTATE_Y_DEG` is given) or `head:SEED` for a procedural head.

use std::path::Path;

use glam::Vec3;
use nelf_scene::head::{HeadParams, head_traits, procedural_head};
use nelf_scene::mesh::Mesh;
use nelf_scene::mesh_io::{LoadOptions, linear_to_srgb, load_mesh};

const PANEL: u32 = 512;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(source), Some(out)) = (args.first(), args.get(1)) else {
        return Err("usage: mesh_preview MESH|head:SEED OUT.png [ROTATE_Y_DEG]".into());
    };
    let mesh = if let Some(seed) = source.strip_prefix("head:") {
        let start = std::time::Instant::now();
        let mesh = procedural_head(seed.parse()?, &HeadParams::default());
        eprintln!(
            "procedural head {seed}: {:.1} ms",
            start.elapsed().as_secs_f64() * 1e3
        );
        eprintln!("{:?}", head_traits(seed.parse()?, &HeadParams::default()));
        mesh
    } else {
        let mut options = if source.ends_with("head.off") {
            LoadOptions::head_off()
        } else {
            LoadOptions {
                fit_height_m: Some(0.23),
                ..LoadOptions::default()
            }
        };
        if let Some(deg) = args.get(2) {
            options.rotate_y_deg = deg.parse()?;
        }
        load_mesh(source, &options)?
    };
    let (lo, hi) = mesh.bounds();
    eprintln!(
        "{} vertices, {} triangles, bounds {lo:?} … {hi:?} (size {:?} m), signed volume {:.3e} m³, edge defects {}",
        mesh.positions.len(),
        mesh.triangles.len(),
        hi - lo,
        mesh.signed_volume(),
        mesh.edge_defects()
    );
    report_defects(&mesh);
    let views = [
        Vec3::Z,
        Vec3::X,
        Vec3::new(1.0, 0.25, 1.0).normalize(),
        Vec3::new(0.0, 1.0, 0.05).normalize(),
    ];
    // PREVIEW_VIEWS=2 keeps only the front and side views (bigger on screen).
    let count = std::env::var("PREVIEW_VIEWS")
        .ok()
        .and_then(|v| v.parse::<usize>().ok())
        .unwrap_or(views.len())
        .clamp(1, views.len());
    let views = &views[..count];
    let mut sheet = image::RgbImage::new(PANEL * views.len() as u32, PANEL);
    let normals = mesh.vertex_normals();
    for (i, view) in views.iter().enumerate() {
        let panel = render_view(&mesh, &normals, *view);
        image::imageops::replace(&mut sheet, &panel, i64::from(PANEL) * i as i64, 0);
    }
    sheet.save(Path::new(out))?;
    eprintln!("wrote {out}");
    Ok(())
}

/// Orthographic view looking along `-toward_camera`, +y (or +z for a top view) up.
fn render_view(mesh: &Mesh, normals: &[Vec3], toward_camera: Vec3) -> image::RgbImage {
    let world_up = if toward_camera.y.abs() > 0.9 {
        Vec3::NEG_Z
    } else {
        Vec3::Y
    };
    let right = world_up.cross(toward_camera).normalize();
    let up = toward_camera.cross(right);
    let light = (toward_camera + 0.6 * up + 0.4 * right).normalize();
    let (lo, hi) = mesh.bounds();
    let centre = 0.5 * (lo + hi);
    let half = 0.55 * (hi - lo).length();
    let size = PANEL as f32;
    let to_screen = |p: Vec3| {
        let q = p - centre;
        Vec3::new(
            (q.dot(right) / half * 0.5 + 0.5) * size,
            (0.5 - q.dot(up) / half * 0.5) * size,
            q.dot(toward_camera),
        )
    };
    let screen: Vec<Vec3> = mesh.positions.iter().map(|&p| to_screen(p)).collect();
    let mut depth = vec![f32::NEG_INFINITY; (PANEL * PANEL) as usize];
    let mut image = image::RgbImage::from_pixel(PANEL, PANEL, image::Rgb([40, 40, 48]));
    for (t, tri) in mesh.triangles.iter().enumerate() {
        let [a, b, c] = tri.map(|i| screen[i as usize]);
        let area = (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
        if area.abs() < 1e-12 {
            continue;
        }
        // Screen y points down, so counter-clockwise-from-outside has negative area.
        let front_facing = area < 0.0;
        let x0 = a.x.min(b.x).min(c.x).floor().max(0.0) as u32;
        let x1 = (a.x.max(b.x).max(c.x).ceil() as u32).min(PANEL - 1);
        let y0 = a.y.min(b.y).min(c.y).floor().max(0.0) as u32;
        let y1 = (a.y.max(b.y).max(c.y).ceil() as u32).min(PANEL - 1);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
                let w0 = ((b.x - px) * (c.y - py) - (b.y - py) * (c.x - px)) / area;
                let w1 = ((c.x - px) * (a.y - py) - (c.y - py) * (a.x - px)) / area;
                let w2 = 1.0 - w0 - w1;
                if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                    continue;
                }
                let z = w0 * a.z + w1 * b.z + w2 * c.z;
                let k = (y * PANEL + x) as usize;
                if z <= depth[k] {
                    continue;
                }
                depth[k] = z;
                let colour = if front_facing {
                    let n = (w0 * normals[tri[0] as usize]
                        + w1 * normals[tri[1] as usize]
                        + w2 * normals[tri[2] as usize])
                        .normalize_or_zero();
                    let albedo = mesh.albedo_at(t, w1, w2);
                    let shade = 0.12 + 0.88 * n.dot(light).max(0.0);
                    albedo.map(|v| (linear_to_srgb(v * shade * 1.6) * 255.0).round() as u8)
                } else {
                    [255, 0, 255]
                };
                image.put_pixel(x, y, image::Rgb(colour));
            }
        }
    }
    image
}

/// Prints where edges that are not shared by exactly two opposite triangles lie.
fn report_defects(mesh: &Mesh) {
    let mut directed = std::collections::HashMap::new();
    for tri in &mesh.triangles {
        for k in 0..3 {
            *directed.entry((tri[k], tri[(k + 1) % 3])).or_insert(0u32) += 1;
        }
    }
    let mut shown = 0;
    for (&(a, b), &count) in &directed {
        let reverse = directed.get(&(b, a)).copied().unwrap_or(0);
        if (a < b || reverse == 0) && !(count == 1 && reverse == 1) && shown < 12 {
            let mid = 0.5 * (mesh.positions[a as usize] + mesh.positions[b as usize]);
            eprintln!("  defect edge {a}-{b} ×{count}/{reverse} at {mid:?}");
            shown += 1;
        }
    }
}
