//! Shared by the export tests: a small synthetic asset and the values each grid must
//! hold, computed from the asset directly (not through the exporter).
#![allow(dead_code, clippy::unwrap_used)]

use std::collections::BTreeMap;

use nelf_export::Lighting;
use nelf_format::conventions::{ENV_H, ENV_W, LatLong};
use nelf_format::synthetic::SyntheticField;
use nelf_format::{Asset, CoefficientEncoding, Coefficients};

/// A synthetic asset of a few dozen bricks, PCA rank 5, 8-bit coefficients.
pub fn asset() -> Asset {
    let field = SyntheticField::new(12_000, 11);
    let pca = field.fit_pca(5, 400);
    let coefficients =
        Coefficients::quantize(&field.project(&pca), 5, CoefficientEncoding::U8Affine).unwrap();
    field.asset_with(pca, coefficients).unwrap()
}

/// A coloured, direction-dependent lighting (a sky brighter towards +y, warm towards +x).
pub fn lighting() -> Lighting {
    let (w, h) = (32, 16);
    let texels = (0..w * h)
        .map(|i| {
            let (row, col) = (i / w, i % w);
            let up = 1.0 - row as f32 / h as f32;
            [0.2 + up + 0.05 * col as f32, 0.3 + up, 0.1 + 0.5 * up]
        })
        .collect();
    Lighting::world(LatLong::new(w, h, texels).unwrap(), 25.0, "test sky")
}

/// White light of radiance 1 from everywhere (8 × 16).
pub fn white() -> Lighting {
    Lighting::world(LatLong::constant(ENV_W, ENV_H, [1.0; 3]), 0.0, "white")
}

/// OpenVDB index coordinate of asset voxel `v`.
pub fn index_of(asset: &Asset, v: usize) -> [i32; 3] {
    let (brick, local) = asset.voxel_location(v);
    std::array::from_fn(|a| 8 * i32::from(brick[a]) + local[a] as i32)
}

/// The expected active values of every grid, by index coordinate: density (σ / scale),
/// colour (nelf-render's relit voxel radiance at `rank`), `pca_k`.
pub struct Expected {
    pub density: BTreeMap<[i32; 3], f32>,
    pub color: BTreeMap<[i32; 3], [f32; 3]>,
    pub pca: Vec<BTreeMap<[i32; 3], f32>>,
}

pub fn expected(asset: &Asset, lighting: &Lighting, rank: usize, scale: f64) -> Expected {
    let light = match lighting {
        Lighting::World {
            env, world_from_env, ..
        } => nelf_render::project_light(&asset.pca, asset.world_from_light, env, *world_from_env).unwrap(),
        Lighting::LightFrame { texels, .. } => nelf_render::project_light_texels(&asset.pca, texels).unwrap(),
    };
    let radiance = nelf_render::voxel_radiance(asset, &light, Some(rank));
    let mut out = Expected {
        density: BTreeMap::new(),
        color: BTreeMap::new(),
        pca: vec![BTreeMap::new(); rank],
    };
    let mut c = vec![0.0; asset.rank()];
    for (v, rgb) in radiance.iter().enumerate() {
        let ijk = index_of(asset, v);
        out.density
            .insert(ijk, (f64::from(asset.density[v].to_f32()) / scale) as f32);
        out.color.insert(ijk, *rgb);
        asset.coefficients.voxel_f32(v, &mut c);
        for (grid, value) in out.pca.iter_mut().zip(&c) {
            grid.insert(ijk, *value);
        }
    }
    assert_eq!(radiance.len(), asset.voxel_count());
    out
}

/// `asset` with a fine density of factor `factor` (format 1.4) that differs from the
/// coarse density upsampled: fine voxel `(i, j, k)` of brick `b` holds the σ of the voxel
/// containing it plus `(i + 2j + 3k + b) mod 5 · 0.25 − 0.5` (so the `F³` fine voxels of
/// one voxel differ from each other and from it, some negative), σ in 1/m.
pub fn with_fine_density(mut asset: Asset, factor: u32) -> Asset {
    let f = factor as usize;
    let edge = 8 * f;
    let mut sigma = Vec::with_capacity(asset.bricks.len() * edge * edge * edge);
    for b in 0..asset.bricks.len() {
        for k in 0..edge {
            for j in 0..edge {
                for i in 0..edge {
                    let coarse = asset.density[b * 512 + i / f + 8 * (j / f) + 64 * (k / f)].to_f32();
                    let delta = ((i + 2 * j + 3 * k + b) % 5) as f32 * 0.25 - 0.5;
                    sigma.push(coarse + delta);
                }
            }
        }
    }
    asset.fine_density = Some(nelf_format::FineDensity {
        factor,
        values: nelf_format::encode_density(&sigma).unwrap(),
    });
    asset.validate().unwrap();
    asset
}

/// The density grid a fine density must give, by OpenVDB index coordinate (`8F·brick +
/// (i, j, k)`): the stored fine σ divided by `scale`.
pub fn expected_fine_density(asset: &Asset, scale: f64) -> BTreeMap<[i32; 3], f32> {
    let fine = asset.fine_density.as_ref().unwrap();
    let edge = 8 * fine.factor as usize;
    let mut out = BTreeMap::new();
    for (v, sigma) in fine.values.iter().enumerate() {
        let (b, local) = (v / edge.pow(3), v % edge.pow(3));
        let ijk = [local % edge, (local / edge) % edge, local / (edge * edge)];
        let index = std::array::from_fn(|a| edge as i32 * i32::from(asset.bricks[b][a]) + ijk[a] as i32);
        out.insert(index, (f64::from(sigma.to_f32()) / scale) as f32);
    }
    out
}

/// Where SPEC.md §6 centres fine voxel `(i, j, k)` of brick `brick`, in scene units:
/// `scale · (bbox_min + (8F·brick + (i, j, k) + ½) · Δ/F)`.
pub fn fine_voxel_centre(asset: &Asset, brick: [u16; 3], ijk: [usize; 3], scale: f64) -> [f64; 3] {
    let f = f64::from(asset.fine_density.as_ref().unwrap().factor);
    let fine_voxel = asset.grid.voxel_size_m / f;
    std::array::from_fn(|a| {
        scale
            * (asset.grid.bbox_min_m[a] + (8.0 * f * f64::from(brick[a]) + ijk[a] as f64 + 0.5) * fine_voxel)
    })
}
