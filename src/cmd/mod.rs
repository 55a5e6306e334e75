//! One module per subcommand: options (clap) and a `run` that calls the libraries.

pub mod bake;
pub mod batch;
pub mod capture;
pub mod demo;
pub mod eval;
pub mod eval_network;
pub mod export;
pub mod inspect;
pub mod light;
pub mod render;
pub mod render_field;
pub mod train;
pub mod view;

/// Saves a command's settings and report as pretty JSON beside its output `out`, in
/// `<out>.<kind>.json` (atomically); returns that path.
pub fn save_record(
    out: &std::path::Path,
    kind: &str,
    record: &impl serde::Serialize,
) -> anyhow::Result<std::path::PathBuf> {
    use anyhow::Context;
    let mut name = out.as_os_str().to_owned();
    name.push(format!(".{kind}.json"));
    let path = std::path::PathBuf::from(name);
    nelf_format::atomic::write_bytes_atomically(
        &path,
        (serde_json::to_string_pretty(record)? + "\n").as_bytes(),
    )
    .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(path)
}
