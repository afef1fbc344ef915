//! Files that appear complete or not at all: every output urbansem writes goes through here.
//!
//! [`AtomicFile`] writes into a temporary file in the target's folder (`.NAME.XXXXXX.partial`),
//! flushes and syncs it, and renames it over the target only in [`AtomicFile::commit`]. Until
//! then the previous file under the target name is untouched; a writer that fails, is dropped
//! or is killed leaves no partial file under the target name (a killed process may leave the
//! hidden `.partial` file behind, never a truncated target). The rename is atomic on POSIX
//! file systems (`rename(2)` within one folder). The new file gets the target's previous
//! permissions, or the usual default (`0o666` less the umask) for a new file.
//!
//! ```
//! use std::io::Write;
//! let dir = tempfile::tempdir().unwrap();
//! let path = dir.path().join("out.txt");
//! let mut f = geodata::fsio::AtomicFile::create(&path).unwrap();
//! f.write_all(b"complete").unwrap();
//! assert!(!path.exists()); // nothing under the name until the commit
//! f.commit().unwrap();
//! assert_eq!(std::fs::read(&path).unwrap(), b"complete");
//! ```

#[cfg(unix)]
use std::fs::Permissions;
use std::io::{self, BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use tempfile::NamedTempFile;

/// A file being written that replaces its target only when committed.
#[derive(Debug)]
pub struct AtomicFile {
    inner: BufWriter<NamedTempFile>,
    path: PathBuf,
}

/// The folder a path's file lives in (`.` for a bare file name).
fn parent_dir(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// Permissions for the new file: the old target's, or the default for a new file.
#[cfg(unix)]
fn permissions_for(path: &Path) -> Permissions {
    use std::os::unix::fs::PermissionsExt;
    match std::fs::metadata(path) {
        Ok(meta) => meta.permissions(),
        // The mode is passed to open(2), which applies the umask.
        Err(_) => Permissions::from_mode(0o666),
    }
}

impl AtomicFile {
    /// Starts writing `path`: creates its folder if missing, then the temporary file beside
    /// it.
    pub fn create(path: impl AsRef<Path>) -> io::Result<AtomicFile> {
        let path = path.as_ref().to_path_buf();
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .ok_or_else(|| {
                io::Error::new(
                    io::ErrorKind::InvalidInput,
                    format!("{}: not a file path", path.display()),
                )
            })?;
        let prefix = format!(".{name}.");
        let mut builder = tempfile::Builder::new();
        builder.prefix(&prefix).suffix(".partial");
        #[cfg(unix)]
        builder.permissions(permissions_for(&path));
        std::fs::create_dir_all(parent_dir(&path))?;
        let file = builder.tempfile_in(parent_dir(&path))?;
        Ok(AtomicFile {
            inner: BufWriter::with_capacity(1 << 16, file),
            path,
        })
    }

    /// The target path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Flushes, syncs and renames the file into place; only now does the target change.
    pub fn commit(self) -> io::Result<()> {
        let file = self.inner.into_inner().map_err(|e| e.into_error())?;
        file.as_file().sync_all()?;
        file.persist(&self.path).map_err(|e| e.error)?;
        Ok(())
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.inner.write(buf)
    }

    fn write_all(&mut self, buf: &[u8]) -> io::Result<()> {
        self.inner.write_all(buf)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.inner.flush()
    }
}

impl Seek for AtomicFile {
    fn seek(&mut self, pos: SeekFrom) -> io::Result<u64> {
        self.inner.seek(pos)
    }
}

/// Writes `bytes` to `path` atomically (see [`AtomicFile`]).
pub fn write_atomic(path: impl AsRef<Path>, bytes: impl AsRef<[u8]>) -> io::Result<()> {
    let mut f = AtomicFile::create(path)?;
    f.write_all(bytes.as_ref())?;
    f.commit()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn partial_files(dir: &Path) -> Vec<String> {
        std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".partial"))
            .collect()
    }

    #[test]
    fn a_missing_folder_is_created() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a/b/out.uloc");
        write_atomic(&path, b"index").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"index");
        assert!(partial_files(&dir.path().join("a/b")).is_empty());
    }

    #[test]
    fn old_file_survives_an_abandoned_write() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("map.srt");
        write_atomic(&path, b"old map").unwrap();
        {
            let mut f = AtomicFile::create(&path).unwrap();
            f.write_all(&[7u8; 100_000]).unwrap();
            // Dropped without commit: an error part-way through a writer.
        }
        assert_eq!(std::fs::read(&path).unwrap(), b"old map");
        assert!(partial_files(dir.path()).is_empty());
        write_atomic(&path, b"new map").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"new map");
        assert!(partial_files(dir.path()).is_empty());
    }

    #[test]
    fn seek_and_bare_names_work() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.bin");
        let mut f = AtomicFile::create(&path).unwrap();
        f.write_all(b"xxxxdata").unwrap();
        f.seek(SeekFrom::Start(0)).unwrap();
        f.write_all(b"head").unwrap();
        f.commit().unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"headdata");
        // A folder that cannot be made (a file stands in its place) is an error.
        assert!(AtomicFile::create(path.join("x")).is_err());
    }

    #[cfg(unix)]
    #[test]
    fn permissions_are_kept_or_default() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("p.txt");
        write_atomic(&path, b"1").unwrap();
        let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode & 0o600, 0o600, "owner can read and write: {mode:o}");
        std::fs::set_permissions(&path, Permissions::from_mode(0o640)).unwrap();
        write_atomic(&path, b"2").unwrap();
        let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o640);
    }
}
