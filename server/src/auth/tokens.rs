//! The token file: one line per person, `NAME ROLE ID HASH`, where the person's token is
//! `npt_ID_SECRET` and HASH is the argon2id hash (PHC string) of SECRET. Only the hash is kept:
//! a copy of the file gives nobody access. `nanopush token add|list|revoke` edits it; the server
//! re-reads it when it changes. Changes are made under an exclusive lock (`FILE.lock`, next to
//! it: [`TokenTable::update`]), so `nanopush token` run at once loses nobody's change.
//!
//! A token is checked by its ID (not secret: it only finds the line) and then by argon2's
//! verification of SECRET against the line's hash, whose digests are compared in constant time.
//! Every check runs argon2 once, whether the ID is in the file or not (and whether the token has
//! the `npt_ID_SECRET` shape at all): an unknown ID takes as long to refuse as a known one with a
//! wrong secret, so the time of an answer does not tell which IDs exist. argon2 works in memory
//! the caller lends ([`Scratch`], 19 MiB with the default parameters), reused from one check to
//! the next.

use subtle::ConstantTimeEq as _;

use std::io::{Read as _, Write as _};
use std::path::{Path, PathBuf};

use argon2::password_hash::{PasswordHash, PasswordHasher, SaltString};
use argon2::{Algorithm, Argon2, Block, Params, Version};
use nanopush_proto::ws::Role;

/// The token's prefix: a token pasted into a chat or a log is recognisable.
pub const TOKEN_PREFIX: &str = "npt_";

/// Longest name (characters).
pub const NAME_MAX: usize = 64;

/// Why the token file could not be read, written or changed.
#[derive(Debug, thiserror::Error)]
pub enum TokenFileError {
    /// Reading or writing the file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// A line is not `NAME ROLE ID HASH`.
    #[error("{path}, line {line}: {why}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// Line number (from 1).
        line: usize,
        /// What is wrong.
        why: String,
    },
    /// A name that is not allowed.
    #[error("name {0:?} is not allowed: 1 to {NAME_MAX} letters, digits, '.', '_', '-' or '@', not starting with '-'")]
    BadName(String),
    /// `add` of a name the file has.
    #[error("{0} has a token already (revoke it first to issue a new one)")]
    Exists(String),
    /// `revoke` of a name the file lacks.
    #[error("no token for {0}")]
    Missing(String),
    /// Hashing failed (never with the default parameters).
    #[error("hashing the token: {0}")]
    Hash(String),
    /// The file's owner could not be kept: the file rewritten by this user would not be
    /// readable by the server running as its owner.
    #[error(
        "{path} belongs to uid {uid} gid {gid} (the server's user, presumably), and this user cannot give the rewritten file back to them ({source}); run `nanopush token` as that user (`sudo -u USER nanopush token …`)"
    )]
    Owner {
        /// The file.
        path: PathBuf,
        /// Its owner.
        uid: u32,
        /// Its group.
        gid: u32,
        /// Cause.
        source: std::io::Error,
    },
    /// Another `nanopush token` holds the lock for longer than we wait.
    #[error("{0}: another `nanopush token` is changing the file (its lock is held); try again")]
    Locked(PathBuf),
    /// The path is not a regular file (a FIFO, a device, a directory): reading it could block or
    /// never end.
    #[error("{path} is not a regular file ({kind}); a token file must be one (made by `nanopush token add`)")]
    NotRegular {
        /// The path.
        path: PathBuf,
        /// What it is.
        kind: &'static str,
    },
    /// The file is larger than a token file can be.
    #[error("{path} is {len} bytes; a token file is at most {TEXT_MAX} bytes")]
    TooBig {
        /// The file.
        path: PathBuf,
        /// Its size.
        len: u64,
    },
}

/// Largest token file read (bytes): tens of thousands of people's lines.
pub const TEXT_MAX: u64 = 4 << 20;

/// What a file that is not a regular one is, in words.
fn kind_of(t: std::fs::FileType) -> &'static str {
    use std::os::unix::fs::FileTypeExt as _;
    if t.is_fifo() {
        "a FIFO"
    } else if t.is_char_device() {
        "a character device"
    } else if t.is_block_device() {
        "a block device"
    } else if t.is_socket() {
        "a socket"
    } else if t.is_dir() {
        "a directory"
    } else {
        "not a file"
    }
}

/// The text of the token file at `path`, and its metadata (the open file's, not the path's): a
/// regular file of at most [`TEXT_MAX`] bytes. Opened without blocking (a FIFO's open would wait
/// for a writer) and looked at before it is read, so a FIFO or a device put in its place is
/// refused at once instead of blocking its reader, or filling its memory, for ever.
pub fn read_text(path: &Path) -> Result<(std::fs::Metadata, String), TokenFileError> {
    use std::os::unix::fs::OpenOptionsExt as _;
    let io = |source| TokenFileError::Io {
        path: path.to_path_buf(),
        source,
    };
    let f = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK | libc::O_NOCTTY)
        .open(path)
        .map_err(io)?;
    let meta = f.metadata().map_err(io)?;
    if !meta.is_file() {
        return Err(TokenFileError::NotRegular {
            path: path.to_path_buf(),
            kind: kind_of(meta.file_type()),
        });
    }
    let mut text = String::new();
    f.take(TEXT_MAX + 1).read_to_string(&mut text).map_err(io)?;
    if text.len() as u64 > TEXT_MAX {
        return Err(TokenFileError::TooBig {
            path: path.to_path_buf(),
            len: meta.len().max(text.len() as u64),
        });
    }
    Ok((meta, text))
}

/// Longest wait for the lock of the token file.
const LOCK_WAIT: std::time::Duration = std::time::Duration::from_secs(30);

/// One person's line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TokenEntry {
    /// The person's name, as the audit log and the records say it.
    pub name: String,
    /// Operator or viewer.
    pub role: Role,
    /// The token's id (8 hex digits): finds the line; not secret.
    pub id: String,
    /// argon2id PHC string of the token's secret.
    pub hash: String,
}

/// The parsed token file.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct TokenTable {
    /// The people, in file order.
    pub entries: Vec<TokenEntry>,
}

/// Whether `name` may name a person.
pub fn valid_name(name: &str) -> bool {
    !name.is_empty()
        && name.chars().count() <= NAME_MAX
        && !name.starts_with('-')
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-' | '@'))
}

/// `operator` or `viewer`.
pub fn parse_role(s: &str) -> Option<Role> {
    match s {
        "operator" => Some(Role::Operator),
        "viewer" => Some(Role::Viewer),
        _ => None,
    }
}

/// The role's name in the file and the CLI.
pub fn role_name(r: Role) -> &'static str {
    match r {
        Role::Operator => "operator",
        Role::Viewer => "viewer",
    }
}

/// `N` random bytes from the kernel.
pub fn random_bytes<const N: usize>() -> std::io::Result<[u8; N]> {
    let mut b = [0u8; N];
    std::fs::File::open("/dev/urandom")?.read_exact(&mut b)?;
    Ok(b)
}

/// Lower-case hex.
pub fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Largest argon2 memory cost a hash in the file may ask for (KiB): each of the server's checks
/// at a time keeps that much.
pub const M_COST_MAX_KIB: u32 = 256 * 1024;

/// argon2's working memory, lent to each check and kept for the next: a thread that checks tokens
/// holds one buffer the size of the largest hash it checked (19 MiB with the default
/// parameters), instead of allocating one per check (with glibc, each thread's arena then keeps
/// 19 MiB, and a server that checked wrong tokens on many threads kept hundreds of MiB).
#[derive(Debug, Default)]
pub struct Scratch {
    blocks: Vec<Block>,
}

/// The salt of the check run for a token whose id is in no line (its result is thrown away).
const DUMMY_SALT: &[u8] = b"nanopush: no such token id";

impl Scratch {
    /// The buffer's size (bytes).
    pub fn bytes(&self) -> usize {
        self.blocks.len() * Block::SIZE
    }

    /// `params`' working memory, grown to it if needed.
    fn blocks(&mut self, params: &Params) -> &mut [Block] {
        let n = params.block_count();
        if self.blocks.len() < n {
            self.blocks.resize(n, Block::default());
        }
        &mut self.blocks[..n]
    }

    /// Whether `secret` hashes to `hash` (argon2, in this memory; the digests compared in
    /// constant time).
    fn verify(&mut self, secret: &str, hash: &PasswordHash<'_>) -> bool {
        let mut check = || -> Option<bool> {
            let algorithm = Algorithm::try_from(hash.algorithm).ok()?;
            let version = hash
                .version
                .map(Version::try_from)
                .transpose()
                .ok()?
                .unwrap_or_default();
            let params = Params::try_from(hash).ok()?;
            let expected = hash.hash?;
            let mut salt = [0u8; 64];
            let salt = hash.salt?.decode_b64(&mut salt).ok()?;
            let mut out = vec![0u8; expected.len()];
            Argon2::new(algorithm, version, params.clone())
                .hash_password_into_with_memory(secret.as_bytes(), salt, &mut out, self.blocks(&params))
                .ok()?;
            Some(bool::from(out.as_slice().ct_eq(expected.as_bytes())))
        };
        check().unwrap_or(false)
    }

    /// The cost of a check with the default parameters, for a token whose id is in no line.
    fn run_in_vain(&mut self, secret: &str) {
        let params = Params::default();
        let mut out = [0u8; Params::DEFAULT_OUTPUT_LEN];
        let _ = Argon2::new(Algorithm::default(), Version::default(), params.clone()).hash_password_into_with_memory(
            secret.as_bytes(),
            DUMMY_SALT,
            &mut out,
            self.blocks(&params),
        );
        std::hint::black_box(out);
    }
}

/// A token's id and secret, or None when it is not `npt_ID_SECRET`.
fn split_token(token: &str) -> Option<(&str, &str)> {
    let rest = token.strip_prefix(TOKEN_PREFIX)?;
    let (id, secret) = rest.split_once('_')?;
    (id.len() == 8 && !secret.is_empty()).then_some((id, secret))
}

fn hash_secret(secret: &str) -> Result<String, TokenFileError> {
    let salt_bytes = random_bytes::<16>().map_err(|e| TokenFileError::Hash(e.to_string()))?;
    let salt = SaltString::encode_b64(&salt_bytes).map_err(|e| TokenFileError::Hash(e.to_string()))?;
    Argon2::default()
        .hash_password(secret.as_bytes(), &salt)
        .map(|h| h.to_string())
        .map_err(|e| TokenFileError::Hash(e.to_string()))
}

impl TokenTable {
    /// Parses the file's text (`path` names it in errors).
    pub fn parse(text: &str, path: &Path) -> Result<TokenTable, TokenFileError> {
        let mut entries: Vec<TokenEntry> = Vec::new();
        for (i, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let bad = |why: String| TokenFileError::Parse {
                path: path.to_path_buf(),
                line: i + 1,
                why,
            };
            let f: Vec<&str> = line.split_whitespace().collect();
            let [name, role, id, hash] = f[..] else {
                return Err(bad(format!("expected 4 fields `NAME ROLE ID HASH`, found {}", f.len())));
            };
            if !valid_name(name) {
                return Err(bad(format!("name {name:?} is not allowed")));
            }
            let role = parse_role(role).ok_or_else(|| bad(format!("role {role:?}; allowed: operator, viewer")))?;
            if id.len() != 8 || !id.chars().all(|c| c.is_ascii_hexdigit()) {
                return Err(bad(format!("id {id:?} is not 8 hex digits")));
            }
            let phc = PasswordHash::new(hash).map_err(|e| bad(format!("hash is not an argon2 PHC string: {e}")))?;
            let m_cost = Params::try_from(&phc)
                .map_err(|e| bad(format!("hash has unusable argon2 parameters: {e}")))?
                .m_cost();
            if m_cost > M_COST_MAX_KIB {
                return Err(bad(format!(
                    "hash's argon2 memory cost m={m_cost} KiB is above the {M_COST_MAX_KIB} KiB allowed"
                )));
            }
            if entries.iter().any(|e| e.name == name || e.id == id) {
                return Err(bad(format!("{name} (or id {id}) appears twice")));
            }
            entries.push(TokenEntry {
                name: name.into(),
                role,
                id: id.into(),
                hash: hash.into(),
            });
        }
        Ok(TokenTable { entries })
    }

    /// Reads `path` ([`read_text`]: a regular file only); a missing file is an empty table when
    /// `missing_ok`.
    pub fn read(path: &Path, missing_ok: bool) -> Result<TokenTable, TokenFileError> {
        match read_text(path) {
            Ok((_, text)) => TokenTable::parse(&text, path),
            Err(TokenFileError::Io { source, .. }) if missing_ok && source.kind() == std::io::ErrorKind::NotFound => {
                Ok(TokenTable::default())
            }
            Err(e) => Err(e),
        }
    }

    /// The file's text.
    pub fn render(&self) -> String {
        let mut s = String::from(
            "# nanopush tokens: NAME ROLE ID ARGON2-HASH, one person a line.\n# Edit with `nanopush token add|list|revoke`; a running server re-reads this file.\n",
        );
        for e in &self.entries {
            s.push_str(&format!("{} {} {} {}\n", e.name, role_name(e.role), e.id, e.hash));
        }
        s
    }

    /// Writes the file whole: a temporary file (mode 0600, the old file's owner and group kept,
    /// so a `sudo nanopush token …` leaves a file the server's user still reads) fsynced, then
    /// renamed over it, so a server re-reading it never sees half a file. Changes read the file
    /// first: use [`Self::update`], which holds the lock.
    pub fn write(&self, path: &Path) -> Result<(), TokenFileError> {
        use std::os::unix::fs::{MetadataExt as _, OpenOptionsExt as _};
        let io = |source| TokenFileError::Io {
            path: path.to_path_buf(),
            source,
        };
        let tmp = path.with_extension(format!("tmp-{}", std::process::id()));
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .create(true)
            .truncate(true)
            .mode(0o600)
            .open(&tmp)
            .map_err(io)?;
        let gone = |e| {
            let _ = std::fs::remove_file(&tmp);
            e
        };
        if let (Ok(old), Ok(new)) = (std::fs::metadata(path), f.metadata()) {
            if (old.uid(), old.gid()) != (new.uid(), new.gid()) {
                std::os::unix::fs::fchown(&f, Some(old.uid()), Some(old.gid())).map_err(|source| {
                    gone(TokenFileError::Owner {
                        path: path.to_path_buf(),
                        uid: old.uid(),
                        gid: old.gid(),
                        source,
                    })
                })?;
            }
        }
        f.write_all(self.render().as_bytes())
            .and_then(|()| f.sync_all())
            .and_then(|()| std::fs::rename(&tmp, path))
            .map_err(|e| gone(io(e)))
    }

    /// Reads the file, lets `change` change the table, and writes it back, all under an
    /// exclusive lock on `FILE.lock` (waiting up to 30 s for another `nanopush token` to finish):
    /// changes made at once are made one after the other, none lost. A missing file is an empty
    /// table when `missing_ok`.
    pub fn update<T>(
        path: &Path,
        missing_ok: bool,
        change: impl FnOnce(&mut TokenTable) -> Result<T, TokenFileError>,
    ) -> Result<T, TokenFileError> {
        let _lock = lock(path)?;
        let mut table = TokenTable::read(path, missing_ok)?;
        let out = change(&mut table)?;
        table.write(path)?;
        Ok(out)
    }

    /// Adds `name` with `role`; returns the new token (shown once: only its hash is kept).
    pub fn add(&mut self, name: &str, role: Role) -> Result<String, TokenFileError> {
        if !valid_name(name) {
            return Err(TokenFileError::BadName(name.into()));
        }
        if self.entries.iter().any(|e| e.name == name) {
            return Err(TokenFileError::Exists(name.into()));
        }
        let rand = |e: std::io::Error| TokenFileError::Hash(format!("reading /dev/urandom: {e}"));
        let id = loop {
            let id = hex(&random_bytes::<4>().map_err(rand)?);
            if !self.entries.iter().any(|e| e.id == id) {
                break id;
            }
        };
        let secret = hex(&random_bytes::<16>().map_err(rand)?);
        let hash = hash_secret(&secret)?;
        self.entries.push(TokenEntry {
            name: name.into(),
            role,
            id: id.clone(),
            hash,
        });
        Ok(format!("{TOKEN_PREFIX}{id}_{secret}"))
    }

    /// Removes `name`'s token.
    pub fn revoke(&mut self, name: &str) -> Result<TokenEntry, TokenFileError> {
        let i = self
            .entries
            .iter()
            .position(|e| e.name == name)
            .ok_or_else(|| TokenFileError::Missing(name.into()))?;
        Ok(self.entries.remove(i))
    }

    /// The line `token` belongs to, checked with argon2 (slow on purpose: call it off the async
    /// workers), or None. A one-off check: [`Self::verify_with`] reuses its memory.
    pub fn verify(&self, token: &str) -> Option<&TokenEntry> {
        self.verify_with(token, &mut Scratch::default())
    }

    /// [`Self::verify`] in `scratch`'s memory. argon2 runs once whatever the token: against its
    /// line's hash, or in vain (with the default parameters) when no line has its id or it is not
    /// a token, so that the time of a refusal says nothing of which ids exist.
    pub fn verify_with(&self, token: &str, scratch: &mut Scratch) -> Option<&TokenEntry> {
        let (id, secret) = split_token(token).unwrap_or(("", token));
        let line = self
            .entries
            .iter()
            .find(|e| e.id == id)
            .and_then(|e| Some((e, PasswordHash::new(&e.hash).ok()?)));
        match line {
            Some((e, hash)) => scratch.verify(secret, &hash).then_some(e),
            None => {
                scratch.run_in_vain(secret);
                None
            }
        }
    }
}

/// The lock file of the token file at `path`: `FILE.lock` next to it.
pub fn lock_path(path: &Path) -> PathBuf {
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(".lock");
    path.with_file_name(name)
}

/// An exclusive `flock` on the token file's lock file, held until dropped (closing the file
/// releases it, also when the process dies).
fn lock(path: &Path) -> Result<std::fs::File, TokenFileError> {
    use std::os::fd::AsRawFd as _;
    use std::os::unix::fs::OpenOptionsExt as _;
    let at = lock_path(path);
    let io = |source| TokenFileError::Io {
        path: at.clone(),
        source,
    };
    // Readable by all (it holds nothing): whoever made it, any user may lock it after.
    let f = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .mode(0o644)
        .open(&at)
        .or_else(|e| match e.kind() {
            std::io::ErrorKind::PermissionDenied => std::fs::File::open(&at),
            _ => Err(e),
        })
        .map_err(io)?;
    let t0 = std::time::Instant::now();
    loop {
        // SAFETY: flock on a file descriptor this function owns.
        if unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } == 0 {
            return Ok(f);
        }
        let e = std::io::Error::last_os_error();
        match e.raw_os_error() {
            Some(libc::EWOULDBLOCK) if t0.elapsed() < LOCK_WAIT => {
                std::thread::sleep(std::time::Duration::from_millis(20))
            }
            Some(libc::EWOULDBLOCK) => return Err(TokenFileError::Locked(path.to_path_buf())),
            Some(libc::EINTR) => {}
            _ => return Err(io(e)),
        }
    }
}

#[cfg(test)]
mod tests;
