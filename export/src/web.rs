//! `nelf export web ASSET -o DIR`: a self-contained web page showing the asset, which
//! any static file server can host: the built web viewer (`web/dist`: `index.html`,
//! `nelf_web.js`, `nelf_web_bg.wasm`, embedded in this crate at compile time, so the
//! `nelf` binary writes the page without building anything), the asset and its
//! environment map, and the page's defaults (asset, map, camera, lighting) in
//! `index.html`'s `nelf-defaults` meta tag, which the page reads before the link's own
//! URL parameters (`web/src/params.rs`).
//!
//! The embedded page is the one committed in `web/dist`; `scripts/build_web.sh`
//! rebuilds it and the root crate's `tests/web.rs` fails when a rebuild differs.

use std::path::{Path, PathBuf};

use nelf_format::conventions::LatLong;
use nelf_format::io_error::FileIoError;

use crate::{ExportError, write_atomic};

/// The built page, embedded: (file name, bytes).
pub const PAGE_FILES: &[(&str, &[u8])] = &[
    ("index.html", include_bytes!("../../web/dist/index.html")),
    ("nelf_web.js", include_bytes!("../../web/dist/nelf_web.js")),
    (
        "nelf_web_bg.wasm",
        include_bytes!("../../web/dist/nelf_web_bg.wasm"),
    ),
];

/// The meta tag whose `content` holds the page's default URL parameters.
const DEFAULTS_TAG: &str = r#"<meta name="nelf-defaults" content="">"#;

/// The environment map a page starts with.
#[derive(Debug, Clone)]
pub enum WebEnvmap {
    /// An `.exr`/`.hdr` file, copied as it is (after checking that it decodes).
    File(PathBuf),
    /// A map made here (e.g. the built-in studio map), written as `<name>.exr`.
    Generated {
        /// File stem.
        name: String,
        /// The map.
        env: LatLong,
    },
}

/// What the page shows at start.
#[derive(Debug, Clone)]
pub struct WebPageOptions {
    /// The `.nelf` asset (read and checked, then copied under its own file name).
    pub asset: PathBuf,
    /// The lighting.
    pub envmap: WebEnvmap,
    /// Further URL parameters the page starts with (`orbit=…&rotate=…`, already checked
    /// by the caller), without the asset and map.
    pub start_query: String,
}

/// What was written.
#[derive(Debug, Clone, serde::Serialize)]
pub struct WebPageReport {
    /// Every file written, with its size in bytes.
    pub files: Vec<(String, u64)>,
    /// Bytes of the viewer itself (html + js + wasm).
    pub viewer_bytes: u64,
    /// The URL parameters the page starts with.
    pub defaults: String,
}

impl WebPageReport {
    /// The lines `nelf export web` prints for a page written to `out_dir`.
    #[must_use]
    pub fn to_text(&self, out_dir: &Path) -> String {
        use std::fmt::Write as _;
        let mut text = String::new();
        for (name, bytes) in &self.files {
            let _ = writeln!(text, "  {name}: {bytes} bytes");
        }
        let _ = writeln!(
            text,
            "web page written to {} (viewer {} bytes; start: ?{}); serve the folder, e.g. \
             `python3 -m http.server -d {}`, and open index.html (WebGPU, or WebGL2 with the relight \
             on the CPU)",
            out_dir.display(),
            self.viewer_bytes,
            self.defaults,
            out_dir.display()
        );
        text
    }
}

/// Writes the page into `out_dir` (created if needed; files of the same names are
/// replaced atomically, others left alone).
pub fn write_web_page(options: &WebPageOptions, out_dir: &Path) -> Result<WebPageReport, ExportError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| ExportError::Io(FileIoError::new(path, source))
    };
    let asset_bytes = std::fs::read(&options.asset).map_err(io(&options.asset))?;
    nelf_format::read_asset_bytes(&asset_bytes)?;
    let asset_name = file_name(&options.asset)?;
    // A file's bytes are copied; a generated map is written as EXR below.
    let (env_name, env_bytes) = match &options.envmap {
        WebEnvmap::File(path) => {
            let bytes = std::fs::read(path).map_err(io(path))?;
            let name = file_name(path)?;
            let kind = nelf_format::envmap_file::EnvmapKind::from_name(&name)
                .map_err(|e| ExportError::BadOption(e.to_string()))?;
            nelf_format::envmap_file::decode_envmap(&bytes, kind)
                .map_err(|e| ExportError::BadOption(format!("{}: {e}", path.display())))?;
            (name, Some(bytes))
        }
        WebEnvmap::Generated { name, .. } => (format!("{name}.exr"), None),
    };
    if asset_name == env_name || PAGE_FILES.iter().any(|(n, _)| *n == asset_name || *n == env_name) {
        return Err(ExportError::BadOption(format!(
            "the asset {asset_name} and map {env_name} need names of their own (not the page's files)"
        )));
    }
    let mut defaults = format!("asset={}&env={}", url_encode(&asset_name), url_encode(&env_name));
    if !options.start_query.is_empty() {
        defaults.push('&');
        defaults.push_str(&options.start_query);
    }
    std::fs::create_dir_all(out_dir).map_err(io(out_dir))?;
    let mut files = Vec::new();
    let mut viewer_bytes = 0;
    for (name, bytes) in PAGE_FILES {
        let page;
        let bytes: &[u8] = if *name == "index.html" {
            page = index_with_defaults(bytes, &defaults)?;
            page.as_bytes()
        } else {
            bytes
        };
        viewer_bytes += bytes.len() as u64;
        files.push(write_file(out_dir, name, bytes)?);
    }
    files.push(write_file(out_dir, &asset_name, &asset_bytes)?);
    match (&options.envmap, env_bytes) {
        (_, Some(bytes)) => files.push(write_file(out_dir, &env_name, &bytes)?),
        (WebEnvmap::Generated { env, .. }, None) => {
            let path = out_dir.join(&env_name);
            nelf_scene::image_io::write_exr_rgb(&path, env.width() as u32, env.height() as u32, env.texels())
                .map_err(|e| ExportError::Metadata(format!("cannot write the environment map: {e}")))?;
            let bytes = std::fs::metadata(&path).map_err(io(&path))?.len();
            files.push((env_name, bytes));
        }
        (WebEnvmap::File(_), None) => {}
    }
    Ok(WebPageReport {
        files,
        viewer_bytes,
        defaults,
    })
}

fn write_file(dir: &Path, name: &str, bytes: &[u8]) -> Result<(String, u64), ExportError> {
    write_atomic(&dir.join(name), bytes)?;
    Ok((name.to_owned(), bytes.len() as u64))
}

fn file_name(path: &Path) -> Result<String, ExportError> {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .ok_or_else(|| ExportError::BadOption(format!("{} names no file", path.display())))
}

/// `index.html` with its defaults tag filled in.
fn index_with_defaults(template: &[u8], defaults: &str) -> Result<String, ExportError> {
    let text = std::str::from_utf8(template)
        .map_err(|_| ExportError::BadOption("the embedded index.html is not UTF-8".into()))?;
    if !text.contains(DEFAULTS_TAG) {
        return Err(ExportError::BadOption(
            "the embedded index.html has no nelf-defaults tag (rebuild web/dist)".into(),
        ));
    }
    let escaped = defaults.replace('&', "&amp;").replace('"', "&quot;");
    Ok(text.replace(
        DEFAULTS_TAG,
        &format!(r#"<meta name="nelf-defaults" content="{escaped}">"#),
    ))
}

/// Percent-encodes everything but unreserved characters.
pub fn url_encode(text: &str) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    for b in text.bytes() {
        if b.is_ascii_alphanumeric() || b"-._~".contains(&b) {
            out.push(char::from(b));
        } else {
            let _ = write!(out, "%{b:02X}");
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_page_is_embedded_with_a_defaults_tag() {
        let index = PAGE_FILES
            .iter()
            .find(|(n, _)| *n == "index.html")
            .map(|(_, b)| *b)
            .unwrap();
        let page = index_with_defaults(index, "asset=a%20b.nelf&env=x.exr").unwrap();
        assert!(
            page.contains(r#"content="asset=a%20b.nelf&amp;env=x.exr""#),
            "{page}"
        );
        assert!(PAGE_FILES.iter().all(|(_, b)| !b.is_empty()));
        let wasm = PAGE_FILES
            .iter()
            .find(|(n, _)| *n == "nelf_web_bg.wasm")
            .map(|(_, b)| *b)
            .unwrap();
        assert_eq!(&wasm[..4], b"\0asm");
    }

    #[test]
    fn names_are_percent_encoded() {
        assert_eq!(url_encode("head scan&1.nelf"), "head%20scan%261.nelf");
        assert_eq!(url_encode("a-b_c.~"), "a-b_c.~");
    }

    #[test]
    fn a_generated_map_round_trips_through_the_written_exr() {
        let dir = tempfile::tempdir().unwrap();
        let asset_path = dir.path().join("head.nelf");
        let asset = nelf_format::synthetic::SyntheticField::new(2_000, 3)
            .asset(2, nelf_format::CoefficientEncoding::U8Affine)
            .unwrap();
        nelf_format::write_asset(&asset_path, &asset, &nelf_format::WriteOptions::default()).unwrap();
        let env = LatLong::new(4, 2, (0..8).map(|i| [i as f32, 0.5, 2.0]).collect()).unwrap();
        let options = WebPageOptions {
            asset: asset_path,
            envmap: WebEnvmap::Generated {
                name: "sky".into(),
                env: env.clone(),
            },
            start_query: String::new(),
        };
        let report = write_web_page(&options, &dir.path().join("site")).unwrap();
        assert!(
            report.files.iter().any(|(n, b)| n == "sky.exr" && *b > 0),
            "{report:?}"
        );
        assert_eq!(report.defaults, "asset=head.nelf&env=sky.exr");
        let bytes = std::fs::read(dir.path().join("site/sky.exr")).unwrap();
        let back = nelf_format::envmap_file::decode_envmap(&bytes, nelf_format::envmap_file::EnvmapKind::Exr)
            .unwrap();
        assert_eq!(back.texels(), env.texels());
    }
}
