//! Writing result files so that a crash never leaves a partial file under a result's name.

use std::io::Write;
use std::path::{Path, PathBuf};

/// `path` with `.partial` appended: where [`write_atomic`] writes before the rename.
pub fn partial(path: &Path) -> PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(".partial");
    PathBuf::from(s)
}

/// Writes `bytes` to `path.partial`, syncs it, and renames it to `path`; on failure the partial
/// file is removed.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let tmp = partial(path);
    let written = std::fs::File::create(&tmp).and_then(|mut f| {
        f.write_all(bytes)?;
        f.sync_all()
    });
    match written.and_then(|()| std::fs::rename(&tmp, path)) {
        Ok(()) => Ok(()),
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            Err(e)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_write_leaves_the_file_and_no_partial() {
        let dir = std::env::temp_dir().join(format!("nanopush-files-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("a.csv");
        write_atomic(&p, b"x,y\n").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"x,y\n");
        assert!(!partial(&p).exists());
        // A directory that does not exist: an error, and nothing left behind.
        let bad = dir.join("missing").join("b.csv");
        assert!(write_atomic(&bad, b"1").is_err());
        assert!(!partial(&bad).exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
