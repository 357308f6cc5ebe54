//! Session cookies that survive a restart: the cookie names its person and is signed with
//! HMAC-SHA256 (RFC 2104) under a key kept in the data directory (`auth/cookie-key`, 32 random
//! bytes, mode 0600), so a page signed in before the server restarted (an update, a power cut)
//! reconnects as the same person without its token. A cookie is believed only while its
//! credential is: the token file still holds its token id with the same role (revocation ends
//! it), or, without a token file, the generated token it was issued for is still the one in
//! force. Cookies older than [`MAX_AGE_S`] are refused.
//!
//! Value: `ISSUED.ROLE.HEX(KEY).HEX(NAME).HEX(MAC)`, where MAC is the HMAC of everything
//! before it; compared in constant time.

use std::io::Write as _;
use std::path::Path;

use nanopush_proto::ws::Role;
use sha2::{Digest, Sha256};
use subtle::ConstantTimeEq;

use super::tokens::{hex, parse_role, random_bytes, role_name};

/// A cookie is refused this long after it was issued (s): a week.
pub const MAX_AGE_S: u64 = 7 * 24 * 3600;

/// The signing key.
pub struct CookieKey([u8; 32]);

/// What a cookie says.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Claims {
    /// The person's name.
    pub name: String,
    /// Their role.
    pub role: Role,
    /// Their credential (a token id, or the generated token's key).
    pub key: String,
}

/// HMAC-SHA256 of `msg` under `key` (RFC 2104, a 32-byte key: shorter than the block).
pub fn hmac_sha256(key: &[u8; 32], msg: &[u8]) -> [u8; 32] {
    let mut k = [0u8; 64];
    k[..32].copy_from_slice(key);
    let pad = |b: u8| k.iter().map(|x| x ^ b).collect::<Vec<u8>>();
    let inner = Sha256::new().chain_update(pad(0x36)).chain_update(msg).finalize();
    Sha256::new()
        .chain_update(pad(0x5c))
        .chain_update(inner)
        .finalize()
        .into()
}

fn unhex(s: &str) -> Option<Vec<u8>> {
    if s.len() % 2 != 0 {
        return None;
    }
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(s.get(i..i + 2)?, 16).ok())
        .collect()
}

impl CookieKey {
    /// A key for this process only (cookies end with it).
    pub fn ephemeral() -> std::io::Result<CookieKey> {
        random_bytes::<32>().map(CookieKey)
    }

    /// The key kept in `dir`, made there (mode 0600) on the first start.
    pub fn load_or_make(dir: &Path) -> std::io::Result<CookieKey> {
        use std::os::unix::fs::OpenOptionsExt as _;
        let path = dir.join("cookie-key");
        if let Ok(bytes) = std::fs::read(&path)
            && let Ok(key) = <[u8; 32]>::try_from(bytes.as_slice())
        {
            return Ok(CookieKey(key));
        }
        std::fs::create_dir_all(dir)?;
        let key = random_bytes::<32>()?;
        let tmp = dir.join(format!("cookie-key.tmp-{}", std::process::id()));
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .create(true)
            .truncate(true)
            .mode(0o600)
            .open(&tmp)?;
        f.write_all(&key)?;
        f.sync_all()?;
        std::fs::rename(&tmp, &path)?;
        Ok(CookieKey(key))
    }

    /// A cookie's value for `c`, issued at `now` (Unix s).
    pub fn issue(&self, c: &Claims, now: u64) -> String {
        let body = format!(
            "{now}.{}.{}.{}",
            role_name(c.role),
            hex(c.key.as_bytes()),
            hex(c.name.as_bytes())
        );
        let mac = hmac_sha256(&self.0, body.as_bytes());
        format!("{body}.{}", hex(&mac))
    }

    /// What a cookie says, if this key signed it and it is not older than [`MAX_AGE_S`] at `now`.
    pub fn open(&self, value: &str, now: u64) -> Option<Claims> {
        let (body, mac) = value.rsplit_once('.')?;
        let mac = unhex(mac)?;
        let want = hmac_sha256(&self.0, body.as_bytes());
        if !bool::from(want.as_slice().ct_eq(&mac)) {
            return None;
        }
        let mut f = body.split('.');
        let issued: u64 = f.next()?.parse().ok()?;
        let role = parse_role(f.next()?)?;
        let key = String::from_utf8(unhex(f.next()?)?).ok()?;
        let name = String::from_utf8(unhex(f.next()?)?).ok()?;
        if f.next().is_some() || issued > now + 60 || now.saturating_sub(issued) > MAX_AGE_S {
            return None;
        }
        Some(Claims { name, role, key })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// RFC 4231 test case 2's message under a 32-byte key of 0x0b, against openssl's
    /// `openssl dgst -sha256 -mac HMAC -macopt hexkey:0b0b…0b` (32 bytes).
    #[test]
    fn hmac_matches_openssl() {
        let key = [0x0b; 32];
        assert_eq!(
            hex(&hmac_sha256(&key, b"what do ya want for nothing?")),
            "c3f2649c34ea24e4d62a2c7e868bbea0233c9d4c2cc300794db76aa18d6822d8"
        );
    }

    #[test]
    fn a_cookie_opens_with_its_key_only_unaltered_and_within_its_age() {
        let k = CookieKey::ephemeral().unwrap();
        let c = Claims {
            name: "alice.b@lab".into(),
            role: Role::Operator,
            key: "3f9a1c2b".into(),
        };
        let v = k.issue(&c, 1000);
        assert_eq!(k.open(&v, 1000), Some(c.clone()));
        assert_eq!(k.open(&v, 1000 + MAX_AGE_S), Some(c));
        assert_eq!(k.open(&v, 1001 + MAX_AGE_S), None, "too old");
        assert_eq!(CookieKey::ephemeral().unwrap().open(&v, 1000), None, "another key");
        let forged = v.replacen("operator", "viewer", 1);
        assert_eq!(k.open(&forged, 1000), None, "altered");
        assert_eq!(k.open("garbage", 1000), None);
        let dir = std::env::temp_dir().join(format!("nanopush-cookie-key-{}", std::process::id()));
        let a = CookieKey::load_or_make(&dir).unwrap();
        let b = CookieKey::load_or_make(&dir).unwrap();
        assert_eq!(a.0, b.0, "kept across starts");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
