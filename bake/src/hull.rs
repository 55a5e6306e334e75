//! The visual hull of a capture's masks (Laurentini 1994), carved on voxels, as NeLF
//! prunes its queries to the region every mask allows.
//!
//! **Test of one axis-aligned box** (a voxel) against one view: its 8 corners are
//! projected; the box's image lies inside the bounding rectangle of those points
//! (a convex body in front of a pinhole projects into the convex hull of its
//! corners' projections). The rectangle is widened to whole pixels (every pixel
//! whose square `[x, x+1] × [y, y+1]` touches it), grown by `dilate_px` pixels on
//! every side and clipped to the image; the box is kept for that view iff some
//! pixel in it is foreground (mask > 0.5). A summed-area table makes every test
//! O(1). Growing the rectangle by `r` is the same as dilating the mask by a
//! `(2r + 1)²` square (a superset of a disc of radius `r`).
//!
//! * A box with a corner at or behind the camera plane has no bounded image: it is
//!   **kept** for that view (the other views decide).
//! * Pixels outside the image count as **background**: a box whose rectangle lies
//!   entirely outside the frame is carved, one partly outside is kept only if the
//!   part inside overlaps the mask. The subject must therefore be inside every
//!   frame; whatever leaves a frame (a neck cut by the bottom edge) is cut there.
//!
//! **Conservative at voxel scale**: a box is carved only if, in some view, no mask
//! pixel lies within `dilate_px` pixels (Chebyshev) of its projection. So every
//! voxel that touches the subject is kept, provided every point of the subject
//! projects within `dilate_px` of a foreground pixel in every view — true for
//! correct masks with `dilate_px ≥ 1` (a pixel a silhouette covers by less than
//! half borders one it covers by more, except at sub-pixel features). The hull
//! kept is the exact visual hull grown by up to one voxel's footprint plus
//! `dilate_px + 1` pixels in each view.
//!
//! **Bounds**: [`hull_bounds`] finds the hull's box coarse-to-fine: carve a cube
//! around the head centre at 32³, grow the cube while kept voxels touch its
//! faces, then carve the kept box again at 64³. Both passes are conservative, so
//! the box returned contains the hull. Few or alike views (two views 30° apart)
//! leave a hull that runs off along their rays; the cube stops growing at a
//! half-size of `max_radius_m` around the head centre, and the hull is clipped there,
//! as NeLF bounds every ray by a sphere around the head (`--max-hull-radius-m`).

use glam::DVec3;
use nelf_format::conventions::PinholeCamera;
use rayon::prelude::*;

use crate::error::{BakeError, Result};

/// Whether a mask value is foreground: the one threshold of the hull and of the
/// network's carve ([`crate::silhouette`]).
pub(crate) fn is_foreground(value: f32) -> bool {
    value > 0.5
}

/// Checks that `mask` holds `width × height` values of a non-empty image.
pub(crate) fn check_mask_size(mask: &[f32], width: usize, height: usize) -> Result<()> {
    if mask.len() != width * height || width == 0 || height == 0 {
        return Err(BakeError::Hull(format!(
            "a {width}×{height} mask needs {} values, got {}",
            width * height,
            mask.len()
        )));
    }
    Ok(())
}

/// Checks that there is one mask per camera, and at least one camera.
pub(crate) fn check_mask_count(cameras: &[PinholeCamera], masks: &[Vec<f32>]) -> Result<()> {
    if cameras.len() != masks.len() || cameras.is_empty() {
        return Err(BakeError::Hull(format!(
            "{} cameras and {} masks: a hull needs one mask per camera",
            cameras.len(),
            masks.len()
        )));
    }
    Ok(())
}

/// Summed-area table of a binary mask (foreground: [`is_foreground`]).
#[derive(Debug, Clone)]
pub struct MaskTable {
    width: usize,
    height: usize,
    /// `(width + 1) × (height + 1)` prefix counts; entry `(x, y)` counts foreground
    /// pixels in `[0, x) × [0, y)`.
    sums: Vec<u32>,
}

impl MaskTable {
    /// Builds the table of `mask` (`width × height`, row-major, values in `[0, 1]`).
    pub fn new(mask: &[f32], width: usize, height: usize) -> Result<Self> {
        check_mask_size(mask, width, height)?;
        let stride = width + 1;
        let mut sums = vec![0u32; stride * (height + 1)];
        for y in 0..height {
            let mut row = 0u32;
            for x in 0..width {
                row += u32::from(is_foreground(mask[y * width + x]));
                sums[(y + 1) * stride + x + 1] = sums[y * stride + x + 1] + row;
            }
        }
        Ok(Self { width, height, sums })
    }

    /// Image width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Image height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// Foreground pixels in columns `x0..=x1`, rows `y0..=y1` (clipped to the image).
    pub fn count(&self, x0: i64, y0: i64, x1: i64, y1: i64) -> u32 {
        let clip = |v: i64, n: usize| v.clamp(0, n as i64) as usize;
        let (x0, x1) = (clip(x0, self.width), clip(x1.saturating_add(1), self.width));
        let (y0, y1) = (clip(y0, self.height), clip(y1.saturating_add(1), self.height));
        if x0 >= x1 || y0 >= y1 {
            return 0;
        }
        let s = self.width + 1;
        let at = |x: usize, y: usize| i64::from(self.sums[y * s + x]);
        (at(x1, y1) - at(x0, y1) - at(x1, y0) + at(x0, y0)) as u32
    }
}

/// Conservative box-against-masks test for a set of views (see the module docs).
#[derive(Debug, Clone)]
pub struct HullCarver {
    cameras: Vec<PinholeCamera>,
    tables: Vec<MaskTable>,
    dilate_px: u32,
}

impl HullCarver {
    /// A carver for `cameras` and their masks (each `width × height` of its camera).
    pub fn new(cameras: &[PinholeCamera], masks: &[Vec<f32>], dilate_px: u32) -> Result<Self> {
        check_mask_count(cameras, masks)?;
        let tables = cameras
            .iter()
            .zip(masks)
            .map(|(c, m)| MaskTable::new(m, c.width as usize, c.height as usize))
            .collect::<Result<Vec<_>>>()?;
        Ok(Self {
            cameras: cameras.to_vec(),
            tables,
            dilate_px,
        })
    }

    /// The cameras.
    pub fn cameras(&self) -> &[PinholeCamera] {
        &self.cameras
    }

    /// Whether the box `[min, max]` may touch the subject in view `view`.
    pub fn keeps_box_in_view(&self, view: usize, min: DVec3, max: DVec3) -> bool {
        let cam = &self.cameras[view];
        let (mut u0, mut v0, mut u1, mut v1) =
            (f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY);
        for corner in 0..8 {
            let p = DVec3::new(
                if corner & 1 == 0 { min.x } else { max.x },
                if corner & 2 == 0 { min.y } else { max.y },
                if corner & 4 == 0 { min.z } else { max.z },
            );
            let q = cam.camera_from_world(p);
            if q.z <= 0.0 || q.z.is_nan() {
                return true;
            }
            let (u, v) = (cam.fx * q.x / q.z + cam.cx, cam.fy * q.y / q.z + cam.cy);
            u0 = u0.min(u);
            u1 = u1.max(u);
            v0 = v0.min(v);
            v1 = v1.max(v);
        }
        if !(u0.is_finite() && u1.is_finite() && v0.is_finite() && v1.is_finite()) {
            return true;
        }
        let r = i64::from(self.dilate_px);
        // Pixels x with [x, x+1] ∩ [u0, u1] ≠ ∅: floor(u0) ..= floor(u1). Clamp before
        // converting so a far-off rectangle cannot overflow.
        let px = |v: f64| v.floor().clamp(-1e12, 1e12) as i64;
        self.tables[view].count(px(u0) - r, px(v0) - r, px(u1) + r, px(v1) + r) > 0
    }

    /// Whether the box `[min, max]` is kept: it may touch the subject in every view.
    pub fn keeps_box(&self, min: DVec3, max: DVec3) -> bool {
        (0..self.cameras.len()).all(|v| self.keeps_box_in_view(v, min, max))
    }

    /// Carves a dense grid of `dims` voxels of edge `voxel_size_m` whose minimum
    /// corner is `origin_m`.
    pub fn carve(&self, origin_m: DVec3, voxel_size_m: f64, dims: [usize; 3]) -> DenseHull {
        let [nx, ny, nz] = dims;
        let mut inside = vec![false; nx * ny * nz];
        if !inside.is_empty() {
            inside.par_chunks_mut(nx * ny).enumerate().for_each(|(z, slab)| {
                for y in 0..ny {
                    for x in 0..nx {
                        let min = origin_m + DVec3::new(x as f64, y as f64, z as f64) * voxel_size_m;
                        slab[y * nx + x] = self.keeps_box(min, min + DVec3::splat(voxel_size_m));
                    }
                }
            });
        }
        DenseHull {
            origin_m,
            voxel_size_m,
            dims,
            inside,
        }
    }
}

/// A carved dense voxel grid: `inside[x + nx·(y + ny·z)]` for the voxel whose box is
/// `origin + [x, x+1] × [y, y+1] × [z, z+1] · voxel_size`.
#[derive(Debug, Clone, PartialEq)]
pub struct DenseHull {
    /// Minimum corner, metres.
    pub origin_m: DVec3,
    /// Voxel edge, metres.
    pub voxel_size_m: f64,
    /// Voxels along x, y, z.
    pub dims: [usize; 3],
    /// Kept flags, x fastest.
    pub inside: Vec<bool>,
}

impl DenseHull {
    /// Whether voxel `(x, y, z)` is kept (false outside the grid).
    pub fn contains(&self, x: i64, y: i64, z: i64) -> bool {
        let [nx, ny, nz] = self.dims;
        if x < 0 || y < 0 || z < 0 || x >= nx as i64 || y >= ny as i64 || z >= nz as i64 {
            return false;
        }
        self.inside[x as usize + nx * (y as usize + ny * z as usize)]
    }

    /// Kept voxels.
    pub fn count(&self) -> usize {
        self.inside.iter().filter(|&&b| b).count()
    }

    /// Volume kept, cubic metres.
    pub fn volume_m3(&self) -> f64 {
        self.count() as f64 * self.voxel_size_m.powi(3)
    }

    /// Box `(min, max)` (metres) of the kept voxels, and whether any kept voxel lies
    /// on the grid's outer layer; `None` when nothing is kept.
    pub fn kept_box(&self) -> Option<(DVec3, DVec3, bool)> {
        let [nx, ny, nz] = self.dims;
        let mut lo = [usize::MAX; 3];
        let mut hi = [0usize; 3];
        let mut any = false;
        for z in 0..nz {
            for y in 0..ny {
                for x in 0..nx {
                    if self.inside[x + nx * (y + ny * z)] {
                        any = true;
                        for (a, v) in [x, y, z].into_iter().enumerate() {
                            lo[a] = lo[a].min(v);
                            hi[a] = hi[a].max(v);
                        }
                    }
                }
            }
        }
        if !any {
            return None;
        }
        let touches = (0..3).any(|a| lo[a] == 0 || hi[a] + 1 == self.dims[a]);
        let corner = |i: [usize; 3]| {
            self.origin_m + DVec3::new(i[0] as f64, i[1] as f64, i[2] as f64) * self.voxel_size_m
        };
        Some((corner(lo), corner(hi.map(|v| v + 1)), touches))
    }
}

/// Cells per side of the first (cube) and second (refining) bounds passes.
const BOUNDS_COARSE: usize = 32;
const BOUNDS_FINE: usize = 64;
/// Times the first cube may double before the hull is declared unbounded.
const BOUNDS_MAX_GROWTH: u32 = 8;

/// The box `(min, max)` in metres holding the visual hull, found coarse-to-fine
/// around `centre_m` (see the module documentation).
pub fn hull_bounds(carver: &HullCarver, centre_m: DVec3, max_radius_m: f64) -> Result<(DVec3, DVec3)> {
    // Start from the largest radius the masks subtend around the centre's depth.
    let mut half = 0.0f64;
    for (cam, table) in carver.cameras.iter().zip(&carver.tables) {
        let depth = cam.camera_from_world(centre_m).z;
        if depth <= 0.0 || depth.is_nan() {
            return Err(BakeError::Hull(format!(
                "the head centre {centre_m} is behind a camera"
            )));
        }
        let diag = (table.width as f64 / cam.fx).hypot(table.height as f64 / cam.fy);
        half = half.max(0.5 * diag * depth);
    }
    if !(half.is_finite() && half > 0.0) {
        return Err(BakeError::Hull("cannot size the search box".into()));
    }
    if !(max_radius_m.is_finite() && max_radius_m > 0.0) {
        return Err(BakeError::Hull(format!(
            "the hull's largest radius {max_radius_m} m must be positive"
        )));
    }
    half = half.min(max_radius_m);
    for _ in 0..BOUNDS_MAX_GROWTH {
        let cell = 2.0 * half / BOUNDS_COARSE as f64;
        let coarse = carver.carve(centre_m - DVec3::splat(half), cell, [BOUNDS_COARSE; 3]);
        match coarse.kept_box() {
            None => {
                return Err(BakeError::Hull(
                    "the masks have no common region: no voxel is inside every mask (check poses and masks)"
                        .into(),
                ));
            }
            Some((_, _, true)) if half < max_radius_m => half = (2.0 * half).min(max_radius_m),
            Some((lo, hi, _)) => {
                let extent = hi - lo;
                let cell = extent.max_element() / BOUNDS_FINE as f64;
                let dims = (extent / cell)
                    .ceil()
                    .as_uvec3()
                    .to_array()
                    .map(|v| (v as usize).max(1));
                let fine = carver.carve(lo, cell, dims);
                return match fine.kept_box() {
                    Some((lo, hi, _)) => Ok((lo, hi)),
                    None => Ok((lo, hi)),
                };
            }
        }
    }
    Err(BakeError::Hull(format!(
        "the hull reaches past a {:.3} m cube around the head centre: the views are too alike to bound it",
        2.0 * half
    )))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summed_area_counts() {
        let mut mask = vec![0.0f32; 6 * 4];
        mask[6 + 2] = 1.0; // (2, 1)
        mask[3 * 6 + 5] = 0.7; // (5, 3)
        mask[4] = 0.5; // not foreground
        let t = MaskTable::new(&mask, 6, 4).unwrap();
        assert_eq!(t.count(0, 0, 5, 3), 2);
        assert_eq!(t.count(2, 1, 2, 1), 1);
        assert_eq!(t.count(3, 0, 4, 3), 0);
        assert_eq!(t.count(-10, -10, 100, 100), 2);
        assert_eq!(t.count(6, 0, 9, 3), 0);
        assert_eq!(t.count(3, 2, 1, 0), 0);
    }

    #[test]
    fn box_test_follows_projection() {
        let cam = PinholeCamera::look_at(DVec3::new(0.0, 0.0, 2.0), DVec3::ZERO, DVec3::Y, 20, 20, 0.5);
        // Foreground: the centre pixel only.
        let mut mask = vec![0.0f32; 400];
        mask[10 * 20 + 10] = 1.0;
        let carver = HullCarver::new(&[cam], &[mask.clone()], 0).unwrap();
        let s = DVec3::splat(0.005);
        assert!(carver.keeps_box(-s, s));
        // A box well to the side projects elsewhere.
        let off = DVec3::new(0.2, 0.0, 0.0);
        assert!(!carver.keeps_box(off - s, off + s));
        // Dilation by enough pixels brings it back.
        let dilated = HullCarver::new(&[cam], &[mask], 10).unwrap();
        assert!(dilated.keeps_box(off - s, off + s));
        // A box straddling the camera plane is kept.
        let eye = DVec3::new(0.0, 0.0, 2.0);
        assert!(carver.keeps_box(eye - DVec3::splat(0.1), eye + DVec3::splat(0.1)));
    }
}
