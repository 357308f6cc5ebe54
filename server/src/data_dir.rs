//! The data directory, held by one server at a time and proven writable at start.
//!
//! Two servers sharing a data directory would lose and mix records: the second one's start-up
//! would remove the first one's unfinished `.partial` trace, and scans of the same second would
//! get the same name. A server therefore holds its data directory for its whole run with an
//! exclusive `flock(2)` on the directory itself, kept open: removing a path cannot release it (a
//! lock on a file alone is gone for the next server once someone deletes that file). It also
//! locks `DATA/.nanopush.lock`, which holds its pid, so that a second server names the holder,
//! and a server of an older version, which locked only that file, is kept out too. A second server
//! given the same directory refuses to start and names the holder. The kernel drops the locks when
//! the process ends however it ends (`kill -9` included), so a crashed server never blocks the
//! next one, and the `.partial` files a new holder finds can only be a dead server's leftovers.
//! (Record names carry the server run as well, so runs one after the other never reuse a name.)
//!
//! Writing the lock file, and then a probe of [`PROBE_BYTES`] synced to disk, proves at start
//! that records can be written: a read-only, full or foreign-owned directory stops the start with
//! the reason, before anyone pushes a particle whose record would be lost.

use std::io::{Read, Seek, Write};
use std::os::fd::AsRawFd;
use std::os::unix::fs::OpenOptionsExt as _;
use std::path::{Path, PathBuf};

/// The lock file's name in the data directory (hidden: never listed or served as a record).
pub const LOCK_FILE: &str = ".nanopush.lock";

/// The start-up write probe (bytes): a directory with less room than this is full.
pub const PROBE_BYTES: usize = 1 << 20;

/// Why the data directory cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum DataDirError {
    /// Creating, locking or writing in it failed.
    #[error(
        "the data directory {dir} cannot be written ({what}: {source}); records would be lost. Give a writable directory with --data-dir (free space, permissions, a read-write mount)"
    )]
    NotWritable {
        /// The directory.
        dir: PathBuf,
        /// What was being done.
        what: &'static str,
        /// Cause.
        source: std::io::Error,
    },
    /// Another live server holds it.
    #[error(
        "the data directory {dir} is held by another nanopush serve ({holder}); two servers would lose and mix each other's records. Give each server its own --data-dir"
    )]
    Held {
        /// The directory.
        dir: PathBuf,
        /// The holder, as its lock file says (`pid N`).
        holder: String,
    },
}

/// A data directory held for the life of this value.
#[derive(Debug)]
pub struct HeldDataDir {
    /// The directory, open: holds the `flock` that no removal of a path releases (released when
    /// dropped, or when the process ends).
    _dir: std::fs::File,
    /// The lock file, open and locked too: it names this process.
    _lock: std::fs::File,
}

/// An exclusive `flock` on `f`, without waiting: Ok(false) when another holds it.
fn try_lock(f: &std::fs::File) -> std::io::Result<bool> {
    // SAFETY: flock(2) on a descriptor the caller owns.
    if unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } == 0 {
        return Ok(true);
    }
    let e = std::io::Error::last_os_error();
    match e.raw_os_error() {
        Some(libc::EWOULDBLOCK) => Ok(false),
        _ => Err(e),
    }
}

/// Creates `dir` if needed, takes its lock (or names the live server that holds it), writes this
/// process's pid in the lock file and proves with a synced probe file that records can be
/// written.
pub fn hold(dir: &Path) -> Result<HeldDataDir, DataDirError> {
    let not_writable = |what: &'static str| {
        move |source: std::io::Error| DataDirError::NotWritable {
            dir: dir.to_path_buf(),
            what,
            source,
        }
    };
    std::fs::create_dir_all(dir).map_err(not_writable("creating it"))?;
    let dir_handle = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_DIRECTORY)
        .open(dir)
        .map_err(not_writable("opening it"))?;
    let dir_free = try_lock(&dir_handle).map_err(not_writable("locking it"))?;
    let mut lock = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        // Never through a symlink: the lock file is truncated and rewritten below, and a link
        // planted there would have its target overwritten.
        .custom_flags(libc::O_NOFOLLOW)
        .open(dir.join(LOCK_FILE))
        .map_err(not_writable("opening its lock file (not a symbolic link)"))?;
    let file_free = try_lock(&lock).map_err(not_writable("locking its lock file"))?;
    if !(dir_free && file_free) {
        let mut text = String::new();
        let _ = lock.read_to_string(&mut text);
        // The lock file was deleted and made again (by this process, just now): the holder's pid
        // went with it.
        let holder = match text.trim() {
            "" if file_free => "its lock file was deleted, so its pid is not known".to_string(),
            "" => "its pid not yet written".to_string(),
            pid => format!("pid {pid}"),
        };
        return Err(DataDirError::Held {
            dir: dir.to_path_buf(),
            holder,
        });
    }
    lock.set_len(0)
        .and_then(|()| lock.rewind())
        .and_then(|()| writeln!(lock, "{}", std::process::id()))
        .and_then(|()| lock.sync_all())
        .map_err(not_writable("writing its lock file"))?;
    let probe = dir.join(format!(".nanopush-probe-{}", std::process::id()));
    let written = std::fs::File::create(&probe)
        .and_then(|mut f| f.write_all(&vec![0u8; PROBE_BYTES]).and_then(|()| f.sync_all()));
    let _ = std::fs::remove_file(&probe);
    written.map_err(not_writable("writing a 1 MiB probe"))?;
    Ok(HeldDataDir {
        _dir: dir_handle,
        _lock: lock,
    })
}

/// Whether records can be written in `dir` now (for `/metrics`): a directory this process may
/// write, on a file system not mounted read-only.
pub fn writable(dir: &Path) -> bool {
    use std::os::unix::ffi::OsStrExt;
    let Ok(path) = std::ffi::CString::new(dir.as_os_str().as_bytes()) else {
        return false;
    };
    let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
    // SAFETY: a NUL-terminated path and a statvfs struct we own.
    let mounted_rw = unsafe { libc::statvfs(path.as_ptr(), &mut st) } == 0 && st.f_flag & libc::ST_RDONLY == 0;
    // SAFETY: a NUL-terminated path.
    mounted_rw && unsafe { libc::access(path.as_ptr(), libc::W_OK | libc::X_OK) } == 0
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One holder at a time, the second told the first's pid; the lock goes with its holder.
    #[test]
    fn a_held_directory_is_refused_naming_its_holder_until_released() {
        let dir = std::env::temp_dir().join(format!("nanopush-held-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let first = hold(&dir).unwrap();
        let e = hold(&dir).unwrap_err().to_string();
        assert!(
            e.contains(&format!("pid {}", std::process::id())) && e.contains("another nanopush serve"),
            "{e}"
        );
        assert!(writable(&dir));
        drop(first);
        let again = hold(&dir).unwrap();
        // No probe is left behind, and the lock file is not a record.
        let names: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, vec![LOCK_FILE.to_string()]);
        assert!(crate::records::list(&dir).unwrap().is_empty());
        drop(again);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Deleting the lock file does not release the directory: a second holder is still refused
    /// (the lock is on the directory itself), and told the first one's pid is not known.
    #[test]
    fn a_deleted_lock_file_does_not_release_the_directory() {
        let dir = std::env::temp_dir().join(format!("nanopush-held-unlinked-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let first = hold(&dir).unwrap();
        std::fs::remove_file(dir.join(LOCK_FILE)).unwrap();
        let e = hold(&dir).unwrap_err().to_string();
        assert!(
            e.contains("another nanopush serve") && e.contains("its lock file was deleted"),
            "{e}"
        );
        drop(first);
        drop(hold(&dir).unwrap());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A symbolic link planted as the lock file is refused, not followed (its target would be
    /// truncated and overwritten with the server's pid).
    #[test]
    fn a_lock_file_that_is_a_symlink_is_refused_and_its_target_kept() {
        let dir = std::env::temp_dir().join(format!("nanopush-held-link-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let target = dir.join("precious.txt");
        std::fs::write(&target, "keep me").unwrap();
        std::os::unix::fs::symlink(&target, dir.join(LOCK_FILE)).unwrap();
        let e = hold(&dir).unwrap_err().to_string();
        assert!(e.contains("not a symbolic link"), "{e}");
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "keep me");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A directory nobody can write (in /proc, even for root) is refused with the
    /// reason, and is not counted writable.
    #[test]
    fn a_directory_that_cannot_be_written_is_refused() {
        let dir = Path::new("/proc/self/fdinfo");
        let e = hold(dir).unwrap_err().to_string();
        assert!(e.contains("/proc/self/fdinfo cannot be written"), "{e}");
        assert!(!writable(Path::new("/nonexistent-nanopush")));
    }
}
