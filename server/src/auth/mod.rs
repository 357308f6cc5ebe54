//! Who is connecting: the credentials (a token in the URL or the `Authorization` header, or the
//! session cookie the page exchanged its token for), the people they name, the failed attempts
//! rate-limited per address, and the live sessions closed when their token is revoked.
//!
//! Two modes. Without a token file (`make run`), one generated operator token and an optional
//! viewer token, compared in constant time; the people are named `operator`, `viewer`
//! and `anonymous` (a viewer when no viewer token is set). With `--token-file`, every connection
//! needs a token of the file ([`tokens`]): one per person, with a role; the file is re-read when
//! it changes ([`reload`]), and the sessions of a token no longer in it (or whose role changed)
//! are closed. Tokens are checked with argon2 a few at a time server-wide ([`checks`]), each
//! attempt counted against its address before it is checked ([`limiter`]).

pub mod checks;
pub mod cookie;
pub mod http;
pub mod limiter;
pub mod reload;
pub mod tokens;

use std::collections::HashMap;
use std::net::IpAddr;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};
use std::sync::{Arc, Mutex};

use axum::http::StatusCode;
use nanopush_proto::ws::Role;
use sha2::{Digest, Sha256};
use subtle::ConstantTimeEq;
use tokio::sync::watch;

use self::checks::Checks;
use self::cookie::{Claims, CookieKey};
use self::limiter::FailureLimiter;
use self::reload::{FileWatch, Stamp};
use self::tokens::TokenTable;
use crate::clock::unix_now;

pub use self::reload::{FILE_POLL, SETTLE};

/// A person, as a credential names them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Person {
    /// Their name (the audit log's and the records' `person`).
    pub name: String,
    /// What they may do.
    pub role: Role,
    /// The credential they came with (a token's id, or `generated:…` without a token file):
    /// what a revocation looks for.
    pub key: String,
}

impl Person {
    /// Whether this is nobody in particular: a viewer without a credential (no token file and no
    /// viewer token), told apart from others only by their address.
    pub fn is_anonymous(&self) -> bool {
        self.key == ANONYMOUS
    }
}

/// The name and credential key of a viewer who came without a credential.
const ANONYMOUS: &str = "anonymous";

/// The session cookie's name.
pub const COOKIE: &str = "nanopush_session";

/// The token file's settings.
#[derive(Debug, Clone)]
pub struct TokenFile {
    /// Where it is.
    pub path: PathBuf,
    /// Its table when the server started (read by the caller, so a broken file stops the start
    /// with its error).
    pub table: TokenTable,
}

/// The counters `/metrics` shows.
#[derive(Debug, Default)]
pub struct AuthCounters {
    /// Credentials presented and refused (wrong, revoked).
    pub failures: AtomicU64,
    /// Attempts refused by the per-address limit without being checked.
    pub throttled: AtomicU64,
    /// Attempts refused unchecked because too many checks were running and waiting.
    pub busy: AtomicU64,
    /// Tokens exchanged for a session cookie.
    pub logins: AtomicU64,
    /// Sessions closed because their token was revoked (or its role changed).
    pub revoked_sessions: AtomicU64,
    /// Times the token file was re-read after a change.
    pub reloads: AtomicU64,
    /// Times the token file could not be used (missing, unreadable, not parsing): each new
    /// problem once.
    pub file_errors: AtomicU64,
}

/// A live WebSocket session: who, and how to close it.
struct Live {
    person: Arc<Person>,
    kick: watch::Sender<Option<String>>,
}

/// The token file as the server holds it.
struct Named {
    path: PathBuf,
    table: Mutex<Arc<TokenTable>>,
    /// The watcher's memory: taken by the watcher alone, never across the file's reading.
    watch: Mutex<FileWatch>,
    /// Whether the file could be used (read and parsed) when last looked at: what `/metrics`
    /// says, without waiting for the watcher.
    file_ok: AtomicBool,
    /// Tokens verified against the current table, by SHA-256 (argon2 once per token, not once
    /// per connection); emptied when the file changes.
    verified: Mutex<HashMap<[u8; 32], Arc<Person>>>,
}

/// Everything about access the handlers share.
pub struct Auth {
    /// Without a token file: the generated operator token and the viewer token.
    generated: (String, Option<String>),
    named: Option<Named>,
    /// Signs the session cookies (`cookie.rs`): a key of this process until the server keeps
    /// one in its data directory ([`Auth::keep_cookies_in`]); None if the kernel gave no random
    /// bytes for one (then no cookie is issued or believed).
    cookie_key: Option<CookieKey>,
    live: Mutex<HashMap<u32, Live>>,
    failures: Mutex<FailureLimiter>,
    checks: Checks,
    /// Counters for `/metrics`.
    pub counters: AuthCounters,
}

/// SHA-256 of a secret: the key it is looked up by (a lookup's time says nothing of it).
pub fn digest(secret: &str) -> [u8; 32] {
    Sha256::digest(secret.as_bytes()).into()
}

/// Whether two strings are equal, in time that depends only on their lengths.
pub fn ct_eq(a: &str, b: &str) -> bool {
    a.as_bytes().ct_eq(b.as_bytes()).into()
}

/// A refusal: the HTTP status and why.
pub type Refused = (StatusCode, String);

/// Why a token names nobody.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Unchecked {
    /// Wrong, revoked, or not a token.
    Wrong,
    /// Not checked: too many checks running and waiting ([`checks`]).
    Busy,
}

impl Auth {
    /// Access with the generated `operator` token and `viewer` token, and the token file when
    /// there is one.
    pub fn new(operator: String, viewer: Option<String>, file: Option<TokenFile>) -> Auth {
        Auth {
            generated: (operator, viewer),
            named: file.map(|f| Named {
                watch: Mutex::new(FileWatch::new(Stamp::at(&f.path))),
                file_ok: AtomicBool::new(true),
                path: f.path,
                table: Mutex::new(Arc::new(f.table)),
                verified: Mutex::new(HashMap::new()),
            }),
            cookie_key: CookieKey::ephemeral().ok(),
            live: Mutex::new(HashMap::new()),
            failures: Mutex::new(FailureLimiter::default()),
            checks: Checks::default(),
            counters: AuthCounters::default(),
        }
    }

    /// Signs cookies with the key kept in `dir` (made there on the first start), so that a
    /// page signed in before a restart stays signed in.
    pub fn keep_cookies_in(&mut self, dir: &std::path::Path) -> std::io::Result<()> {
        self.cookie_key = Some(CookieKey::load_or_make(dir)?);
        Ok(())
    }

    /// The credential key of the generated token of `role`: changes with the token, so a
    /// cookie issued for another token is not believed.
    fn generated_key(&self, role: Role) -> Option<String> {
        let token = match role {
            Role::Operator => Some(&self.generated.0),
            Role::Viewer => self.generated.1.as_ref(),
        }?;
        Some(format!(
            "generated:{}:{}",
            tokens::role_name(role),
            tokens::hex(&digest(token)[..8])
        ))
    }

    /// Whether the person a credential named is still believed: their token in the file with
    /// the same role and name, or the generated token they came with still in force.
    fn still_valid(&self, p: &Person) -> bool {
        match &self.named {
            Some(named) => named.table.lock().is_ok_and(|t| {
                t.entries
                    .iter()
                    .any(|e| e.id == p.key && e.role == p.role && e.name == p.name)
            }),
            None => self.generated_key(p.role).is_some_and(|k| k == p.key),
        }
    }

    /// Whether the people come from a token file.
    pub fn is_named(&self) -> bool {
        self.named.is_some()
    }

    /// Whether a connection without a credential is refused (a token file, or a viewer token).
    pub fn credential_required(&self) -> bool {
        self.named.is_some() || self.generated.1.is_some()
    }

    /// The person `token` names, checked (argon2 on a blocking thread, a few at a time
    /// server-wide: [`checks`]).
    async fn person_for_token(&self, token: &str) -> Result<Arc<Person>, Unchecked> {
        let Some(named) = &self.named else {
            let (op, viewer) = &self.generated;
            // Both compared, whatever the first says.
            let is_op = ct_eq(token, op);
            let is_viewer = viewer.as_deref().is_some_and(|v| ct_eq(token, v));
            let role = match (is_op, is_viewer) {
                (true, _) => Role::Operator,
                (_, true) => Role::Viewer,
                _ => return Err(Unchecked::Wrong),
            };
            return Ok(Arc::new(Person {
                name: tokens::role_name(role).into(),
                role,
                key: self.generated_key(role).ok_or(Unchecked::Wrong)?,
            }));
        };
        let key = digest(token);
        if let Some(p) = named.verified.lock().ok().and_then(|v| v.get(&key).cloned()) {
            return Ok(p);
        }
        let table = named.table.lock().map_err(|_| Unchecked::Wrong)?.clone();
        let token = token.to_string();
        let found = self
            .checks
            .run(move |scratch| {
                table.verify_with(&token, scratch).map(|e| {
                    Arc::new(Person {
                        name: e.name.clone(),
                        role: e.role,
                        key: e.id.clone(),
                    })
                })
            })
            .await
            .ok_or(Unchecked::Busy)?
            .ok_or(Unchecked::Wrong)?;
        // Cached only if the table it was checked against is still the one in force.
        let still = named.table.lock().map_err(|_| Unchecked::Wrong)?;
        if still.entries.iter().any(|e| e.id == found.key && e.role == found.role) {
            if let Ok(mut v) = named.verified.lock() {
                v.insert(key, found.clone());
            }
            Ok(found)
        } else {
            Err(Unchecked::Wrong)
        }
    }

    /// The person a session cookie names, or None: not signed by this server, too old, or its
    /// credential revoked (such cookies are as none).
    pub fn person_for_cookie(&self, cookie: &str) -> Option<Arc<Person>> {
        let c = self.cookie_key.as_ref()?.open(cookie, unix_now())?;
        let p = Person {
            name: c.name,
            role: c.role,
            key: c.key,
        };
        self.still_valid(&p).then(|| Arc::new(p))
    }

    /// Who a request is: its token (checked, failures rate-limited per `ip`), else its cookie,
    /// else anonymous where that is allowed (a viewer, without a token file or viewer token).
    pub async fn authenticate(
        &self,
        ip: IpAddr,
        token: Option<&str>,
        cookie: Option<&str>,
    ) -> Result<Arc<Person>, Refused> {
        if let Some(token) = token {
            // The attempt is counted against its address before it is checked, and given back
            // if the token is right: attempts sent at once cannot all pass an almost empty
            // bucket while their checks run.
            let reserved = self.failures.lock().map_or(Ok(()), |mut f| f.reserve(ip));
            if let Err(wait) = reserved {
                self.counters.throttled.fetch_add(1, Relaxed);
                return Err((
                    StatusCode::TOO_MANY_REQUESTS,
                    format!(
                        "too many failed attempts from {}; try again in {} s",
                        crate::client_addr::show_key(crate::client_addr::limit_key(ip)),
                        wait.as_secs().max(1)
                    ),
                ));
            }
            let checked = self.person_for_token(token).await;
            if !matches!(checked, Err(Unchecked::Wrong)) {
                if let Ok(mut f) = self.failures.lock() {
                    f.refund(ip);
                }
            }
            return match checked {
                Ok(p) => Ok(p),
                Err(Unchecked::Wrong) => {
                    self.counters.failures.fetch_add(1, Relaxed);
                    Err((StatusCode::UNAUTHORIZED, "invalid or revoked token".into()))
                }
                Err(Unchecked::Busy) => {
                    self.counters.busy.fetch_add(1, Relaxed);
                    Err((
                        StatusCode::SERVICE_UNAVAILABLE,
                        format!(
                            "the server is busy checking other sign-ins ({} at once, {} waiting); try again in a few seconds",
                            checks::AT_ONCE,
                            checks::WAITING
                        ),
                    ))
                }
            };
        }
        if let Some(p) = cookie.and_then(|c| self.person_for_cookie(c)) {
            return Ok(p);
        }
        if self.credential_required() {
            return Err((
                StatusCode::UNAUTHORIZED,
                "this server needs a token: open the page with ?token= (your own, from `nanopush token add`)".into(),
            ));
        }
        Ok(Arc::new(Person {
            name: ANONYMOUS.into(),
            role: Role::Viewer,
            key: ANONYMOUS.into(),
        }))
    }

    /// A new session cookie's value for `person`, signed (`cookie.rs`); None without a key.
    pub fn login(&self, person: &Person) -> Option<String> {
        let value = self.cookie_key.as_ref()?.issue(
            &Claims {
                name: person.name.clone(),
                role: person.role,
                key: person.key.clone(),
            },
            unix_now(),
        );
        self.counters.logins.fetch_add(1, Relaxed);
        Some(value)
    }

    /// Session `client` of `person` begins: it is closed (the receiver changes to the reason)
    /// when the person's token is revoked.
    pub fn join(&self, client: u32, person: Arc<Person>) -> watch::Receiver<Option<String>> {
        let (kick, rx) = watch::channel(None);
        if let Ok(mut l) = self.live.lock() {
            l.insert(client, Live { person, kick });
        }
        rx
    }

    /// Session `client` ended.
    pub fn leave(&self, client: u32) {
        if let Ok(mut l) = self.live.lock() {
            l.remove(&client);
        }
    }

    /// The name of the person on session `client`.
    pub fn name_of(&self, client: u32) -> Option<String> {
        self.live.lock().ok()?.get(&client).map(|l| l.person.name.clone())
    }

    /// The counters as Prometheus text.
    pub fn render_metrics(&self) -> String {
        let c = &self.counters;
        let mut s = String::new();
        for (name, help, v) in [
            (
                "nanopush_auth_failures_total",
                "Credentials presented and refused (wrong or revoked tokens).",
                &c.failures,
            ),
            (
                "nanopush_auth_throttled_total",
                "Attempts refused unchecked: too many failures from their address.",
                &c.throttled,
            ),
            (
                "nanopush_auth_busy_total",
                "Attempts refused unchecked (503): too many token checks running and waiting.",
                &c.busy,
            ),
            (
                "nanopush_auth_logins_total",
                "Tokens exchanged for a session cookie.",
                &c.logins,
            ),
            (
                "nanopush_auth_revoked_sessions_total",
                "Sessions closed because their token was revoked.",
                &c.revoked_sessions,
            ),
            (
                "nanopush_auth_token_file_reloads_total",
                "Times the token file was re-read after a change.",
                &c.reloads,
            ),
            (
                "nanopush_auth_token_file_errors_total",
                "Times the token file could not be used (missing, unreadable, not parsing); each new problem once.",
                &c.file_errors,
            ),
        ] {
            s.push_str(&format!(
                "# HELP {name} {help}\n# TYPE {name} counter\n{name} {}\n",
                v.load(Relaxed)
            ));
        }
        if let Some(named) = &self.named {
            let ok = named.file_ok.load(Relaxed);
            s.push_str(&format!(
                "# HELP nanopush_auth_token_file_ok 1 while the token file can be read and parsed; 0: the tokens read before stay in force and revocations wait.\n# TYPE nanopush_auth_token_file_ok gauge\nnanopush_auth_token_file_ok {}\n",
                u8::from(ok)
            ));
        }
        s
    }
}

#[cfg(test)]
mod tests;
