//! Writing a file so that readers see the old file or the whole new one, never a
//! part: every file the tool writes for people and other programs (`.nelf` assets,
//! exports, images, JSON sidecars, captures) goes through [`write_atomically`].
//!
//! The bytes go to a temporary file in the destination's folder (a rename is atomic
//! only within one file system), created with mode `0o666` so the process's umask
//! applies exactly as it would to a plain `File::create` (a temporary file's usual
//! `0o600` would survive the rename and leave a baked asset only its owner can
//! read), flushed and synced to disk, then renamed over the destination. If
//! anything fails the temporary file is removed and an existing file at the
//! destination is untouched.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

/// Writes `path` atomically with `write`, which receives a buffered writer (seekable,
/// for encoders that need it). Errors are the underlying I/O errors; callers name
/// the path in their own error type. Encoders with other error types map them with
/// [`std::io::Error::other`].
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    // The temporary name starts with (at most 64 characters of) the final one, so a
    // left-over file says what it was, and a 255-byte name still leaves room.
    let name: String = path
        .file_name()
        .map_or_else(|| "out".into(), |n| n.to_string_lossy())
        .chars()
        .take(64)
        .collect();
    let prefix = format!(".{name}.");
    let mut builder = tempfile::Builder::new();
    builder.prefix(&prefix).suffix(".tmp");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    let tmp = builder.tempfile_in(dir)?;
    let (file, tmp_path) = tmp.into_parts();
    let mut writer = BufWriter::new(file);
    write(&mut writer)?;
    writer.flush()?;
    {
        // Closed at the end of this block, before the rename (Windows cannot rename an
        // open file).
        let file = writer.into_inner().map_err(std::io::IntoInnerError::into_error)?;
        file.sync_all()?;
    }
    tmp_path.persist(path).map_err(|e| e.error)?;
    Ok(())
}

/// [`write_atomically`] of a byte slice.
pub fn write_bytes_atomically(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    write_atomically(path, |w| w.write_all(bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_whole_files_with_the_umask_mode_and_keeps_the_old_file_on_failure() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("asset.nelf");
        write_bytes_atomically(&path, b"first").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"first");
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let plain = dir.path().join("plain");
            File::create(&plain).unwrap();
            let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
            assert_eq!(mode(&path), mode(&plain), "the mode a plain create gives");
        }
        // A failing writer leaves the old bytes and no temporary file.
        let err = write_atomically(&path, |w| {
            w.write_all(b"partial")?;
            Err(std::io::Error::other("encoder failed"))
        })
        .unwrap_err();
        assert_eq!(err.to_string(), "encoder failed");
        assert_eq!(std::fs::read(&path).unwrap(), b"first");
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names.len(), 2, "{names:?}");
        // Replacing works.
        write_bytes_atomically(&path, b"second").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"second");
        // The longest name a file system takes still has room for the temporary name.
        let long = dir.path().join(format!("{}.nelf", "a".repeat(250)));
        write_bytes_atomically(&long, b"long").unwrap();
        assert_eq!(std::fs::read(&long).unwrap(), b"long");
        // A missing folder is an error, not a panic.
        assert!(write_bytes_atomically(&dir.path().join("no/such/file"), b"x").is_err());
    }
}
