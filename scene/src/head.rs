//! Procedural human heads, so that tests and training need no files.
//!
//! A head is a signed distance function (negative inside) built from ellipsoids,
//! capsules and tapered capsules combined with the polynomial smooth minimum
//! `smin(a, b, k) = mix(b, a, h) − k·h·(1 − h)`, `h = clamp(½ + ½(b − a)/k, 0, 1)`
//! (and `smax(a, b, k) = −smin(−a, −b, k)` for carving): cranium, mid-face, jaw,
//! chin and jaw line, cheekbones, cheeks, brow ridge, nose (bridge, tip, alae),
//! eye sockets holding eyeballs, lips, ears with a concha, a neck cut flat at the
//! bottom and a hair cap over the top and back of the skull. The field is sampled
//! on a regular grid and polygonised with Naive Surface Nets (Gibson 1998, via the
//! `fast-surface-nets` crate): one vertex per sign-changing cell, one quad per
//! sign-changing grid edge, so the mesh is closed; features are kept thicker than
//! a few cells so no cell face is ambiguous and every edge has exactly two
//! triangles. Triangles are oriented along the field's gradient (outward,
//! counter-clockwise).
//!
//! Albedo is per vertex, by which part of the field forms the surface there:
//! skin (a tone from pale to dark interpolated between measured-looking linear
//! RGB skin albedos), redder lips, brows and hair in the hair colour, eyeballs
//! with sclera, iris and pupil.
//!
//! Frame: metres, +y up, facing +z (the nose is the extreme point along +z),
//! bounding box centred at the origin, total height (hair top to neck cut)
//! 0.19–0.24 m by default — smaller than life: the whole head *and* neck fits
//! in that height.
//!
//! Everything is a pure function of the seed and [`HeadParams`]: the same seed
//! gives the same mesh, bit for bit.

use glam::{Mat3, Vec3};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;

use crate::mesh::{Albedo, Mesh};

/// Linear-RGB skin albedos from pale (tone 0) to dark (tone 1), evenly spaced in
/// tone; chosen to resemble measured diffuse skin reflectance (red > green > blue,
/// about 0.7 → 0.09 in red).
const SKIN_TONES: [[f32; 3]; 5] = [
    [0.70, 0.52, 0.44],
    [0.56, 0.38, 0.29],
    [0.40, 0.25, 0.17],
    [0.22, 0.13, 0.08],
    [0.09, 0.052, 0.035],
];

/// Skin albedo (linear RGB) for a tone in `[0, 1]`: 0 pale … 1 dark (clamped).
pub fn skin_albedo(tone: f32) -> [f32; 3] {
    let t = if tone.is_finite() {
        tone.clamp(0.0, 1.0)
    } else {
        0.5
    };
    let x = t * (SKIN_TONES.len() - 1) as f32;
    let i = (x.floor() as usize).min(SKIN_TONES.len() - 2);
    let f = x - i as f32;
    std::array::from_fn(|c| SKIN_TONES[i][c] * (1.0 - f) + SKIN_TONES[i + 1][c] * f)
}

/// Hair colours a head can get.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HairColour {
    /// Near-black.
    Black,
    /// Dark brown.
    DarkBrown,
    /// Mid brown.
    Brown,
    /// Blond.
    Blond,
    /// Auburn / red.
    Auburn,
    /// Grey.
    Grey,
}

impl HairColour {
    /// Every hair colour.
    pub const ALL: [Self; 6] = [
        Self::Black,
        Self::DarkBrown,
        Self::Brown,
        Self::Blond,
        Self::Auburn,
        Self::Grey,
    ];

    /// Diffuse albedo, linear RGB.
    pub fn albedo(self) -> [f32; 3] {
        match self {
            Self::Black => [0.020, 0.016, 0.013],
            Self::DarkBrown => [0.055, 0.033, 0.020],
            Self::Brown => [0.13, 0.075, 0.040],
            Self::Blond => [0.42, 0.30, 0.15],
            Self::Auburn => [0.28, 0.085, 0.030],
            Self::Grey => [0.33, 0.32, 0.31],
        }
    }
}

/// Settings of the generator. Fields left `None` are drawn from the seed.
#[derive(Debug, Clone, PartialEq)]
pub struct HeadParams {
    /// Grid cells along the head's height: sets the triangle count (about
    /// 6·n² triangles; the default 88 gives 43–50 k over seeds 0–29) and the
    /// smallest feature resolved. Clamped to `[32, 512]`.
    pub cells_per_height: u32,
    /// Total height in metres (hair top to the neck cut); `None`: uniform in
    /// 0.19–0.24 m.
    pub height_m: Option<f32>,
    /// Skin tone, 0 pale … 1 dark ([`skin_albedo`]); `None`: uniform in `[0, 1]`.
    pub skin_tone: Option<f32>,
    /// Hair colour; `None`: one of [`HairColour::ALL`] (grey less often).
    pub hair: Option<HairColour>,
}

impl Default for HeadParams {
    fn default() -> Self {
        Self {
            cells_per_height: 88,
            height_m: None,
            skin_tone: None,
            hair: None,
        }
    }
}

/// The appearance a seed chose (for tests, captions and metadata).
#[derive(Debug, Clone, PartialEq)]
pub struct HeadTraits {
    /// Skin tone, 0 pale … 1 dark.
    pub skin_tone: f32,
    /// Skin albedo, linear RGB.
    pub skin_albedo: [f32; 3],
    /// Hair colour.
    pub hair: HairColour,
    /// Hair albedo, linear RGB.
    pub hair_albedo: [f32; 3],
    /// Iris albedo, linear RGB.
    pub iris_albedo: [f32; 3],
    /// Lip albedo, linear RGB.
    pub lip_albedo: [f32; 3],
    /// Total height, metres.
    pub height_m: f32,
}

/// Signed distance to an ellipsoid (centre `c`, radii `r`): Quilez's bound,
/// exact on the surface, within a factor of the true distance elsewhere.
fn ellipsoid(p: Vec3, c: Vec3, r: Vec3) -> f32 {
    let q = p - c;
    let k0 = (q / r).length();
    let k1 = (q / (r * r)).length();
    if k1 > 1e-12 {
        k0 * (k0 - 1.0) / k1
    } else {
        -r.min_element()
    }
}

/// Signed distance to a capsule from `a` to `b` with radius `r`.
fn capsule(p: Vec3, a: Vec3, b: Vec3, r: f32) -> f32 {
    tapered_capsule(p, a, b, r, r)
}

/// Signed distance (approximate off the surface) to a capsule whose radius goes
/// linearly from `ra` at `a` to `rb` at `b`.
fn tapered_capsule(p: Vec3, a: Vec3, b: Vec3, ra: f32, rb: f32) -> f32 {
    let pa = p - a;
    let ba = b - a;
    let h = (pa.dot(ba) / ba.length_squared()).clamp(0.0, 1.0);
    (pa - ba * h).length() - (ra + (rb - ra) * h)
}

/// Polynomial smooth minimum with blend radius `k`.
fn smin(a: f32, b: f32, k: f32) -> f32 {
    let h = (0.5 + 0.5 * (b - a) / k).clamp(0.0, 1.0);
    b + (a - b) * h - k * h * (1.0 - h)
}

/// Smooth maximum (intersection; `smax(d, −e, k)` carves `e` out of `d`).
fn smax(a: f32, b: f32, k: f32) -> f32 {
    -smin(-a, -b, k)
}

/// Mirrors a point into the +x half (symmetric features are defined there).
fn mirror(p: Vec3) -> Vec3 {
    Vec3::new(p.x.abs(), p.y, p.z)
}

/// A uniform draw in `[lo, hi)`.
fn uniform(rng: &mut Pcg64Mcg, lo: f32, hi: f32) -> f32 {
    lo + (hi - lo) * rng.random::<f32>()
}

/// One head's geometry, in centimetres of a model frame (+y up, facing +z, pupils
/// at y = 1). Symmetric parts are stored for the +x side and mirrored.
#[derive(Debug, Clone)]
struct HeadShape {
    cranium_c: Vec3,
    cranium_r: Vec3,
    midface_c: Vec3,
    midface_r: Vec3,
    muzzle_c: Vec3,
    muzzle_r: Vec3,
    jaw_c: Vec3,
    jaw_r: Vec3,
    chin_c: Vec3,
    chin_r: Vec3,
    jawline_a: Vec3,
    jawline_b: Vec3,
    jawline_r: f32,
    cheekbone_c: Vec3,
    cheekbone_r: Vec3,
    cheek_c: Vec3,
    cheek_r: Vec3,
    brow_a: Vec3,
    brow_b: Vec3,
    brow_r: f32,
    nose_bridge: Vec3,
    nose_tip: Vec3,
    nose_bridge_r: f32,
    nose_tip_r: f32,
    ala_c: Vec3,
    ala_r: Vec3,
    lid_r: Vec3,
    fissure_c: Vec3,
    fissure_r: Vec3,
    eye_c: Vec3,
    eye_r: f32,
    iris_cos: f32,
    pupil_cos: f32,
    upper_lip_a: Vec3,
    upper_lip_b: Vec3,
    upper_lip_r: f32,
    lower_lip_a: Vec3,
    lower_lip_b: Vec3,
    lower_lip_r: f32,
    ear_c: Vec3,
    ear_r: Vec3,
    ear_from_model: Mat3,
    neck_top: Vec3,
    neck_low: Vec3,
    neck_r: f32,
    neck_bottom_y: f32,
    hair_c: Vec3,
    hair_thickness: f32,
    hairline_point: Vec3,
    hairline_normal: Vec3,
}

/// Distances to the parts of a head that carry different albedo.
#[derive(Debug, Clone, Copy)]
struct Parts {
    /// Skin: everything but the lips, eyes and hair.
    skin: f32,
    /// Lips.
    lips: f32,
    /// Eyeballs.
    eyes: f32,
    /// Hair cap.
    hair: f32,
}

impl Parts {
    /// The head's signed distance.
    fn distance(self) -> f32 {
        smin(
            smin(smin(self.skin, self.lips, 0.3), self.eyes, 0.2),
            self.hair,
            0.35,
        )
    }
}

impl HeadShape {
    /// Draws a head's proportions from `rng`: anatomical landmarks of an average
    /// adult (cm), each varied by a few to 15 %.
    fn random(rng: &mut Pcg64Mcg) -> Self {
        let mut vary = |spread: f32| 1.0 + uniform(rng, -spread, spread);
        let width = vary(0.06);
        let depth = vary(0.05);
        let height = vary(0.05);
        let face_length = vary(0.06);
        let jaw_width = vary(0.10);
        let chin = vary(0.15);
        let cheek = vary(0.12);
        let brow = vary(0.15);
        let nose_length = vary(0.12);
        let nose_out = vary(0.15);
        let nose_width = vary(0.15);
        let eye_spacing = vary(0.06);
        let lip = vary(0.2);
        let ear = vary(0.1);
        let neck = vary(0.08);
        let iris = vary(0.1);
        let hair_thickness = uniform(rng, 0.25, 0.75);
        let hairline = uniform(rng, -1.0, 1.0);

        let cranium_c = Vec3::new(0.0, 3.2, -1.2);
        let cranium_r = Vec3::new(7.5 * width, 9.0 * height, 9.5 * depth);
        let front = |y: f32| {
            let f = (y - cranium_c.y) / cranium_r.y;
            cranium_c.z + cranium_r.z * (1.0 - f * f).max(0.0).sqrt()
        };
        let eye_c = Vec3::new(3.1 * eye_spacing, 1.0, 6.35 * depth);
        let lid_r = Vec3::new(1.65, 1.5, 1.5);
        let ear_c = {
            let (y, z) = (-0.5 * face_length, -depth);
            let fy = (y - cranium_c.y) / cranium_r.y;
            let fz = (z - cranium_c.z) / cranium_r.z;
            let side = cranium_r.x * (1.0 - fy * fy - fz * fz).max(0.0).sqrt();
            Vec3::new(side + 0.2, y, z)
        };
        // Hairline: a plane through the forehead hairline and the nape, so the cap
        // covers the top and back of the skull and reaches the ears at the sides.
        let hair_front_y = 8.0 + hairline;
        let hairline_point = Vec3::new(0.0, hair_front_y, front(hair_front_y));
        let nape = Vec3::new(0.0, -4.5 + 0.5 * hairline, cranium_c.z - cranium_r.z);
        let along = hairline_point - nape;
        let hairline_normal = Vec3::new(0.0, along.z, -along.y).normalize();
        let mouth_y = -5.0 * face_length;
        let chin_c = Vec3::new(0.0, -8.6 * face_length, 6.3 * depth + 0.5 * (chin - 1.0));
        Self {
            cranium_c,
            cranium_r,
            midface_c: Vec3::new(0.0, -0.5, 3.3 * depth),
            midface_r: Vec3::new(5.6 * width, 4.5 * face_length, 4.6 * depth),
            muzzle_c: Vec3::new(0.0, mouth_y, 4.8 * depth),
            muzzle_r: Vec3::new(3.4, 2.8 * face_length, 3.5),
            jaw_c: Vec3::new(0.0, -3.6 * face_length, 2.2 * depth),
            jaw_r: Vec3::new(4.4 * jaw_width * width, 5.9 * face_length, 5.2 * depth),
            chin_c,
            chin_r: Vec3::new(1.9, 1.4, 1.5) * chin,
            jawline_a: Vec3::new(1.3 * chin, chin_c.y - 0.2, chin_c.z - 1.0),
            jawline_b: Vec3::new(4.6 * jaw_width * width, -6.3 * face_length, -0.5 * depth),
            jawline_r: 0.8 * jaw_width,
            cheekbone_c: Vec3::new(4.8 * width, 0.2, 4.2 * depth),
            cheekbone_r: Vec3::new(1.8, 1.2, 2.1) * cheek,
            cheek_c: Vec3::new(3.4 * width, -2.4 * face_length, 4.4 * depth),
            cheek_r: Vec3::new(1.9, 2.2, 2.2) * cheek,
            brow_a: Vec3::new(4.4 * width, 2.6, front(2.6) - 1.6),
            brow_b: Vec3::new(0.0, 2.8, front(2.8) - 0.7 + 0.4 * (brow - 1.0)),
            brow_r: 0.85 * brow,
            nose_bridge: Vec3::new(0.0, 1.9, 8.0 * depth),
            nose_tip: Vec3::new(0.0, -1.9 * nose_length, 8.0 * depth + 1.9 * nose_out),
            nose_bridge_r: 0.55 * nose_width,
            nose_tip_r: 0.85 * nose_width,
            ala_c: Vec3::new(
                0.95 * nose_width,
                -2.4 * nose_length,
                8.0 * depth + 0.8 * nose_out,
            ),
            ala_r: Vec3::new(0.7, 0.55, 0.75) * nose_width,
            lid_r,
            fissure_c: eye_c + Vec3::new(0.0, 0.05, lid_r.z),
            fissure_r: Vec3::new(1.45, 0.5, 0.75),
            eye_c,
            eye_r: 1.2,
            iris_cos: (0.5 * iris).cos(),
            pupil_cos: (0.2 * iris).cos(),
            upper_lip_a: Vec3::new(2.4 * lip.sqrt(), mouth_y - 0.2, 7.2 * depth),
            upper_lip_b: Vec3::new(0.0, mouth_y + 0.45, 8.2 * depth),
            upper_lip_r: 0.45 * lip,
            lower_lip_a: Vec3::new(2.1 * lip.sqrt(), mouth_y - 0.5, 7.1 * depth),
            lower_lip_b: Vec3::new(0.0, mouth_y - 1.0, 7.9 * depth),
            lower_lip_r: 0.5 * lip,
            ear_c,
            ear_r: Vec3::new(0.85, 3.0 * ear, 1.85 * ear),
            ear_from_model: Mat3::from_rotation_x(-0.25),
            neck_top: Vec3::new(0.0, -5.0, -1.8),
            neck_low: Vec3::new(0.0, -20.0, -2.6),
            neck_r: 5.3 * neck,
            neck_bottom_y: -13.5 * face_length,
            hair_c: cranium_c + Vec3::new(0.0, 0.1, -0.2),
            hair_thickness,
            hairline_point,
            hairline_normal,
        }
    }

    /// Distance to each albedo part at `p` (cm, model frame).
    fn parts(&self, p: Vec3) -> Parts {
        let q = mirror(p);
        let mut d = ellipsoid(p, self.cranium_c, self.cranium_r);
        d = smin(d, ellipsoid(p, self.midface_c, self.midface_r), 1.5);
        d = smin(d, ellipsoid(p, self.jaw_c, self.jaw_r), 2.0);
        d = smin(d, ellipsoid(p, self.muzzle_c, self.muzzle_r), 1.2);
        d = smin(d, ellipsoid(p, self.chin_c, self.chin_r), 1.8);
        d = smin(d, capsule(q, self.jawline_a, self.jawline_b, self.jawline_r), 2.0);
        d = smin(d, ellipsoid(q, self.cheekbone_c, self.cheekbone_r), 1.5);
        d = smin(d, ellipsoid(q, self.cheek_c, self.cheek_r), 2.0);
        d = smin(d, capsule(q, self.brow_a, self.brow_b, self.brow_r), 1.0);
        // Eyelids: a ball around each eyeball, with the eye opening carved out.
        d = smin(d, ellipsoid(q, self.eye_c, self.lid_r), 0.6);
        d = smax(d, -ellipsoid(q, self.fissure_c, self.fissure_r), 0.2);
        // Ears: a flattened, tilted ellipsoid with a bowl (concha) carved out.
        let local = self.ear_from_model * (q - self.ear_c);
        let concha = Vec3::new(0.9, -0.1 * self.ear_r.y, 0.2);
        let mut ear = ellipsoid(local, Vec3::ZERO, self.ear_r);
        ear = smax(ear, -ellipsoid(local, concha, Vec3::new(0.5, 1.2, 0.8)), 0.3);
        d = smin(d, ear, 0.6);
        let neck = capsule(p, self.neck_top, self.neck_low, self.neck_r).max(self.neck_bottom_y - p.y);
        d = smin(d, neck, 3.0);
        let nose = smin(
            tapered_capsule(
                p,
                self.nose_bridge,
                self.nose_tip,
                self.nose_bridge_r,
                self.nose_tip_r,
            ),
            ellipsoid(q, self.ala_c, self.ala_r),
            0.6,
        );
        let skin = smin(d, nose, 0.6);
        let upper = tapered_capsule(q, self.upper_lip_a, self.upper_lip_b, 0.25, self.upper_lip_r);
        let lower = tapered_capsule(q, self.lower_lip_a, self.lower_lip_b, 0.3, self.lower_lip_r);
        let lips = upper.min(lower);
        let eyes = (q - self.eye_c).length() - self.eye_r;
        let above_hairline = (self.hairline_point - p).dot(self.hairline_normal);
        // The cap thins to nothing over the last 2 cm before the hairline.
        let fade = (-above_hairline / 2.0).clamp(0.0, 1.0);
        let thickness = self.hair_thickness * fade * fade * (3.0 - 2.0 * fade);
        let hair = smax(
            ellipsoid(p, self.hair_c, self.cranium_r) - thickness,
            above_hairline,
            0.3,
        );
        Parts {
            skin,
            lips,
            eyes,
            hair,
        }
    }

    /// The head's signed distance at `p` (cm, model frame).
    fn distance(&self, p: Vec3) -> f32 {
        self.parts(p).distance()
    }

    /// Albedo at a surface point `p` (cm, model frame).
    fn albedo(&self, p: Vec3, traits: &HeadTraits) -> [f32; 3] {
        let parts = self.parts(p);
        let others = parts.skin.min(parts.lips).min(parts.hair);
        if parts.eyes < others {
            let gaze = (mirror(p) - self.eye_c).normalize_or_zero().z;
            return if gaze > self.pupil_cos {
                [0.012, 0.010, 0.010]
            } else if gaze > self.iris_cos {
                traits.iris_albedo
            } else {
                [0.62, 0.58, 0.53]
            };
        }
        // Hair blends into skin over about a millimetre (no jagged hairline).
        let hair_weight = (0.5 + (parts.skin.min(parts.lips) - parts.hair) / 0.3).clamp(0.0, 1.0);
        if hair_weight >= 1.0 {
            return traits.hair_albedo;
        }
        // Lips fade into skin over a few millimetres.
        let lip_weight = (1.0 - (parts.lips - parts.skin.min(0.0)) / 0.25).clamp(0.0, 1.0);
        let q = mirror(p);
        // Brows: a band along the top of the brow ridge, in the hair colour.
        let lift = Vec3::new(0.0, 0.5, 0.6);
        let brow_distance = capsule(
            q,
            self.brow_a + lift,
            self.brow_b.lerp(self.brow_a, 0.28) + lift,
            0.0,
        );
        let brow_weight = (1.0 - (brow_distance - 0.35) / 0.35).clamp(0.0, 1.0) * 0.85;
        let hair_weight = hair_weight.max(brow_weight);
        std::array::from_fn(|c| {
            let with_lips =
                traits.skin_albedo[c] + (traits.lip_albedo[c] - traits.skin_albedo[c]) * lip_weight;
            with_lips + (traits.hair_albedo[c] - with_lips) * hair_weight
        })
    }
}

/// Removes every ambiguous grid face (inside/outside corners in a checkerboard)
/// by moving its outside corners just inside, repeating until none is left.
///
/// Surface Nets makes one quad per sign-changing grid edge; the edge between the
/// vertices of two face-adjacent cells is shared by the quads of the sign-changing
/// edges of their common face — two, unless the face is a checkerboard, when four
/// quads share it and the mesh is not edge-manifold. Such faces only occur where
/// the field has a crack or sliver thinner than a cell; filling it changes the
/// shape by less than a cell. Every pass only turns outside corners inside, so the
/// loop ends. Returns the number of corners filled.
fn fill_ambiguous_faces(field: &mut [f32], [nx, ny, nz]: [usize; 3]) -> usize {
    const INSIDE: f32 = -1e-3;
    let index = |x: usize, y: usize, z: usize| (z * ny + y) * nx + x;
    let strides = [index(1, 0, 0), index(0, 1, 0), index(0, 0, 1)];
    let mut filled = 0;
    loop {
        let mut changed = 0;
        // Faces spanned by axis pairs (a, b), at every corner whose +a and +b neighbours exist.
        for (a, b) in [(0usize, 1usize), (1, 2), (0, 2)] {
            for z in 0..nz {
                for y in 0..ny {
                    for x in 0..nx {
                        let at = [x, y, z];
                        let limits = [nx, ny, nz];
                        if at[a] + 1 >= limits[a] || at[b] + 1 >= limits[b] {
                            continue;
                        }
                        let c00 = index(x, y, z);
                        let corners = [
                            c00,
                            c00 + strides[a],
                            c00 + strides[a] + strides[b],
                            c00 + strides[b],
                        ];
                        let inside = corners.map(|c| field[c] < 0.0);
                        if inside[0] == inside[2] && inside[1] == inside[3] && inside[0] != inside[1] {
                            for (c, is_inside) in corners.iter().zip(inside) {
                                if !is_inside {
                                    field[*c] = INSIDE;
                                    changed += 1;
                                }
                            }
                        }
                    }
                }
            }
        }
        filled += changed;
        if changed == 0 {
            return filled;
        }
    }
}

/// Draws the traits a seed gives, honouring the fields `params` fixes.
fn draw_traits(rng: &mut Pcg64Mcg, params: &HeadParams) -> HeadTraits {
    let tone_draw = rng.random::<f32>();
    let hair_draw = rng.random::<f32>();
    let height_draw = rng.random::<f32>();
    let iris_draw = rng.random_range(0..4usize);
    let lip_red = uniform(rng, 0.0, 1.0);
    let skin_tone = params
        .skin_tone
        .map_or(tone_draw, |t| if t.is_finite() { t.clamp(0.0, 1.0) } else { 0.5 });
    let skin = skin_albedo(skin_tone);
    // Grey hair half as likely as the others.
    let weights = [2.0, 2.0, 2.0, 2.0, 2.0, 1.0];
    let total: f32 = weights.iter().sum();
    let mut pick = hair_draw * total;
    let mut hair = HairColour::Grey;
    for (colour, w) in HairColour::ALL.iter().zip(weights) {
        if pick < w {
            hair = *colour;
            break;
        }
        pick -= w;
    }
    let hair = params.hair.unwrap_or(hair);
    let iris_albedo = [
        [0.09, 0.045, 0.02],
        [0.03, 0.018, 0.012],
        [0.08, 0.13, 0.20],
        [0.08, 0.11, 0.05],
    ][iris_draw];
    // Lips: the skin, redder and a little darker.
    let lip_albedo = [
        skin[0] * (0.95 + 0.15 * lip_red),
        skin[1] * (0.62 - 0.1 * lip_red),
        skin[2] * (0.70 - 0.1 * lip_red),
    ];
    let height_m = params
        .height_m
        .filter(|h| h.is_finite() && *h > 0.0)
        .unwrap_or(0.19 + 0.05 * height_draw);
    HeadTraits {
        skin_tone,
        skin_albedo: skin,
        hair,
        hair_albedo: hair.albedo(),
        iris_albedo,
        lip_albedo,
        height_m,
    }
}

/// The appearance (skin tone, hair, height, …) that [`procedural_head`] gives
/// `seed` with `params`, without building the mesh.
pub fn head_traits(seed: u64, params: &HeadParams) -> HeadTraits {
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let _shape = HeadShape::random(&mut rng);
    draw_traits(&mut rng, params)
}

/// Builds a procedural head for `seed` (see the module docs): a watertight,
/// outward-wound triangle mesh with per-vertex albedo, +y up, facing +z, its
/// bounding box centred at the origin and its height [`HeadTraits::height_m`].
pub fn procedural_head(seed: u64, params: &HeadParams) -> Mesh {
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let shape = HeadShape::random(&mut rng);
    let traits = draw_traits(&mut rng, params);

    // Grid over the model-frame bounds, with two empty cells of margin.
    let top = shape.hair_c.y + shape.cranium_r.y + shape.hair_thickness;
    let bottom = shape.neck_bottom_y;
    let cells = params.cells_per_height.clamp(32, 512) as f32;
    let cell = (top - bottom) / cells;
    let margin = 2.0 * cell;
    let lo = Vec3::new(-10.5, bottom - margin, -12.5);
    let hi = Vec3::new(10.5, top + margin, 13.5);
    let dims = ((hi - lo) / cell).ceil().as_uvec3() + 1;
    let (nx, ny, nz) = (dims.x as usize, dims.y as usize, dims.z as usize);
    let mut field = vec![0.0f32; nx * ny * nz];
    field.par_chunks_mut(nx * ny).enumerate().for_each(|(z, slab)| {
        for y in 0..ny {
            for x in 0..nx {
                let p = lo + Vec3::new(x as f32, y as f32, z as f32) * cell;
                slab[y * nx + x] = shape.distance(p) / cell;
            }
        }
    });
    // Keep the outer layer outside so the surface is closed.
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                if x == 0 || y == 0 || z == 0 || x == nx - 1 || y == ny - 1 || z == nz - 1 {
                    let v = &mut field[(z * ny + y) * nx + x];
                    *v = v.max(1.0);
                }
            }
        }
    }
    fill_ambiguous_faces(&mut field, [nx, ny, nz]);
    let grid_shape = fast_surface_nets::ndshape::RuntimeShape::<u32, 3>::new([dims.x, dims.y, dims.z]);
    let mut buffer = fast_surface_nets::SurfaceNetsBuffer::default();
    fast_surface_nets::surface_nets(
        &field,
        &grid_shape,
        [0; 3],
        [dims.x - 1, dims.y - 1, dims.z - 1],
        &mut buffer,
    );

    let model: Vec<Vec3> = buffer
        .positions
        .iter()
        .map(|&[x, y, z]| lo + Vec3::new(x, y, z) * cell)
        .collect();
    let mut triangles: Vec<[u32; 3]> = buffer
        .indices
        .chunks_exact(3)
        .map(|t| [t[0], t[1], t[2]])
        .collect();
    // Orient along the field gradient (outward): flip if most triangles disagree.
    let agreeing = triangles
        .iter()
        .filter(|t| {
            let [a, b, c] = t.map(|i| model[i as usize]);
            let gradient: Vec3 = t.iter().map(|&i| Vec3::from(buffer.normals[i as usize])).sum();
            (b - a).cross(c - a).dot(gradient) > 0.0
        })
        .count();
    if 2 * agreeing < triangles.len() {
        for t in &mut triangles {
            t.swap(1, 2);
        }
    }
    let colours: Vec<[f32; 3]> = model.par_iter().map(|&p| shape.albedo(p, &traits)).collect();

    // Model cm → metres: scale to the height, centre the bounding box.
    let (mut min, mut max) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for &p in &model {
        min = min.min(p);
        max = max.max(p);
    }
    let scale = traits.height_m / (max.y - min.y).max(f32::MIN_POSITIVE);
    let centre = 0.5 * (min + max);
    let positions = model.iter().map(|&p| (p - centre) * scale).collect();
    Mesh {
        positions,
        triangles,
        albedo: Albedo::PerVertex(colours),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smooth_min_bounds() {
        assert_eq!(smin(1.0, 5.0, 0.5), 1.0);
        assert!(smin(1.0, 1.0, 0.5) < 1.0);
        assert_eq!(smax(1.0, 5.0, 0.5), 5.0);
    }

    #[test]
    fn primitives_are_signed() {
        let r = Vec3::new(1.0, 2.0, 3.0);
        assert!(ellipsoid(Vec3::ZERO, Vec3::ZERO, r) < 0.0);
        assert!(ellipsoid(Vec3::new(0.0, 2.0, 0.0), Vec3::ZERO, r).abs() < 1e-6);
        assert!(ellipsoid(Vec3::new(0.0, 0.0, 4.0), Vec3::ZERO, r) > 0.0);
        assert!((capsule(Vec3::new(0.5, 2.0, 0.0), Vec3::ZERO, Vec3::X, 1.0) - 1.0).abs() < 1e-6);
    }

    #[test]
    fn skin_tones_run_pale_to_dark() {
        let lum = |c: [f32; 3]| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
        let mut last = f32::INFINITY;
        for i in 0..=10 {
            let c = skin_albedo(i as f32 / 10.0);
            assert!(c[0] > c[1] && c[1] > c[2], "skin is red > green > blue");
            assert!(lum(c) < last);
            last = lum(c);
        }
    }

    #[test]
    fn head_contains_its_core_and_not_far_points() {
        let mut rng = Pcg64Mcg::seed_from_u64(3);
        let shape = HeadShape::random(&mut rng);
        assert!(shape.distance(Vec3::new(0.0, 2.0, -1.0)) < 0.0);
        assert!(shape.distance(Vec3::new(0.0, -12.0, -2.0)) < 0.0, "neck");
        assert!(shape.distance(Vec3::new(0.0, 20.0, 0.0)) > 0.0);
        assert!(shape.distance(Vec3::new(0.0, 0.0, 14.0)) > 0.0);
    }
}
