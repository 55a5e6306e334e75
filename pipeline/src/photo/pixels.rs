//! Bilinear samples of a row-major image at continuous pixel coordinates (pixel
//! centres at `i + ½`, as `nelf_format::conventions::PinholeCamera::project` gives
//! them), shared by the reflectance and stereo stages.

use glam::DVec2;

/// Bilinear sample of a row-major image at continuous pixel coordinates (pixel
/// centres at `i + ½`), or `None` outside the centres' hull.
pub(crate) fn bilinear<T: Copy>(
    pixels: &[T],
    width: usize,
    height: usize,
    p: DVec2,
    mix: impl Fn([T; 4], [f32; 4]) -> T,
) -> Option<T> {
    let (x, y) = (p.x - 0.5, p.y - 0.5);
    if !(x >= 0.0 && y >= 0.0 && x <= (width - 1) as f64 && y <= (height - 1) as f64) {
        return None;
    }
    let (x0, y0) = (x.floor() as usize, y.floor() as usize);
    let (x1, y1) = ((x0 + 1).min(width - 1), (y0 + 1).min(height - 1));
    let (fx, fy) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
    let at = |x: usize, y: usize| pixels[y * width + x];
    Some(mix(
        [at(x0, y0), at(x1, y0), at(x0, y1), at(x1, y1)],
        [(1.0 - fx) * (1.0 - fy), fx * (1.0 - fy), (1.0 - fx) * fy, fx * fy],
    ))
}

/// [`bilinear`] of an RGB image.
pub(crate) fn bilinear_rgb(image: &[[f32; 3]], width: usize, height: usize, p: DVec2) -> Option<[f32; 3]> {
    bilinear(image, width, height, p, |c, k| {
        std::array::from_fn(|ch| c.iter().zip(k).map(|(c, k)| c[ch] * k).sum())
    })
}
