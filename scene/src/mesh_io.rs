//! Mesh loaders — Geomview OFF (`OFF`, `COFF`, `NOFF`, `STOFF` …, polygons fan-
//! triangulated) and Wavefront OBJ with its MTL (`Kd`, `map_Kd`, per-corner UVs) —
//! plus the few mesh operations loading needs: turning about +y, fitting a head
//! height, making triangles face outward, and topology checks.
//!
//! Orientation: a mesh is made outward-facing by its signed volume
//! `V = Σ_t (a_t − c)·((b_t − c) × (c_t − c)) / 6` about the bounding-box centre
//! `c` (divergence theorem): `V < 0` means clockwise triangles, and all are flipped.
//!
//! Colour: 8-bit texture and vertex colours are sRGB and are converted to linear
//! with the IEC 61966-2-1 transfer function; MTL `Kd` is taken as linear.
//!
//! Our head convention: centred near the origin, +y up, facing +z (the frontal
//! camera sits on +z looking toward −z). `data/meshes/head.off` (CGAL's
//! scanned head, +y up) faces −x (its nose is the extreme −x point, on the
//! midline z ≈ 0) with clockwise triangles, and is open at the neck and at both
//! eyes (58 boundary edges): load it with [`LoadOptions::head_off`] (turn +90°
//! about +y, orient outward, fit 0.23 m).

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

use glam::{DVec3, Vec2, Vec3};

use crate::error::SceneError;
use crate::mesh::{Albedo, Mesh, Texture};
pub use crate::srgb::{linear_to_srgb, linear_to_srgb8, srgb_to_linear};

/// A plausible diffuse albedo of medium-light skin, linear RGB: what untextured
/// meshes (and OBJ files whose MTL is missing) get unless told otherwise.
pub const DEFAULT_SKIN_ALBEDO: [f32; 3] = [0.52, 0.36, 0.27];

/// Turn about +y, in degrees, that makes `data/meshes/head.off` face +z
/// (its nose points along −x as stored).
pub const HEAD_OFF_ROTATE_Y_DEG: f32 = 90.0;

/// How to post-process a mesh after parsing it.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadOptions {
    /// Scale uniformly so the mesh is this many metres tall (y extent) and centre
    /// its bounding box at the origin; `None` keeps the file's units and placement.
    pub fit_height_m: Option<f32>,
    /// Turn the mesh by this many degrees about +y (right-handed, before fitting):
    /// use it to make a head face +z. `0` keeps the file's orientation.
    pub rotate_y_deg: f32,
    /// Albedo (linear RGB) for meshes that carry none: plain OFF, OBJ without MTL,
    /// MTL without `Kd`.
    pub default_albedo: [f32; 3],
    /// Flip every triangle when the signed volume is negative, so triangles are
    /// counter-clockwise seen from outside (the [`Mesh`] convention). Meant for
    /// closed or nearly closed meshes (a head with an open neck is fine); turn it
    /// off for open sheets, whose signed volume says nothing.
    pub orient_outward: bool,
    /// Close every hole with a fan of triangles ([`Mesh::close_holes`]) before
    /// orienting: a head scan open at the neck or the eyes becomes a closed surface,
    /// so ground-truth images and the volume field agree there. Turn it off for
    /// open sheets.
    pub close_holes: bool,
}

impl Default for LoadOptions {
    fn default() -> Self {
        Self {
            fit_height_m: None,
            rotate_y_deg: 0.0,
            default_albedo: DEFAULT_SKIN_ALBEDO,
            orient_outward: true,
            close_holes: true,
        }
    }
}

impl LoadOptions {
    /// The options that put `data/meshes/head.off` in our head
    /// convention: facing +z, +y up, 0.23 m tall (head and neck), centred at the origin.
    pub fn head_off() -> Self {
        Self {
            fit_height_m: Some(0.23),
            rotate_y_deg: HEAD_OFF_ROTATE_Y_DEG,
            ..Self::default()
        }
    }
}

/// Loads a mesh, choosing the parser by extension (`.off`, `.obj`, any case), then
/// applies `options` (orient, turn, fit) and validates it.
pub fn load_mesh(path: impl AsRef<Path>, options: &LoadOptions) -> Result<Mesh, SceneError> {
    let path = path.as_ref();
    let extension = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let mesh = match extension.as_deref() {
        Some("off") => {
            let text = std::fs::read_to_string(path).map_err(|e| SceneError::io(path, e))?;
            parse_off(&text, path, options.default_albedo)?
        }
        Some("obj") => read_obj(path, options.default_albedo)?,
        _ => {
            return Err(SceneError::UnsupportedExtension {
                path: path.to_path_buf(),
                expected: ".off or .obj",
            });
        }
    };
    finish(mesh, path, options)
}

/// Applies orientation, rotation and fitting, then validates.
fn finish(mut mesh: Mesh, path: &Path, options: &LoadOptions) -> Result<Mesh, SceneError> {
    let invalid = |source| SceneError::Mesh {
        path: path.to_path_buf(),
        source,
    };
    mesh.validate().map_err(invalid)?;
    if options.close_holes {
        mesh.close_holes();
    }
    if options.orient_outward && mesh.signed_volume() < 0.0 {
        mesh.flip_winding();
    }
    if options.rotate_y_deg != 0.0 {
        if !options.rotate_y_deg.is_finite() {
            return Err(SceneError::format(path, "rotate_y_deg is not finite"));
        }
        mesh.rotate_y_deg(options.rotate_y_deg);
    }
    if let Some(height_m) = options.fit_height_m {
        if !(height_m.is_finite() && height_m > 0.0) {
            return Err(SceneError::format(
                path,
                format!("fit height {height_m} m is not a positive number"),
            ));
        }
        mesh.fit_height(Vec3::ZERO, height_m);
    }
    mesh.validate().map_err(invalid)?;
    Ok(mesh)
}

/// Mesh operations used by the loaders and by tests of any mesh.
/// Largest area of a hole's cap, as a share of the area of the connected piece of
/// the mesh around it, that [`Mesh::close_holes`] closes (¼: a head scan's neck
/// opening is about 5 % of the head; an open sheet's rim encloses about its own area).
pub const MAX_CAP_SHARE: f32 = 0.25;

impl Mesh {
    /// For every triangle, the surface area of the connected piece it belongs to
    /// (triangles sharing a vertex are connected).
    fn piece_areas(&self) -> Vec<f32> {
        fn root(parent: &mut [u32], mut i: u32) -> u32 {
            while parent[i as usize] != i {
                let up = parent[parent[i as usize] as usize];
                parent[i as usize] = up;
                i = up;
            }
            i
        }
        let mut parent: Vec<u32> = (0..self.positions.len() as u32).collect();
        for tri in &self.triangles {
            let r0 = root(&mut parent, tri[0]);
            for &v in &tri[1..] {
                let r = root(&mut parent, v);
                parent[r as usize] = r0;
            }
        }
        let mut area = vec![0.0f32; self.positions.len()];
        let roots: Vec<u32> = self.triangles.iter().map(|t| root(&mut parent, t[0])).collect();
        for (t, &r) in roots.iter().enumerate() {
            let [a, b, c] = self.corners(t);
            area[r as usize] += 0.5 * (b - a).cross(c - a).length();
        }
        roots.iter().map(|&r| area[r as usize]).collect()
    }

    /// Turns every position by `degrees` about +y (right-handed: +90° takes −x to +z).
    pub fn rotate_y_deg(&mut self, degrees: f32) {
        let rotation = glam::Mat3::from_rotation_y(degrees.to_radians());
        for p in &mut self.positions {
            *p = rotation * *p;
        }
    }

    /// Reverses every triangle's winding (keeping per-corner UVs with their corners).
    pub fn flip_winding(&mut self) {
        for tri in &mut self.triangles {
            tri.swap(1, 2);
        }
        if let Albedo::Texture { uvs, .. } = &mut self.albedo {
            for corners in uvs.chunks_exact_mut(3) {
                corners.swap(1, 2);
            }
        }
    }

    /// Closes every hole: each loop of boundary edges (a directed edge `a → b` whose
    /// reverse no triangle has) gets a new vertex at the loop's centroid and a fan of
    /// triangles `(b, a, centroid)`, oriented like their neighbours. Scans open at the
    /// neck or the eyes become closed surfaces, so inside and outside are defined
    /// everywhere and a camera looking into an opening sees a cap, as a volume model
    /// of the head will show. The new vertex's albedo is the loop's mean (per-vertex
    /// colours) and each cap corner's texture coordinate is copied from the
    /// neighbouring triangle's corner (the centroid's: their mean). Returns the
    /// number of loops closed. Non-manifold boundary vertices (several boundary edges
    /// leaving one vertex) are followed one way.
    ///
    /// Only *holes* are closed: a loop whose fan would be large next to the surface it
    /// bounds (area above [`MAX_CAP_SHARE`] of its connected piece's) is the rim of an
    /// open sheet — a collar, a flap of cloth, a shell torn wide open — and is left
    /// open: a fan over it would add a lid the scan does not have.
    pub fn close_holes(&mut self) -> usize {
        let piece_area = self.piece_areas();
        let tri_count = self.triangles.len();
        let mut directed: HashSet<(u32, u32)> = HashSet::with_capacity(3 * tri_count);
        for tri in &self.triangles {
            for e in 0..3 {
                directed.insert((tri[e], tri[(e + 1) % 3]));
            }
        }
        // Boundary edges a → b by start vertex, with the (triangle, corner) of a and b.
        let mut leaving: HashMap<u32, Vec<(u32, usize, usize)>> = HashMap::new();
        let mut boundary = Vec::new();
        for (t, tri) in self.triangles.iter().enumerate() {
            for e in 0..3 {
                let (a, b) = (tri[e], tri[(e + 1) % 3]);
                if !directed.contains(&(b, a)) {
                    leaving
                        .entry(a)
                        .or_default()
                        .push((b, 3 * t + e, 3 * t + (e + 1) % 3));
                    boundary.push((a, b, 3 * t + e, 3 * t + (e + 1) % 3));
                }
            }
        }
        let mut used: HashSet<(u32, u32)> = HashSet::new();
        let mut loops = 0;
        for &(start, first, ..) in &boundary {
            if used.contains(&(start, first)) {
                continue;
            }
            // Walk the loop start → first → … back to start.
            let mut edges = Vec::new();
            let mut a = start;
            while let Some(next) = leaving
                .get(&a)
                .and_then(|list| list.iter().find(|(b, ..)| !used.contains(&(a, *b))).copied())
            {
                used.insert((a, next.0));
                edges.push((a, next.0, next.1, next.2));
                a = next.0;
                if a == start {
                    break;
                }
            }
            if edges.len() < 3 {
                continue;
            }
            let n = edges.len() as f32;
            let centroid = edges
                .iter()
                .map(|e| self.positions[e.0 as usize])
                .sum::<glam::Vec3>()
                / n;
            let cap_area: f32 = edges
                .iter()
                .map(|e| {
                    let (a, b) = (self.positions[e.0 as usize], self.positions[e.1 as usize]);
                    0.5 * (a - centroid).cross(b - centroid).length()
                })
                .sum();
            if cap_area > MAX_CAP_SHARE * piece_area[edges[0].2 / 3] {
                continue;
            }
            let c = self.positions.len() as u32;
            self.positions.push(centroid);
            if let Albedo::PerVertex(colours) = &mut self.albedo {
                let mean: [f32; 3] = std::array::from_fn(|ch| {
                    edges.iter().map(|e| colours[e.0 as usize][ch]).sum::<f32>() / n
                });
                colours.push(mean);
            }
            if let Albedo::Texture { uvs, .. } = &mut self.albedo {
                let centre_uv = edges.iter().map(|e| uvs[e.2]).sum::<glam::Vec2>() / n;
                for &(_, _, corner_a, corner_b) in &edges {
                    let (uv_a, uv_b) = (uvs[corner_a], uvs[corner_b]);
                    uvs.extend_from_slice(&[uv_b, uv_a, centre_uv]);
                }
            }
            for &(a, b, ..) in &edges {
                self.triangles.push([b, a, c]);
            }
            loops += 1;
        }
        loops
    }

    /// Signed volume enclosed by the triangles, about the bounding-box centre, in
    /// cubic units of the positions: positive for outward (counter-clockwise)
    /// triangles of a closed mesh. Computed in `f64`.
    pub fn signed_volume(&self) -> f64 {
        let (lo, hi) = self.bounds();
        let centre = (0.5 * (lo + hi)).as_dvec3();
        self.triangles
            .iter()
            .map(|tri| {
                let [a, b, c] = tri.map(|i| self.positions[i as usize].as_dvec3() - centre);
                a.dot(b.cross(c))
            })
            .sum::<f64>()
            / 6.0
    }

    /// Undirected edges that are *not* shared by exactly two triangles traversing
    /// them in opposite directions: 0 for a closed, consistently oriented
    /// (watertight, 2-manifold-edged) mesh. Boundary edges, edges of three or more
    /// triangles and edges where neighbours disagree on orientation all count.
    pub fn edge_defects(&self) -> usize {
        let mut directed: HashMap<(u32, u32), u32> = HashMap::with_capacity(3 * self.triangles.len());
        for tri in &self.triangles {
            for k in 0..3 {
                *directed.entry((tri[k], tri[(k + 1) % 3])).or_insert(0) += 1;
            }
        }
        let mut defects = 0;
        for (&(a, b), &count) in &directed {
            let reverse = directed.get(&(b, a)).copied().unwrap_or(0);
            // Count each undirected edge once: from its smaller-first direction, or
            // from the only direction that exists.
            if (a < b || reverse == 0) && !(count == 1 && reverse == 1) {
                defects += 1;
            }
        }
        defects
    }

    /// Area-weighted unit vertex normals (zero for vertices of no triangle).
    pub fn vertex_normals(&self) -> Vec<Vec3> {
        let mut normals = vec![DVec3::ZERO; self.positions.len()];
        for tri in &self.triangles {
            let [a, b, c] = tri.map(|i| self.positions[i as usize].as_dvec3());
            let n = (b - a).cross(c - a);
            for &i in tri {
                normals[i as usize] += n;
            }
        }
        normals.iter().map(|n| n.normalize_or_zero().as_vec3()).collect()
    }
}

/// Which optional per-vertex fields an OFF header announces (`[ST][C][N]OFF`).
#[derive(Debug, Clone, Copy, Default)]
struct OffLayout {
    texture_coords: bool,
    colours: bool,
    normals: bool,
}

/// Strips a `#` comment and surrounding blanks.
fn strip_comment(line: &str) -> &str {
    line.split('#').next().unwrap_or("").trim()
}

/// Parses the OFF keyword (`OFF`, `COFF`, `NOFF`, `STCNOFF`, …).
fn off_layout(keyword: &str, path: &Path, line: usize) -> Result<OffLayout, SceneError> {
    let Some(mut prefix) = keyword.strip_suffix("OFF") else {
        return Err(SceneError::parse(
            path,
            line,
            format!("expected an OFF header (OFF, COFF, NOFF, …), found {keyword:?}"),
        ));
    };
    let mut layout = OffLayout::default();
    if let Some(rest) = prefix.strip_prefix("ST") {
        layout.texture_coords = true;
        prefix = rest;
    }
    if let Some(rest) = prefix.strip_prefix('C') {
        layout.colours = true;
        prefix = rest;
    }
    if let Some(rest) = prefix.strip_prefix('N') {
        layout.normals = true;
        prefix = rest;
    }
    if !prefix.is_empty() {
        return Err(SceneError::parse(
            path,
            line,
            format!("unsupported OFF variant {keyword:?} (4D and nD OFF are not read)"),
        ));
    }
    Ok(layout)
}

/// Parses one number token, naming the line on failure.
fn number<T: std::str::FromStr>(token: &str, what: &str, path: &Path, line: usize) -> Result<T, SceneError> {
    token
        .parse::<T>()
        .map_err(|_| SceneError::parse(path, line, format!("{what}: cannot read {token:?} as a number")))
}

/// Parses Geomview OFF text. `path` is only used in error messages.
///
/// Accepts `[ST][C][N]OFF` headers (counts on the header line or the next), `#`
/// comments and blank lines anywhere, one vertex per line (`x y z [nx ny nz]
/// [r g b [a]] [s t]`) and one face per line (`n i₁ … iₙ [colour]`), polygons with
/// more than three vertices split into a fan. `COFF` vertex colours (0–1 floats or
/// 0–255 integers, sRGB) become per-vertex albedo; otherwise the mesh gets
/// `default_albedo`. Face colours, normals, texture coordinates and the edge count
/// are read past and ignored.
pub fn parse_off(text: &str, path: &Path, default_albedo: [f32; 3]) -> Result<Mesh, SceneError> {
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, strip_comment(l)))
        .filter(|(_, l)| !l.is_empty());
    let Some((header_line, header)) = lines.next() else {
        return Err(SceneError::format(path, "empty file: no OFF header"));
    };
    let mut header_tokens = header.split_whitespace();
    let keyword = header_tokens.next().unwrap_or("");
    let layout = off_layout(keyword, path, header_line)?;
    let mut rest: Vec<&str> = header_tokens.collect();
    if rest.first() == Some(&"BINARY") {
        return Err(SceneError::parse(
            path,
            header_line,
            "binary OFF is not supported",
        ));
    }
    let mut counts_line = header_line;
    if rest.is_empty() {
        let Some((line, counts)) = lines.next() else {
            return Err(SceneError::format(
                path,
                "file ends before the vertex/face counts",
            ));
        };
        counts_line = line;
        rest = counts.split_whitespace().collect();
    }
    if rest.len() < 2 {
        return Err(SceneError::parse(
            path,
            counts_line,
            "expected counts \"vertices faces [edges]\"",
        ));
    }
    let vertex_count: usize = number(rest[0], "vertex count", path, counts_line)?;
    let face_count: usize = number(rest[1], "face count", path, counts_line)?;

    // Never trust counts for allocation: each vertex or face needs at least one line.
    let budget = text.len() / 2 + 1;
    let mut positions = Vec::with_capacity(vertex_count.min(budget));
    let mut colours = Vec::with_capacity(if layout.colours {
        vertex_count.min(budget)
    } else {
        0
    });
    for read in 0..vertex_count {
        let Some((line, body)) = lines.next() else {
            return Err(SceneError::format(
                path,
                format!("file ends after {read} of {vertex_count} vertices"),
            ));
        };
        let tokens: Vec<&str> = body.split_whitespace().collect();
        if tokens.len() < 3 {
            return Err(SceneError::parse(path, line, "a vertex needs three coordinates"));
        }
        let mut xyz = [0.0f32; 3];
        for (k, v) in xyz.iter_mut().enumerate() {
            *v = number(tokens[k], "vertex coordinate", path, line)?;
        }
        let p = Vec3::from(xyz);
        if !p.is_finite() {
            return Err(SceneError::parse(path, line, "vertex coordinate is not finite"));
        }
        positions.push(p);
        if layout.colours {
            let start = 3 + if layout.normals { 3 } else { 0 };
            let end = tokens.len() - if layout.texture_coords { 2 } else { 0 };
            let fields = tokens.get(start..end).unwrap_or(&[]);
            if !(fields.len() == 3 || fields.len() == 4) {
                return Err(SceneError::parse(
                    path,
                    line,
                    format!(
                        "COFF vertex needs an RGB or RGBA colour, found {} values",
                        fields.len()
                    ),
                ));
            }
            let mut rgb = [0.0f32; 3];
            for (k, v) in rgb.iter_mut().enumerate() {
                *v = number(fields[k], "vertex colour", path, line)?;
            }
            colours.push(rgb);
        }
    }
    let mut triangles = Vec::with_capacity(face_count.min(budget));
    for read in 0..face_count {
        let Some((line, body)) = lines.next() else {
            return Err(SceneError::format(
                path,
                format!("file ends after {read} of {face_count} faces"),
            ));
        };
        let tokens: Vec<&str> = body.split_whitespace().collect();
        let corners: usize = number(tokens[0], "face vertex count", path, line)?;
        if corners < 3 {
            return Err(SceneError::parse(
                path,
                line,
                format!("a face needs at least 3 vertices, this one has {corners}"),
            ));
        }
        if tokens.len() < 1 + corners {
            return Err(SceneError::parse(
                path,
                line,
                format!("face announces {corners} vertices but lists {}", tokens.len() - 1),
            ));
        }
        let mut polygon = Vec::with_capacity(corners);
        for token in &tokens[1..=corners] {
            let index: u32 = number(token, "face vertex index", path, line)?;
            if index as usize >= vertex_count {
                return Err(SceneError::parse(
                    path,
                    line,
                    format!("face refers to vertex {index}, but the file has {vertex_count} vertices"),
                ));
            }
            polygon.push(index);
        }
        for k in 1..corners - 1 {
            triangles.push([polygon[0], polygon[k], polygon[k + 1]]);
        }
    }
    let albedo = if layout.colours {
        // Integers 0–255 if any component exceeds 1, else floats in [0, 1].
        let scale = if colours.iter().flatten().any(|&c| c > 1.0) {
            1.0 / 255.0
        } else {
            1.0
        };
        Albedo::PerVertex(
            colours
                .iter()
                .map(|c| c.map(|v| srgb_to_linear(v * scale)))
                .collect(),
        )
    } else {
        Albedo::Uniform(default_albedo)
    };
    Ok(Mesh {
        positions,
        triangles,
        albedo,
    })
}

/// Where one OBJ model's colour comes from.
#[derive(Debug, Clone)]
enum ModelColour {
    /// `map_Kd`: index into the list of distinct textures.
    Texture(usize),
    /// One colour (Kd, or the default).
    Flat([f32; 3]),
}

/// Reads an OBJ (and its MTL) with `tobj`, triangulating polygons as fans.
///
/// Albedo, in order of preference:
/// * models whose material has `map_Kd` and that have UVs use the texture (sRGB →
///   linear; `Kd` is not multiplied in — exporters often write `Kd 0.8` beside a
///   texture that already holds the colour). Several textures, and untextured
///   models beside textured ones, are packed into one atlas (textures stacked
///   top to bottom at a common width, plus one row per flat colour), so the mesh
///   keeps a single [`Albedo::Texture`]. In an atlas a triangle's UVs are shifted
///   by a whole number so its mean `v` lies in `[0, 1)` and `v` is then clamped
///   to `[0, 1]`: textures repeating in `v` across one triangle are not supported
///   there (`u` wraps as usual). A single texture keeps the file's UVs untouched.
/// * otherwise, when every model has OBJ vertex colours (`v x y z r g b`), those
///   (sRGB) per vertex;
/// * otherwise each model's `Kd` (linear), per vertex when models differ, else
///   uniform.
///
/// A missing or unreadable MTL file, a material without `Kd` and a model without a
/// material fall back to `default_albedo`, silently: a mesh without materials is
/// ordinary. A missing *texture* file is an error naming it.
fn read_obj(path: &Path, default_albedo: [f32; 3]) -> Result<Mesh, SceneError> {
    let obj_options = tobj::LoadOptions {
        single_index: false,
        triangulate: true,
        ignore_points: true,
        ignore_lines: true,
    };
    let (models, materials) = tobj::load_obj(path, &obj_options).map_err(|e| match e {
        tobj::LoadError::OpenFileFailed => SceneError::io(
            path,
            std::fs::File::open(path)
                .err()
                .unwrap_or_else(|| std::io::Error::other("could not open file")),
        ),
        other => SceneError::format(path, format!("cannot parse OBJ: {other}")),
    })?;
    let materials = materials.unwrap_or_default();
    let base = path.parent().unwrap_or_else(|| Path::new(""));

    let mut texture_paths: Vec<PathBuf> = Vec::new();
    let mut colours = Vec::with_capacity(models.len());
    for model in &models {
        let material = model.mesh.material_id.and_then(|id| materials.get(id));
        let kd = material.and_then(|m| m.diffuse).unwrap_or(default_albedo);
        let texture = material.and_then(|m| m.diffuse_texture.as_deref());
        let colour = match texture {
            Some(name) if !model.mesh.texcoords.is_empty() => {
                let file = resolve_texture_path(base, name);
                let index = texture_paths.iter().position(|p| *p == file).unwrap_or_else(|| {
                    texture_paths.push(file);
                    texture_paths.len() - 1
                });
                ModelColour::Texture(index)
            }
            _ => ModelColour::Flat(kd.map(|v| v.clamp(0.0, 1.0))),
        };
        colours.push(colour);
    }

    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    for model in &models {
        let offset = positions.len() as u32;
        positions.extend(
            model
                .mesh
                .positions
                .chunks_exact(3)
                .map(|p| Vec3::new(p[0], p[1], p[2])),
        );
        triangles.extend(
            model
                .mesh
                .indices
                .chunks_exact(3)
                .map(|t| [t[0] + offset, t[1] + offset, t[2] + offset]),
        );
    }
    if triangles.is_empty() {
        return Err(SceneError::format(path, "the OBJ file has no faces"));
    }

    let albedo = if texture_paths.is_empty() {
        flat_obj_albedo(&models, &colours, positions.len(), default_albedo)
    } else {
        let textures = texture_paths
            .iter()
            .map(|p| load_texture(p))
            .collect::<Result<Vec<_>, _>>()?;
        textured_obj_albedo(&models, &colours, &textures)
    };
    Ok(Mesh {
        positions,
        triangles,
        albedo,
    })
}

/// Writes `mesh` as a Wavefront OBJ at `path` (metres) with its material beside it:
/// `<stem>.mtl`, and for a textured mesh the texture as an sRGB JPEG
/// `<stem>_albedo.jpg` (quality 95) named by `map_Kd`, per-corner UVs as `vt`.
/// Per-vertex colours are written as sRGB after each `v` (the common extension
/// [`load_mesh`] reads); a uniform colour is the material's `Kd` (linear). Each file
/// is written to a temporary name and renamed into place.
pub fn write_obj(mesh: &Mesh, path: &Path) -> Result<(), SceneError> {
    use std::fmt::Write as _;
    mesh.validate()
        .map_err(|e| SceneError::format(path, e.to_string()))?;
    let stem = path
        .file_stem()
        .and_then(|s| s.to_str())
        .ok_or_else(|| SceneError::format(path, "the OBJ path has no file name"))?;
    let mtl_name = format!("{stem}.mtl");
    let texture_name = format!("{stem}_albedo.jpg");
    let sibling = |name: &str| path.with_file_name(name);
    let mut obj = format!("# written by nelf-scene\nmtllib {mtl_name}\nusemtl albedo\n");
    let mut mtl = String::from("newmtl albedo\n");
    let srgb = |c: [f32; 3]| c.map(linear_to_srgb);
    for (i, p) in mesh.positions.iter().enumerate() {
        match &mesh.albedo {
            Albedo::PerVertex(colours) => {
                let [r, g, b] = srgb(colours[i]);
                let _ = writeln!(obj, "v {} {} {} {r} {g} {b}", p.x, p.y, p.z);
            }
            _ => {
                let _ = writeln!(obj, "v {} {} {}", p.x, p.y, p.z);
            }
        }
    }
    match &mesh.albedo {
        Albedo::Texture { uvs, texture } => {
            for uv in uvs {
                let _ = writeln!(obj, "vt {} {}", uv.x, uv.y);
            }
            for (t, tri) in mesh.triangles.iter().enumerate() {
                let [a, b, c] = tri.map(|i| i + 1);
                let k = 3 * t as u32;
                let _ = writeln!(obj, "f {a}/{} {b}/{} {c}/{}", k + 1, k + 2, k + 3);
            }
            let _ = writeln!(mtl, "Kd 1 1 1\nmap_Kd {texture_name}");
            crate::image_io::write_jpeg_srgb(
                sibling(&texture_name),
                texture.width as u32,
                texture.height as u32,
                &texture.texels,
                95,
            )?;
        }
        albedo => {
            for tri in &mesh.triangles {
                let [a, b, c] = tri.map(|i| i + 1);
                let _ = writeln!(obj, "f {a} {b} {c}");
            }
            let kd = match albedo {
                Albedo::Uniform(c) => *c,
                _ => [1.0; 3],
            };
            let _ = writeln!(mtl, "Kd {} {} {}", kd[0], kd[1], kd[2]);
        }
    }
    let write_text = |target: &Path, text: &str| {
        nelf_format::atomic::write_bytes_atomically(target, text.as_bytes())
            .map_err(|e| SceneError::io(target, e))
    };
    write_text(&sibling(&mtl_name), &mtl)?;
    write_text(path, &obj)
}

/// A `map_Kd` value may carry options (`-bm 0.5 skin.png`): use the whole value if
/// it names a file, else its last word.
fn resolve_texture_path(base: &Path, value: &str) -> PathBuf {
    let whole = base.join(value.trim());
    if whole.is_file() {
        return whole;
    }
    let last = value.split_whitespace().last().unwrap_or(value);
    base.join(last)
}

/// Albedo of an OBJ without textures: vertex colours, else Kd per model.
fn flat_obj_albedo(
    models: &[tobj::Model],
    colours: &[ModelColour],
    vertex_count: usize,
    default_albedo: [f32; 3],
) -> Albedo {
    let flat = |c: &ModelColour| match c {
        ModelColour::Flat(rgb) => *rgb,
        ModelColour::Texture(_) => default_albedo,
    };
    if models
        .iter()
        .all(|m| !m.mesh.vertex_color.is_empty() && m.mesh.vertex_color.len() == m.mesh.positions.len())
    {
        let per_vertex = models
            .iter()
            .flat_map(|m| m.mesh.vertex_color.chunks_exact(3))
            .map(|c| [c[0], c[1], c[2]].map(srgb_to_linear))
            .collect();
        return Albedo::PerVertex(per_vertex);
    }
    let first = colours.first().map_or(default_albedo, flat);
    if colours.iter().all(|c| flat(c) == first) {
        return Albedo::Uniform(first);
    }
    let mut per_vertex = Vec::with_capacity(vertex_count);
    for (model, colour) in models.iter().zip(colours) {
        per_vertex.extend(std::iter::repeat_n(flat(colour), model.mesh.positions.len() / 3));
    }
    Albedo::PerVertex(per_vertex)
}

/// The UV of corner `k` of triangle `t` of a tobj mesh (0 if it has none).
fn corner_uv(mesh: &tobj::Mesh, t: usize, k: usize) -> Vec2 {
    let i = mesh.texcoord_indices.get(3 * t + k).copied().unwrap_or(0) as usize;
    match mesh.texcoords.get(2 * i..2 * i + 2) {
        Some(uv) if uv[0].is_finite() && uv[1].is_finite() => Vec2::new(uv[0], uv[1]),
        _ => Vec2::ZERO,
    }
}

/// Albedo of an OBJ with at least one texture: per-corner UVs into the texture
/// itself when it is the only colour source, else into an atlas.
fn textured_obj_albedo(models: &[tobj::Model], colours: &[ModelColour], textures: &[Texture]) -> Albedo {
    let mut flat_colours: Vec<[f32; 3]> = Vec::new();
    for colour in colours {
        if let ModelColour::Flat(rgb) = colour {
            if !flat_colours.contains(rgb) {
                flat_colours.push(*rgb);
            }
        }
    }
    if let ([texture], true) = (textures, flat_colours.is_empty()) {
        // One texture for everything: the file's UVs as they are (wrapping as usual).
        let uvs = models
            .iter()
            .flat_map(|m| (0..m.mesh.indices.len() / 3).flat_map(move |t| (0..3).map(move |k| (m, t, k))))
            .map(|(m, t, k)| corner_uv(&m.mesh, t, k))
            .collect();
        return Albedo::Texture {
            uvs,
            texture: texture.clone(),
        };
    }
    // Atlas rows: each texture (resampled to the widest, nearest) between copies of
    // its first and last rows, so v = 0 and v = 1 stay inside the block; then one
    // row per flat colour.
    let width = textures.iter().map(|t| t.width).max().unwrap_or(1);
    let mut block_rows = Vec::with_capacity(textures.len());
    let mut texels = Vec::new();
    for texture in textures {
        block_rows.push((texels.len() / width + 1, texture.height));
        let rows = std::iter::once(0)
            .chain(0..texture.height)
            .chain(std::iter::once(texture.height - 1));
        for y in rows {
            for x in 0..width {
                let sx = (x * texture.width) / width;
                texels.push(texture.texels[y * texture.width + sx]);
            }
        }
    }
    let flat_rows_start = texels.len() / width;
    for rgb in &flat_colours {
        texels.extend(std::iter::repeat_n(*rgb, width));
    }
    let height = flat_rows_start + flat_colours.len();
    let atlas_v = |block_row: usize, block_height: usize, v_local: f32| {
        // Row within the atlas of local v (v = 1 at the block's top row).
        let rows = block_row as f32 + (1.0 - v_local) * block_height as f32;
        1.0 - rows / height as f32
    };

    let mut uvs = Vec::new();
    for (model, colour) in models.iter().zip(colours) {
        let mesh = &model.mesh;
        match colour {
            ModelColour::Texture(index) => {
                let (block_row, block_height) = block_rows[*index];
                for t in 0..mesh.indices.len() / 3 {
                    let corners = [0, 1, 2].map(|k| corner_uv(mesh, t, k));
                    let shift = ((corners[0].y + corners[1].y + corners[2].y) / 3.0).floor();
                    for uv in corners {
                        let v_local = (uv.y - shift).clamp(0.0, 1.0);
                        uvs.push(Vec2::new(uv.x, atlas_v(block_row, block_height, v_local)));
                    }
                }
            }
            ModelColour::Flat(rgb) => {
                let k = flat_colours.iter().position(|c| c == rgb).unwrap_or(0);
                let uv = Vec2::new(0.5, atlas_v(flat_rows_start + k, 1, 0.5));
                uvs.extend(std::iter::repeat_n(uv, mesh.indices.len()));
            }
        }
    }
    Albedo::Texture {
        uvs,
        texture: Texture {
            width,
            height,
            texels,
        },
    }
}

/// Loads an RGB texture as linear colour: 8- and 16-bit images are sRGB and are
/// linearised; float images (HDR, EXR) are taken as linear. Alpha is ignored.
pub fn load_texture(path: &Path) -> Result<Texture, SceneError> {
    let image_error = |source| SceneError::Image {
        path: path.to_path_buf(),
        source,
    };
    let decoded = image::ImageReader::open(path)
        .map_err(|e| SceneError::io(path, e))?
        .with_guessed_format()
        .map_err(|e| SceneError::io(path, e))?
        .decode()
        .map_err(image_error)?;
    let is_float = matches!(
        decoded,
        image::DynamicImage::ImageRgb32F(_) | image::DynamicImage::ImageRgba32F(_)
    );
    let rgb = decoded.to_rgb32f();
    let (width, height) = (rgb.width() as usize, rgb.height() as usize);
    if width == 0 || height == 0 {
        return Err(SceneError::format(path, "texture has no pixels"));
    }
    let texels = rgb
        .pixels()
        .map(|p| {
            p.0.map(|v| {
                if is_float {
                    if v.is_finite() { v.clamp(0.0, 1.0) } else { 0.0 }
                } else {
                    srgb_to_linear(v)
                }
            })
        })
        .collect();
    Ok(Texture {
        width,
        height,
        texels,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn off_layout_prefixes() {
        let p = Path::new("x.off");
        let l = off_layout("STCNOFF", p, 1).unwrap();
        assert!(l.texture_coords && l.colours && l.normals);
        assert!(off_layout("4OFF", p, 1).is_err());
        assert!(off_layout("PLY", p, 1).is_err());
    }

    #[test]
    fn tetrahedron_topology_and_volume() {
        let mut m = Mesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z],
            triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
            albedo: Albedo::Uniform([0.5; 3]),
        };
        assert_eq!(m.edge_defects(), 0);
        assert!((m.signed_volume() - 1.0 / 6.0).abs() < 1e-9);
        m.flip_winding();
        assert!((m.signed_volume() + 1.0 / 6.0).abs() < 1e-9);
        assert_eq!(m.edge_defects(), 0);
        m.triangles[0].swap(1, 2);
        assert_eq!(m.edge_defects(), 3, "one flipped face disagrees on all its edges");
        m.triangles.pop();
        assert!(m.edge_defects() > 0);
    }

    #[test]
    fn rotate_y_takes_minus_x_to_plus_z() {
        let mut m = Mesh {
            positions: vec![Vec3::NEG_X],
            triangles: vec![[0, 0, 0]],
            albedo: Albedo::Uniform([0.5; 3]),
        };
        m.rotate_y_deg(90.0);
        assert!(m.positions[0].abs_diff_eq(Vec3::Z, 1e-6));
    }
}
