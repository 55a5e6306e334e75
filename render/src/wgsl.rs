//! The WGSL shaders of the GPU passes, as text (one file per pass in `../shaders/`,
//! embedded at compile time), and [`preprocess`], which resolves their `#import`
//! lines. They live here, beside the CPU reference they mirror, so that the viewer
//! (which runs them with wgpu) and the exporter (which translates them to GLSL and
//! HLSL with naga for engines) read the same preprocessed source without either
//! depending on the other.
//!
//! **Imports.** Shared helpers live once, in `shaders/common.wgsl`. A shader pulls them
//! in with a line of the form `#import "common.wgsl"`; [`preprocess`] replaces such a
//! line by the named file's text (itself preprocessed), each file at most once per
//! shader (later imports of the same file become empty), and reports unknown files and
//! import cycles. Nothing else is rewritten: line numbers of the importing file shift by
//! the imported text, which error messages from [`preprocess`] account for by naming
//! the file.

use std::collections::HashSet;

/// Shared helpers: atlas addressing, ray–box, hashing, tone mapping, sRGB.
pub const COMMON_WGSL: &str = include_str!("../../shaders/common.wgsl");
/// The relight pass (compute: `shade` per voxel, then `fill` per atlas texel).
pub const RELIGHT_WGSL: &str = include_str!("../../shaders/relight.wgsl");
/// The ray march of one pixel, shared by the march passes (imported).
pub const MARCH_CORE_WGSL: &str = include_str!("../../shaders/march_core.wgsl");
/// The ray-march pass (compute and fragment entries).
pub const MARCH_WGSL: &str = include_str!("../../shaders/march.wgsl");
/// The display pass (tone mapping, sRGB; full-screen triangle).
pub const DISPLAY_WGSL: &str = include_str!("../../shaders/display.wgsl");
/// The view pass of view-dependent assets (format 1.2; compute, one invocation per
/// voxel, run when the eye or the lighting changed).
pub const VIEW_WGSL: &str = include_str!("../../shaders/view.wgsl");
/// The reflect pass of reflection assets (format 1.3; compute: `reflect_mean` per lighting
/// change, `reflect_toward_eye` per voxel when the eye or the lighting changed).
pub const REFLECT_WGSL: &str = include_str!("../../shaders/reflect.wgsl");
/// Writing a voxel into the atlas, shared by the passes that fill it (imported; declares
/// their neighbour-block and atlas bindings).
pub const ATLAS_STORE_WGSL: &str = include_str!("../../shaders/atlas_store.wgsl");
/// The benchmark's bare dense-texture march (the speed ceiling of a texture march).
pub const DENSE_MARCH_WGSL: &str = include_str!("../../shaders/dense_march.wgsl");

/// Files that `#import` may name, with their text.
pub const LIBRARY: &[(&str, &str)] = &[
    ("common.wgsl", COMMON_WGSL),
    ("march_core.wgsl", MARCH_CORE_WGSL),
    ("atlas_store.wgsl", ATLAS_STORE_WGSL),
];

/// The entry shaders: (file name, text).
pub const PASSES: &[(&str, &str)] = &[
    ("relight.wgsl", RELIGHT_WGSL),
    ("march.wgsl", MARCH_WGSL),
    ("display.wgsl", DISPLAY_WGSL),
    ("dense_march.wgsl", DENSE_MARCH_WGSL),
    ("view.wgsl", VIEW_WGSL),
    ("reflect.wgsl", REFLECT_WGSL),
];

/// A problem found while resolving `#import` lines.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PreprocessError {
    /// An `#import` names a file that is not in [`LIBRARY`].
    #[error("{file}:{line}: #import of unknown file {name:?}")]
    UnknownImport {
        /// File holding the import.
        file: String,
        /// 1-based line number.
        line: usize,
        /// Name imported.
        name: String,
    },
    /// An `#import` line is not `#import "name"`.
    #[error("{file}:{line}: malformed #import (expected `#import \"file.wgsl\"`)")]
    Malformed {
        /// File holding the import.
        file: String,
        /// 1-based line number.
        line: usize,
    },
    /// Files import each other.
    #[error("import cycle: {0}")]
    Cycle(String),
}

/// Resolves the `#import "file"` lines of `source` (named `name` in messages) against
/// [`LIBRARY`].
pub fn preprocess(name: &str, source: &str) -> Result<String, PreprocessError> {
    let mut done = HashSet::new();
    let mut stack = vec![name.to_string()];
    let mut out = String::with_capacity(source.len() + COMMON_WGSL.len());
    expand(name, source, &mut done, &mut stack, &mut out)?;
    Ok(out)
}

fn expand(
    name: &str,
    source: &str,
    done: &mut HashSet<String>,
    stack: &mut Vec<String>,
    out: &mut String,
) -> Result<(), PreprocessError> {
    for (index, line) in source.lines().enumerate() {
        let trimmed = line.trim();
        let Some(rest) = trimmed.strip_prefix("#import") else {
            out.push_str(line);
            out.push('\n');
            continue;
        };
        let imported = rest
            .trim()
            .strip_prefix('"')
            .and_then(|r| r.strip_suffix('"'))
            .filter(|r| !r.is_empty() && !r.contains('"'))
            .ok_or_else(|| PreprocessError::Malformed {
                file: name.to_string(),
                line: index + 1,
            })?;
        if stack.iter().any(|s| s == imported) {
            return Err(PreprocessError::Cycle(format!(
                "{} → {imported}",
                stack.join(" → ")
            )));
        }
        if done.contains(imported) {
            continue;
        }
        let text = LIBRARY
            .iter()
            .find(|(n, _)| *n == imported)
            .map(|(_, t)| *t)
            .ok_or_else(|| PreprocessError::UnknownImport {
                file: name.to_string(),
                line: index + 1,
                name: imported.to_string(),
            })?;
        stack.push(imported.to_string());
        expand(imported, text, done, stack, out)?;
        stack.pop();
        done.insert(imported.to_string());
    }
    Ok(())
}
