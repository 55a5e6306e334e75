//! Procedural environment maps for training diversity: seeded lat-long radiance
//! maps (linear RGB, arbitrary but consistent units: a sky of about 1) in three
//! families — outdoor (sky gradient, ground, sun disc of 0.5°–15° with
//! circumsolar glow, optional clouds), indoor (ceiling/wall/floor gradients with
//! 1–4 coloured rectangular area lights) and studio (dark backdrop with key, fill
//! and rim softboxes).
//!
//! Maps follow the project conventions ([`nelf_format::conventions`]): row 0 at
//! the zenith, the image centre looking along −z; "front" (where a head faces and
//! the frontal camera sits) is +z, azimuth φ = ±π.
//!
//! Emitters (sun, rectangles) are rasterised with their exact power: each texel
//! they may touch is split into sub-texels of equal solid angle (uniform in
//! `cos θ` and `φ`), the covered fraction is counted, and the sun's coverage is
//! renormalised so that `Σ Ω_texel · coverage = 2π(1 − cos α)`, the disc's solid
//! angle, however small the disc is against a texel.

use std::f64::consts::PI;

use glam::DVec3;
use nelf_format::conventions::{
    LatLong, direction, row_theta_bounds, texel_center_direction, texel_solid_angle,
};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;

/// The kind of lighting a procedural map imitates.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EnvFamily {
    /// Sky, ground and sun, maybe clouds.
    Outdoor,
    /// A room: ceiling, walls, floor and 1–4 rectangular lights.
    Indoor,
    /// A photo studio: dark backdrop, key, fill and rim softboxes.
    Studio,
}

impl EnvFamily {
    /// Every family.
    pub const ALL: [Self; 3] = [Self::Outdoor, Self::Indoor, Self::Studio];
}

/// Settings of the generator.
#[derive(Debug, Clone, PartialEq)]
pub struct EnvGenParams {
    /// Map width in texels (azimuth). Default 128.
    pub width: usize,
    /// Map height in texels (polar angle). Default 64.
    pub height: usize,
    /// Family to draw; `None`: chosen by the seed (each equally likely).
    pub family: Option<EnvFamily>,
}

impl Default for EnvGenParams {
    fn default() -> Self {
        Self {
            width: 128,
            height: 64,
            family: None,
        }
    }
}

/// The shape of an emitter, as seen from the centre of the map.
#[derive(Debug, Clone, PartialEq)]
pub enum EmitterShape {
    /// A disc of angular radius `half_angle_rad` around `centre` (unit).
    Disc {
        /// Unit direction to the disc's centre.
        centre: DVec3,
        /// Angular radius, radians.
        half_angle_rad: f64,
    },
    /// A rectangle facing the centre at unit distance along `centre`, spanning
    /// `±half_width` along `right` and `±half_height` along `up` (unit, orthogonal).
    Rectangle {
        /// Unit direction to the rectangle's centre.
        centre: DVec3,
        /// Unit in-plane axis of the width.
        right: DVec3,
        /// Unit in-plane axis of the height.
        up: DVec3,
        /// Half width at unit distance (tangent of the half angle).
        half_width: f64,
        /// Half height at unit distance.
        half_height: f64,
    },
}

impl EmitterShape {
    /// Whether direction `d` (unit) sees the emitter.
    pub fn contains(&self, d: DVec3) -> bool {
        match self {
            Self::Disc {
                centre,
                half_angle_rad,
            } => d.dot(*centre) >= half_angle_rad.cos(),
            Self::Rectangle {
                centre,
                right,
                up,
                half_width,
                half_height,
            } => {
                let along = d.dot(*centre);
                if along <= 1e-9 {
                    return false;
                }
                let hit = d / along;
                hit.dot(*right).abs() <= *half_width && hit.dot(*up).abs() <= *half_height
            }
        }
    }

    /// Unit direction to the emitter's centre.
    pub fn centre(&self) -> DVec3 {
        match self {
            Self::Disc { centre, .. } | Self::Rectangle { centre, .. } => *centre,
        }
    }

    /// Angle (radians) from the centre that bounds the emitter.
    fn bounding_angle(&self) -> f64 {
        match self {
            Self::Disc { half_angle_rad, .. } => *half_angle_rad,
            Self::Rectangle {
                half_width,
                half_height,
                ..
            } => half_width.hypot(*half_height).atan(),
        }
    }
}

/// A light source in a procedural map: a shape of constant radiance.
#[derive(Debug, Clone, PartialEq)]
pub struct Emitter {
    /// Where it is.
    pub shape: EmitterShape,
    /// Its radiance, linear RGB.
    pub radiance: [f32; 3],
}

/// A procedural map with a description of what is in it.
#[derive(Debug, Clone, PartialEq)]
pub struct ProceduralEnv {
    /// The map.
    pub map: LatLong,
    /// Its family.
    pub family: EnvFamily,
    /// Unit direction to the sun (outdoor maps only).
    pub sun_direction: Option<DVec3>,
    /// The emitters added on top of the background (sun, area lights, softboxes).
    pub emitters: Vec<Emitter>,
}

/// The built-in map of `family`: its procedural map at seed 1. `nelf view`'s picker
/// offers one per family ([`builtin_envmaps`]); `nelf export` lights with the studio one.
pub fn builtin_envmap(family: EnvFamily) -> LatLong {
    procedural_envmap(
        1,
        &EnvGenParams {
            family: Some(family),
            ..EnvGenParams::default()
        },
    )
}

/// The built-in maps, studio, outdoor and indoor ([`builtin_envmap`]), each with the
/// name the viewer's picker shows ("studio (procedural)", …).
pub fn builtin_envmaps() -> Vec<(String, LatLong)> {
    [
        ("studio (procedural)", EnvFamily::Studio),
        ("outdoor (procedural)", EnvFamily::Outdoor),
        ("indoor (procedural)", EnvFamily::Indoor),
    ]
    .into_iter()
    .map(|(name, family)| (name.to_string(), builtin_envmap(family)))
    .collect()
}

/// A procedural environment map for `seed` ([`procedural_env`]'s map).
pub fn procedural_envmap(seed: u64, params: &EnvGenParams) -> LatLong {
    procedural_env(seed, params).map
}

/// A procedural environment map for `seed`, with its description. Deterministic:
/// the same seed and parameters give the same map, bit for bit. Every texel is
/// finite and non-negative.
pub fn procedural_env(seed: u64, params: &EnvGenParams) -> ProceduralEnv {
    let width = params.width.clamp(4, 8192);
    let height = params.height.clamp(2, 4096);
    let mut rng = Pcg64Mcg::seed_from_u64(seed ^ 0x5eed_e4f1_0000_0000);
    let drawn = EnvFamily::ALL[rng.random_range(0..EnvFamily::ALL.len())];
    let family = params.family.unwrap_or(drawn);
    let (background, emitters, sun_direction) = match family {
        EnvFamily::Outdoor => outdoor(&mut rng),
        EnvFamily::Indoor => indoor(&mut rng),
        EnvFamily::Studio => studio(&mut rng),
    };
    let mut texels = Vec::with_capacity(width * height);
    for row in 0..height {
        for col in 0..width {
            let d = texel_center_direction(row, col, height, width);
            texels.push(background.radiance(d));
        }
    }
    for emitter in &emitters {
        splat_emitter(&mut texels, width, height, emitter);
    }
    for texel in &mut texels {
        *texel = texel.map(|v| if v.is_finite() && v > 0.0 { v } else { 0.0 });
    }
    let map =
        LatLong::new(width, height, texels).unwrap_or_else(|_| LatLong::constant(width, height, [0.0; 3]));
    ProceduralEnv {
        map,
        family,
        sun_direction,
        emitters,
    }
}

/// Adds `emitter` to `map` (world frame): its radiance × the covered fraction of
/// every texel it touches (16 × 16 sub-texel points); a disc carries exactly its
/// radiance × its solid angle `2π(1 − cos α)`, however small (one smaller than a
/// sub-texel lands whole in the texel holding its centre).
pub fn add_emitter(map: &mut LatLong, emitter: &Emitter) {
    let (width, height) = (map.width(), map.height());
    splat_emitter(map.texels_mut(), width, height, emitter);
}

/// Adds an emitter's radiance × covered fraction to every texel it touches.
fn splat_emitter(texels: &mut [[f32; 3]], width: usize, height: usize, emitter: &Emitter) {
    const SUB: usize = 16;
    let centre = emitter.shape.centre();
    let reach = emitter.shape.bounding_angle();
    let dphi = 2.0 * PI / width as f64;
    let mut coverage = Vec::new();
    for row in 0..height {
        let (t0, t1) = row_theta_bounds(row, height);
        let sin_max = if t0 <= PI / 2.0 && t1 >= PI / 2.0 {
            1.0
        } else {
            t0.sin().max(t1.sin())
        };
        let texel_radius = 0.5 * (t1 - t0).hypot(dphi * sin_max) + 1e-9;
        let omega = texel_solid_angle(row, height, width);
        for col in 0..width {
            let d = texel_center_direction(row, col, height, width);
            if d.dot(centre).clamp(-1.0, 1.0).acos() > reach + texel_radius {
                continue;
            }
            let (u0, u1) = (t0.cos(), t1.cos());
            let phi0 = col as f64 * dphi - PI;
            let mut hits = 0usize;
            for a in 0..SUB {
                let theta = (u0 + (u1 - u0) * (a as f64 + 0.5) / SUB as f64)
                    .clamp(-1.0, 1.0)
                    .acos();
                for b in 0..SUB {
                    let phi = phi0 + dphi * (b as f64 + 0.5) / SUB as f64;
                    if emitter.shape.contains(direction(theta, phi)) {
                        hits += 1;
                    }
                }
            }
            if hits > 0 {
                coverage.push((row * width + col, hits as f64 / (SUB * SUB) as f64, omega));
            }
        }
    }
    // Discs get their exact solid angle; a disc smaller than a sub-texel still
    // lands in the texel holding its centre.
    let scale = match emitter.shape {
        EmitterShape::Disc { half_angle_rad, .. } => {
            let exact = 2.0 * PI * (1.0 - half_angle_rad.cos());
            let covered: f64 = coverage.iter().map(|&(_, f, omega)| f * omega).sum();
            if covered > 0.0 {
                exact / covered
            } else {
                let (row, col) = nelf_format::conventions::texel_of_direction(centre, height, width);
                coverage.push((row * width + col, 1.0, texel_solid_angle(row, height, width)));
                exact / texel_solid_angle(row, height, width)
            }
        }
        EmitterShape::Rectangle { .. } => 1.0,
    };
    for (index, fraction, _) in coverage {
        let weight = (fraction * scale) as f32;
        for (value, radiance) in texels[index].iter_mut().zip(emitter.radiance) {
            *value += radiance * weight;
        }
    }
}

/// The smooth part of a map (sky, room, backdrop), evaluated per texel centre.
#[derive(Debug, Clone)]
enum Background {
    Outdoor {
        zenith: [f32; 3],
        horizon: [f32; 3],
        ground: [f32; 3],
        sun: DVec3,
        glow: [f32; 3],
        cloud_cover: f32,
        cloud_colour: [f32; 3],
        noise: ValueNoise,
    },
    Room {
        ceiling: [f32; 3],
        walls: [f32; 3],
        floor: [f32; 3],
        bright_wall_azimuth: f64,
        bright_wall_gain: f32,
    },
}

/// Linear interpolation of RGB triples.
fn mix(a: [f32; 3], b: [f32; 3], t: f32) -> [f32; 3] {
    std::array::from_fn(|c| a[c] + (b[c] - a[c]) * t)
}

/// Hermite smooth step of `x` from `e0` to `e1`.
fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

impl Background {
    fn radiance(&self, d: DVec3) -> [f32; 3] {
        match self {
            Self::Outdoor {
                zenith,
                horizon,
                ground,
                sun,
                glow,
                cloud_cover,
                cloud_colour,
                noise,
            } => {
                let elevation = d.y as f32;
                if elevation < 0.0 {
                    // Ground, fading into a hazy horizon over the first few degrees.
                    return mix(*horizon, *ground, smoothstep(0.0, 0.08, -elevation));
                }
                let mut sky = mix(*horizon, *zenith, elevation.sqrt());
                let angle = d.dot(*sun).clamp(-1.0, 1.0).acos() as f32;
                let circumsolar = (-angle / 0.25).exp() + 0.25 * (-angle / 1.0).exp();
                for c in 0..3 {
                    sky[c] += glow[c] * circumsolar;
                }
                if *cloud_cover > 0.0 {
                    // Clouds: low-frequency noise on a dome, thinning at the horizon.
                    let n = noise.fbm(d * 2.5);
                    let threshold = 1.0 - cloud_cover;
                    let density =
                        smoothstep(threshold - 0.08, threshold + 0.12, n) * smoothstep(0.0, 0.15, elevation);
                    sky = mix(sky, *cloud_colour, density);
                }
                sky
            }
            Self::Room {
                ceiling,
                walls,
                floor,
                bright_wall_azimuth,
                bright_wall_gain,
            } => {
                let y = d.y as f32;
                let base = if y >= 0.0 {
                    mix(*walls, *ceiling, smoothstep(0.2, 0.8, y))
                } else {
                    mix(*walls, *floor, smoothstep(0.0, 0.4, -y))
                };
                let phi = d.x.atan2(-d.z);
                let facing = (0.5 + 0.5 * (phi - bright_wall_azimuth).cos()) as f32;
                let gain = 1.0 + bright_wall_gain * facing * (1.0 - y.abs());
                base.map(|v| v * gain)
            }
        }
    }
}

/// Seeded 3D value noise (trilinear with a smooth fade), in `[0, 1]`.
#[derive(Debug, Clone)]
struct ValueNoise {
    seed: u64,
}

impl ValueNoise {
    /// Lattice value at integer point (`SplitMix64` finaliser of the coordinates).
    fn lattice(&self, x: i64, y: i64, z: i64) -> f32 {
        let mut h = self.seed
            ^ (x as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)
            ^ (y as u64).wrapping_mul(0xc2b2_ae3d_27d4_eb4f)
            ^ (z as u64).wrapping_mul(0x1656_67b1_9e37_79f9);
        h ^= h >> 30;
        h = h.wrapping_mul(0xbf58_476d_1ce4_e5b9);
        h ^= h >> 27;
        h = h.wrapping_mul(0x94d0_49bb_1331_11eb);
        h ^= h >> 31;
        (h >> 40) as f32 / (1u64 << 24) as f32
    }

    fn value(&self, p: DVec3) -> f32 {
        let base = p.floor();
        let f = p - base;
        let fade = |t: f64| (t * t * (3.0 - 2.0 * t)) as f32;
        let (u, v, w) = (fade(f.x), fade(f.y), fade(f.z));
        let (x, y, z) = (base.x as i64, base.y as i64, base.z as i64);
        let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
        let c = |dx, dy, dz| self.lattice(x + dx, y + dy, z + dz);
        lerp(
            lerp(
                lerp(c(0, 0, 0), c(1, 0, 0), u),
                lerp(c(0, 1, 0), c(1, 1, 0), u),
                v,
            ),
            lerp(
                lerp(c(0, 0, 1), c(1, 0, 1), u),
                lerp(c(0, 1, 1), c(1, 1, 1), u),
                v,
            ),
            w,
        )
    }

    /// Four octaves of fractal noise, normalised to `[0, 1]`.
    fn fbm(&self, p: DVec3) -> f32 {
        let mut sum = 0.0;
        let mut amplitude = 0.5;
        let mut frequency = 1.0;
        let mut total = 0.0;
        for _ in 0..4 {
            sum += amplitude * self.value(p * frequency);
            total += amplitude;
            amplitude *= 0.5;
            frequency *= 2.03;
        }
        sum / total
    }
}

/// Uniform draw in `[lo, hi)`.
fn uniform(rng: &mut Pcg64Mcg, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * rng.random::<f64>()
}

/// Direction at `elevation` above the horizon and azimuth `phi` (our convention).
fn at_elevation(elevation: f64, phi: f64) -> DVec3 {
    direction(PI / 2.0 - elevation, phi)
}

/// A colour of correlated temperature between candle-warm and overcast-cool,
/// `t ∈ [0, 1]` (0 warm), normalised to luminance 1.
fn white_balance(t: f64) -> [f32; 3] {
    let warm = [1.0f32, 0.72, 0.45];
    let cool = [0.78f32, 0.88, 1.0];
    let c = mix(warm, cool, t as f32);
    let luminance = 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
    c.map(|v| v / luminance)
}

/// Scales a colour of luminance 1 to radiance whose emitter has `power`
/// (`radiance × solid angle`) over `solid_angle`.
fn radiance_for_power(colour: [f32; 3], power: f64, solid_angle: f64) -> [f32; 3] {
    colour.map(|c| (f64::from(c) * power / solid_angle.max(1e-12)) as f32)
}

/// Solid angle of a rectangle at unit distance with half sides `a`, `b`:
/// `4 · atan(a·b / √(1 + a² + b²))`.
fn rectangle_solid_angle(a: f64, b: f64) -> f64 {
    4.0 * (a * b / (1.0 + a * a + b * b).sqrt()).atan()
}

/// A rectangle facing the centre from `centre`, `right` kept horizontal.
fn rectangle(centre: DVec3, half_width: f64, half_height: f64, tilt: f64) -> EmitterShape {
    let centre = centre.normalize();
    let horizontal = if centre.cross(DVec3::Y).length() > 1e-6 {
        DVec3::Y
    } else {
        DVec3::Z
    };
    let right0 = horizontal.cross(centre).normalize();
    let up0 = centre.cross(right0);
    let (s, c) = tilt.sin_cos();
    EmitterShape::Rectangle {
        centre,
        right: right0 * c + up0 * s,
        up: up0 * c - right0 * s,
        half_width,
        half_height,
    }
}

type Scene = (Background, Vec<Emitter>, Option<DVec3>);

/// Outdoor: sky gradient, ground, sun of 0.5°–15° diameter, optional clouds.
fn outdoor(rng: &mut Pcg64Mcg) -> Scene {
    let elevation = uniform(rng, 5.0, 75.0).to_radians();
    let azimuth = uniform(rng, -PI, PI);
    let sun = at_elevation(elevation, azimuth);
    // Log-uniform angular diameter, 0.5°–15°.
    let diameter = (0.5f64.ln() + rng.random::<f64>() * (15.0f64.ln() - 0.5f64.ln())).exp();
    let half_angle = (0.5 * diameter).to_radians();
    let sky_level = uniform(rng, 0.3, 1.2) as f32;
    let sun_power = uniform(rng, 1.5, 12.0);
    // Low suns are warmer.
    let sun_colour = white_balance((elevation / 75f64.to_radians()).clamp(0.0, 1.0) * 0.6 + 0.2);
    let blue = uniform(rng, 0.5, 1.0) as f32;
    let zenith = [0.25 * blue + 0.2 * (1.0 - blue), 0.42, 0.9].map(|v| v * sky_level);
    let horizon = [0.78, 0.82, 0.88].map(|v| v * sky_level * 1.1);
    let ground_albedo = [
        uniform(rng, 0.08, 0.3) as f32,
        uniform(rng, 0.08, 0.28) as f32,
        uniform(rng, 0.05, 0.2) as f32,
    ];
    let illumination = f64::from(sky_level) + sun_power * elevation.sin() / PI;
    let ground = ground_albedo.map(|a| a * illumination as f32);
    let glow = sun_colour.map(|c| c * sky_level * uniform(rng, 0.2, 0.8) as f32);
    let cloud_cover = if rng.random::<f64>() < 0.5 {
        0.0
    } else {
        uniform(rng, 0.1, 0.7) as f32
    };
    let cloud_colour = [0.85f32, 0.86, 0.88].map(|v| v * sky_level * uniform(rng, 0.8, 1.6) as f32);
    let noise = ValueNoise { seed: rng.random() };
    let disc = EmitterShape::Disc {
        centre: sun,
        half_angle_rad: half_angle,
    };
    let solid_angle = 2.0 * PI * (1.0 - half_angle.cos());
    let emitters = vec![Emitter {
        shape: disc,
        radiance: radiance_for_power(sun_colour, sun_power, solid_angle),
    }];
    let background = Background::Outdoor {
        zenith,
        horizon,
        ground,
        sun,
        glow,
        cloud_cover,
        cloud_colour,
        noise,
    };
    (background, emitters, Some(sun))
}

/// Indoor: warm or cool room gradients and 1–4 coloured rectangular lights.
fn indoor(rng: &mut Pcg64Mcg) -> Scene {
    let room = white_balance(rng.random::<f64>());
    let level = uniform(rng, 0.05, 0.35) as f32;
    let ceiling = room.map(|v| v * level * uniform(rng, 0.8, 1.5) as f32);
    let walls = room.map(|v| v * level);
    let floor = room.map(|v| v * level * uniform(rng, 0.3, 0.8) as f32);
    let background = Background::Room {
        ceiling,
        walls,
        floor,
        bright_wall_azimuth: uniform(rng, -PI, PI),
        bright_wall_gain: uniform(rng, 0.0, 1.5) as f32,
    };
    let count = rng.random_range(1..=4usize);
    let mut emitters = Vec::with_capacity(count);
    for _ in 0..count {
        let centre = at_elevation(uniform(rng, 10.0, 85.0).to_radians(), uniform(rng, -PI, PI));
        let (a, b) = (uniform(rng, 0.08, 0.45), uniform(rng, 0.08, 0.45));
        let shape = rectangle(centre, a, b, uniform(rng, -0.5, 0.5));
        // Colour: a white balance, sometimes tinted by a saturated hue.
        let mut colour = white_balance(rng.random::<f64>());
        if rng.random::<f64>() < 0.4 {
            let hue = [
                uniform(rng, 0.2, 1.0) as f32,
                uniform(rng, 0.2, 1.0) as f32,
                uniform(rng, 0.2, 1.0) as f32,
            ];
            let luminance = 0.2126 * hue[0] + 0.7152 * hue[1] + 0.0722 * hue[2];
            colour = hue.map(|v| v / luminance);
        }
        let power = uniform(rng, 0.5, 6.0);
        emitters.push(Emitter {
            shape,
            radiance: radiance_for_power(colour, power, rectangle_solid_angle(a, b)),
        });
    }
    (background, emitters, None)
}

/// Studio: dark backdrop; key softbox in front and to one side, a dimmer fill on
/// the other side, a narrow rim light behind.
fn studio(rng: &mut Pcg64Mcg) -> Scene {
    let grey = uniform(rng, 0.01, 0.06) as f32;
    let backdrop = [grey; 3];
    let background = Background::Room {
        ceiling: backdrop.map(|v| v * 1.3),
        walls: backdrop,
        floor: backdrop.map(|v| v * 0.6),
        bright_wall_azimuth: 0.0,
        bright_wall_gain: uniform(rng, 0.0, 1.0) as f32,
    };
    // Front (+z) is azimuth π; the key sits 20°–60° to one side of it.
    let side = if rng.random::<bool>() { 1.0 } else { -1.0 };
    let key_azimuth = PI + side * uniform(rng, 20.0, 60.0).to_radians();
    let fill_azimuth = PI - side * uniform(rng, 30.0, 80.0).to_radians();
    let rim_azimuth = side * uniform(rng, -40.0, 40.0).to_radians();
    let key_power = uniform(rng, 3.0, 10.0);
    let warmth = uniform(rng, 0.3, 0.8);
    let specs = [
        (
            at_elevation(uniform(rng, 15.0, 45.0).to_radians(), key_azimuth),
            uniform(rng, 0.3, 0.6),
            uniform(rng, 0.3, 0.6),
            key_power,
            warmth,
        ),
        (
            at_elevation(uniform(rng, 0.0, 25.0).to_radians(), fill_azimuth),
            uniform(rng, 0.3, 0.7),
            uniform(rng, 0.3, 0.7),
            key_power * uniform(rng, 0.15, 0.5),
            (warmth + uniform(rng, -0.2, 0.2)).clamp(0.0, 1.0),
        ),
        (
            at_elevation(uniform(rng, 10.0, 50.0).to_radians(), rim_azimuth),
            uniform(rng, 0.06, 0.15),
            uniform(rng, 0.4, 0.8),
            key_power * uniform(rng, 0.3, 1.0),
            (warmth + uniform(rng, -0.3, 0.3)).clamp(0.0, 1.0),
        ),
    ];
    let emitters = specs
        .iter()
        .map(|&(centre, a, b, power, white)| Emitter {
            shape: rectangle(centre, a, b, 0.0),
            radiance: radiance_for_power(white_balance(white), power, rectangle_solid_angle(a, b)),
        })
        .collect();
    (background, emitters, None)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rectangle_solid_angle_matches_coverage() {
        // A square of half side 0.4 rasterised on a fine map has its analytic solid angle.
        let shape = rectangle(DVec3::new(0.3, 0.5, -0.8), 0.4, 0.25, 0.3);
        let mut texels = vec![[0.0f32; 3]; 256 * 128];
        splat_emitter(
            &mut texels,
            256,
            128,
            &Emitter {
                shape,
                radiance: [1.0; 3],
            },
        );
        let map = LatLong::new(256, 128, texels).unwrap();
        let want = rectangle_solid_angle(0.4, 0.25);
        assert!(
            (map.integral()[0] - want).abs() < 2e-3 * want,
            "{:?} vs {want}",
            map.integral()
        );
    }

    #[test]
    fn tiny_sun_keeps_its_power() {
        let half = 0.25f64.to_radians();
        let solid = 2.0 * PI * (1.0 - half.cos());
        let mut texels = vec![[0.0f32; 3]; 64 * 32];
        splat_emitter(
            &mut texels,
            64,
            32,
            &Emitter {
                shape: EmitterShape::Disc {
                    centre: at_elevation(0.4, 1.0),
                    half_angle_rad: half,
                },
                radiance: [(1.0 / solid) as f32; 3],
            },
        );
        let map = LatLong::new(64, 32, texels).unwrap();
        assert!((map.integral()[1] - 1.0).abs() < 1e-4, "{:?}", map.integral());
    }

    #[test]
    fn noise_is_in_unit_range_and_seeded() {
        let a = ValueNoise { seed: 1 };
        let b = ValueNoise { seed: 2 };
        let mut differ = false;
        for i in 0..200 {
            let p = DVec3::new(i as f64 * 0.37, i as f64 * 0.11, -(i as f64) * 0.23);
            let v = a.fbm(p);
            assert!((0.0..=1.0).contains(&v));
            differ |= (v - b.fbm(p)).abs() > 1e-3;
        }
        assert!(differ);
    }
}
