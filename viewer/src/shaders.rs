//! The `#[repr(C)]` mirrors of the structs the WGSL shaders read. The shader text and
//! its `#import` preprocessing live in `nelf_render::wgsl` (shared with the exporter's
//! GLSL/HLSL translation) and are re-exported here, except the passes only the viewer
//! runs (the storage-free march of WebGL2 and the per-pixel replay); [`VIEWER_PASSES`]
//! lists every pass the viewer compiles.
//!
//! **Mirrors.** Every uniform struct has a Rust twin with the same field order, made only
//! of 16-byte vectors so WGSL's uniform layout rules (vec4 alignment 16) and `repr(C)`
//! agree; a test compares sizes and offsets with the layout naga computes.

pub use nelf_render::wgsl::{
    ATLAS_STORE_WGSL, COMMON_WGSL, DENSE_MARCH_WGSL, DISPLAY_WGSL, LIBRARY, MARCH_WGSL, PASSES,
    PreprocessError, REFLECT_WGSL, RELIGHT_WGSL, VIEW_WGSL, preprocess,
};

/// The march pass for devices without storage bindings or compute (WebGL2): a fragment
/// entry only, no counters, no marks.
pub const MARCH_NOSTORAGE_WGSL: &str = include_str!("../../shaders/march_nostorage.wgsl");

/// Relighting a held camera's frame per pixel (compute; viewer/src/gpu/replay.rs).
pub const REPLAY_WGSL: &str = include_str!("../../shaders/replay.wgsl");

/// Every entry shader the viewer compiles: `nelf_render::wgsl::PASSES`, the storage-free
/// march and the replay.
pub const VIEWER_PASSES: &[(&str, &str)] = &[
    ("relight.wgsl", RELIGHT_WGSL),
    ("march.wgsl", MARCH_WGSL),
    ("march_nostorage.wgsl", MARCH_NOSTORAGE_WGSL),
    ("display.wgsl", DISPLAY_WGSL),
    ("dense_march.wgsl", DENSE_MARCH_WGSL),
    ("view.wgsl", VIEW_WGSL),
    ("reflect.wgsl", REFLECT_WGSL),
    ("replay.wgsl", REPLAY_WGSL),
];

/// Uniform of the per-pixel replay (`ReplayParams` in `replay.wgsl`).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ReplayParams {
    /// First component of a build dispatch, components it sums (≤ 64), components the
    /// relight uses, pixels.
    pub components: [u32; 4],
    /// Stored bricks, u32 words per voxel, coefficient encoding (1 = 8-bit affine,
    /// 2 = f16), stored rank.
    pub coefficients: [u32; 4],
    /// The lighting's mean radiance `P_mean` (rgb, not folded), unused.
    pub light_mean: [f32; 4],
    /// The cached rectangle of the image: first pixel x, y; width, height.
    pub rect: [u32; 4],
}

/// Uniform of the relight pass (`RelightParams` in `relight.wgsl`).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct RelightParams {
    /// Slot packing `x_bits`, `y_bits`; slot (brick) count; components used.
    pub atlas: [u32; 4],
    /// Grid extent in bricks; `w`: coefficient encoding (1 = 8-bit affine, 2 = f16).
    pub grid_bricks: [i32; 4],
    /// Stored rank, u32 words per voxel, 1 = show |rgb|, unused.
    pub words: [u32; 4],
    /// Folded mean radiance (rgb), unused.
    pub light_mean: [f32; 4],
    /// Stored voxels, invocations per row of a dispatch over them; invocations of
    /// `relight` (four voxels each), invocations per row of its dispatch.
    pub dispatch: [u32; 4],
    /// View part (`relight_lobes` only): lobes `J`, view rank `K_v`, u32 words of view
    /// coefficients per voxel, their encoding (1 = 8-bit affine, 2 = f16).
    pub view: [u32; 4],
}

/// Uniform of the view pass (`ViewParams` in `view.wgsl`).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ViewParams {
    /// Slot packing `x_bits`, `y_bits`; lobes `J`; stored voxels.
    pub atlas: [u32; 4],
    /// The eye in lattice coordinates `(p − bbox_min)/voxel − 0.5`, unused.
    pub eye_u: [f32; 4],
    /// Invocations per row of the dispatch, unused ×3.
    pub dispatch: [u32; 4],
    /// Lobe weights over the 9 harmonics of degrees 0–2: lobe `j`'s over harmonics 0–3
    /// in `lobes[3j]`, 4–7 in `lobes[3j + 1]`, 8 in `lobes[3j + 2][0]`.
    pub lobes: [[f32; 4]; 27],
}

/// Largest number of eyes a reflection part averages over (the length of `eyes_u` in
/// `reflect.wgsl`'s `ReflectParams`; the size test checks the two agree).
pub const MAX_REFLECT_EYES: usize = nelf_format::asset::MAX_REFLECTION_EYES;

/// Uniform of the reflect pass (`ReflectParams` in `reflect.wgsl`).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ReflectParams {
    /// Slot packing `x_bits`, `y_bits`; stored voxels; eyes in `eyes_u`.
    pub atlas: [u32; 4],
    /// The eye in lattice coordinates `(p − bbox_min)/voxel − 0.5`, unused.
    pub eye_u: [f32; 4],
    /// Invocations per row of the dispatch, unused ×3.
    pub dispatch: [u32; 4],
    /// Dequantization offsets of the codes (normal `u`, normal `v`, scale), unused.
    pub code_offset: [f32; 4],
    /// Dequantization steps of the codes (normal `u`, normal `v`, scale), unused.
    pub code_scale: [f32; 4],
    /// The columns of `light_from_world` (xyz, `w` unused): the frame of the filtered
    /// environment's table.
    pub light_from_world: [[f32; 4]; 3],
    /// The eyes the PCA part averages over, in lattice coordinates (xyz, `w` unused).
    pub eyes_u: [[f32; 4]; MAX_REFLECT_EYES],
}

/// Uniform of the march pass (`MarchParams` in `march.wgsl`).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct MarchParams {
    /// Column 0 of `Rᵀ` (row 0 of the camera's `R`), unused.
    pub world_from_camera_x: [f32; 4],
    /// Column 1 of `Rᵀ`, unused.
    pub world_from_camera_y: [f32; 4],
    /// Column 2 of `Rᵀ`, unused.
    pub world_from_camera_z: [f32; 4],
    /// Camera centre in lattice coordinates `(p − bbox_min)/voxel − 0.5`; `w` = 1/voxel size (1/m).
    pub origin_u: [f32; 4],
    /// `fx, fy, cx, cy` in pixels.
    pub intrinsics: [f32; 4],
    /// Upper grid-box corner in lattice coordinates; `w` = step Δ in metres.
    pub box_max_u: [f32; 4],
    /// `1 / atlas size` in texels; `w` = minimum transmittance.
    pub atlas_inv_size: [f32; 4],
    /// Grid extent in bricks; `w` = voxels per march-grid texel edge.
    pub grid_bricks: [i32; 4],
    /// Image width, height, frame index, flags (bit 0: jitter).
    pub image: [u32; 4],
    /// View (0 shaded, 1 density, 2 alpha), slot packing `x_bits`, `y_bits`, unused.
    pub view: [u32; 4],
    /// Density-view scale (1/σ shown as white), unused ×3.
    pub scales: [f32; 4],
    /// A fine density (format 1.4): `1 /` its atlas's size in texels; `w` = its factor `F`
    /// (0: none, σ from the atlas).
    pub fine: [f32; 4],
}

/// Sample counters written by the march when `COUNT_SAMPLES` is on (`Counters`).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Counters {
    /// Trilinear atlas samples taken.
    pub samples: u32,
    /// Lattice steps visited (samples plus skips).
    pub steps: u32,
}

/// Uniform of the display pass (`DisplayParams` in `display.wgsl`).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct DisplayParams {
    /// Background radiance (linear rgb); `w` = exposure multiplier `2^EV`.
    pub background: [f32; 4],
    /// Tone map (0 linear, 1 ACES), encode sRGB (1), debug view (1), unused.
    pub mode: [u32; 4],
}

/// Uniform of the benchmark's dense march (`DenseParams` in `dense_march.wgsl`).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct DenseParams {
    /// Image width, height, steps per ray, unused.
    pub image: [u32; 4],
}

#[cfg(test)]
mod tests {
    use super::*;

    fn module(name: &str, text: &str) -> naga::Module {
        let source = preprocess(name, text).unwrap();
        match naga::front::wgsl::parse_str(&source) {
            Ok(m) => m,
            Err(e) => panic!("{name}: {}", e.emit_to_string(&source)),
        }
    }

    #[test]
    fn every_shader_parses_and_validates() {
        for (name, text) in VIEWER_PASSES {
            let source = preprocess(name, text).unwrap();
            let module = module(name, text);
            let mut validator = naga::valid::Validator::new(
                naga::valid::ValidationFlags::all(),
                naga::valid::Capabilities::default(),
            );
            if let Err(e) = validator.validate(&module) {
                panic!("{name}: {}", e.emit_to_string(&source));
            }
            assert!(!module.entry_points.is_empty(), "{name} has no entry point");
        }
    }

    /// `(size, [(member name, offset)])` of WGSL struct `name` in `module`.
    fn wgsl_layout(module: &naga::Module, name: &str) -> (u32, Vec<(String, u32)>) {
        for (_, ty) in module.types.iter() {
            if ty.name.as_deref() == Some(name)
                && let naga::TypeInner::Struct { members, span } = &ty.inner
            {
                let fields = members
                    .iter()
                    .map(|m| (m.name.clone().unwrap_or_default(), m.offset))
                    .collect();
                return (*span, fields);
            }
        }
        panic!("struct {name} not found");
    }

    macro_rules! assert_mirror {
        ($module:expr, $ty:ident, [$($field:ident),* $(,)?]) => {{
            let (span, fields) = wgsl_layout(&$module, stringify!($ty));
            assert_eq!(span as usize, std::mem::size_of::<$ty>(), "size of {}", stringify!($ty));
            let rust: Vec<(String, u32)> =
                vec![$((stringify!($field).to_string(), std::mem::offset_of!($ty, $field) as u32)),*];
            assert_eq!(fields, rust, "fields of {}", stringify!($ty));
        }};
    }

    #[test]
    fn rust_mirrors_match_wgsl_layouts() {
        let relight = module("relight.wgsl", RELIGHT_WGSL);
        assert_mirror!(
            relight,
            RelightParams,
            [atlas, grid_bricks, words, light_mean, dispatch, view]
        );
        let view = module("view.wgsl", VIEW_WGSL);
        assert_mirror!(view, ViewParams, [atlas, eye_u, dispatch, lobes]);
        let reflect = module("reflect.wgsl", REFLECT_WGSL);
        assert_mirror!(
            reflect,
            ReflectParams,
            [
                atlas,
                eye_u,
                dispatch,
                code_offset,
                code_scale,
                light_from_world,
                eyes_u
            ]
        );
        let march = module("march.wgsl", MARCH_WGSL);
        assert_mirror!(
            march,
            MarchParams,
            [
                world_from_camera_x,
                world_from_camera_y,
                world_from_camera_z,
                origin_u,
                intrinsics,
                box_max_u,
                atlas_inv_size,
                grid_bricks,
                image,
                view,
                scales,
                fine,
            ]
        );
        assert_mirror!(march, Counters, [samples, steps]);
        let display = module("display.wgsl", DISPLAY_WGSL);
        assert_mirror!(display, DisplayParams, [background, mode]);
        let replay = module("replay.wgsl", REPLAY_WGSL);
        assert_mirror!(replay, ReplayParams, [components, coefficients, light_mean, rect]);
        let dense = module("dense_march.wgsl", DENSE_MARCH_WGSL);
        assert_mirror!(dense, DenseParams, [image]);
    }

    #[test]
    fn imports_are_expanded_once_and_checked() {
        let twice = "#import \"common.wgsl\"\n  #import \"common.wgsl\"\nfn f() {}\n";
        let out = preprocess("t.wgsl", twice).unwrap();
        assert_eq!(out.matches("fn pcg_hash").count(), 1);
        assert!(out.ends_with("fn f() {}\n"));
        assert!(!out.lines().any(|l| l.trim_start().starts_with("#import")));
        assert_eq!(
            preprocess("t.wgsl", "x\n#import \"nope.wgsl\"\n"),
            Err(PreprocessError::UnknownImport {
                file: "t.wgsl".into(),
                line: 2,
                name: "nope.wgsl".into()
            })
        );
        assert!(matches!(
            preprocess("t.wgsl", "#import common.wgsl\n"),
            Err(PreprocessError::Malformed { line: 1, .. })
        ));
        assert!(matches!(
            preprocess("common.wgsl", "#import \"common.wgsl\"\n"),
            Err(PreprocessError::Cycle(_))
        ));
        // Every pass imports the shared helpers rather than copying them.
        for (name, text) in VIEWER_PASSES {
            assert!(text.contains("#import \"common.wgsl\""), "{name}");
            for helper in [
                "fn pcg_hash",
                "fn voxel_texel",
                "fn view_harmonics",
                "fn half_to_f32",
                "fn store_voxel_texels",
                "fn lobe_buffer_radiance",
            ] {
                assert!(!text.contains(helper), "{name} copies {helper}");
            }
        }
        // The viewer compiles every pass the renderer crate lists.
        for pass in PASSES {
            assert!(VIEWER_PASSES.contains(pass), "{}", pass.0);
        }
    }
}
