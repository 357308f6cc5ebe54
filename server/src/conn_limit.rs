//! Connections counted before anything is read from them: one address (an IPv6 client's /64)
//! holds at most `--max-connections-per-address` sockets at once (a `--trusted-proxy` excepted: its clients
//! are told apart only by their requests), and all addresses together at most
//! `--max-connections`, which by default leaves [`FILES_RESERVED`] of the open-files limit to
//! the server's own files, so that it never runs out of descriptors. (Out of them, it could
//! accept no connection at all, the operator's included: the slowloris guard bounds how long a
//! silent socket lives, not how many there are.) A connection past either cap is closed at once,
//! with a reset, before its request (or its TLS handshake) is read.
//!
//! The lease holder's address has [`HOLDER_ROOM`] places more than any other under both caps,
//! while its client holds the lease and for [`RECONNECT_GRACE`] after the lease was freed: an
//! operator whose connection dropped gets back in while others fill every place. (Before its
//! request is read a connection is known only by its address, so a client at the holder's
//! address has the same room.)

use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crate::client_addr::{Cidr, limit_key, show_key};

/// Places more for the lease holder's address, under both caps.
pub const HOLDER_ROOM: u64 = 16;

/// How long the last lease holder's address keeps its room after the lease was freed.
pub const RECONNECT_GRACE: Duration = Duration::from_secs(120);

/// Descriptors of the open-files limit left to the server's own files (records, the audit log,
/// the token file, the haptic link, its threads) by the default `--max-connections`.
pub const FILES_RESERVED: u64 = 256;

/// A refusal of one address is said in the log at most this often.
const WARN_EVERY: Duration = Duration::from_secs(60);

/// The process's open-files limit (its soft limit), or None when it cannot be read.
pub fn open_files_limit() -> Option<u64> {
    let mut lim = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit with a valid rlimit struct.
    (unsafe { libc::getrlimit(libc::RLIMIT_NOFILE, &mut lim) } == 0).then_some(lim.rlim_cur)
}

/// The default `--max-connections` under an open-files limit of `nofile`: what it leaves beyond
/// [`FILES_RESERVED`] and the holder's room, at least 64.
pub fn default_total(nofile: u64) -> u64 {
    nofile.saturating_sub(FILES_RESERVED + HOLDER_ROOM).max(64)
}

/// Why a connection was not admitted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refused {
    /// Its address holds its cap already.
    Address,
    /// All addresses together hold theirs.
    Total,
}

/// What is counted, under one lock.
#[derive(Debug, Default)]
struct Counts {
    per_address: HashMap<IpAddr, u64>,
    total: u64,
    /// The lease holder's address, and until when it keeps its room (None: while it holds it).
    holder: Option<(IpAddr, Option<Instant>)>,
    /// When each address's refusals were last said in the log.
    warned: HashMap<IpAddr, Instant>,
}

/// The connection caps and what they count.
#[derive(Debug)]
pub struct ConnLimits {
    per_address: u64,
    total: u64,
    exempt: Vec<Cidr>,
    counts: Mutex<Counts>,
    /// Connections closed unread, past a cap.
    pub refused: AtomicU64,
}

/// An admitted connection's place, given back when it is dropped (the connection closed).
#[derive(Debug)]
pub struct Permit {
    limits: Arc<ConnLimits>,
    ip: IpAddr,
}

impl Drop for Permit {
    fn drop(&mut self) {
        if let Ok(mut c) = self.limits.counts.lock() {
            c.total = c.total.saturating_sub(1);
            if let Some(n) = c.per_address.get_mut(&self.ip) {
                *n = n.saturating_sub(1);
                if *n == 0 {
                    c.per_address.remove(&self.ip);
                }
            }
        }
    }
}

impl ConnLimits {
    /// At most `per_address` connections from one address (but from `exempt` ones) and `total`
    /// in all, the lease holder's address [`HOLDER_ROOM`] more under each.
    pub fn new(per_address: u64, total: u64, exempt: Vec<Cidr>) -> Arc<ConnLimits> {
        Arc::new(ConnLimits {
            per_address,
            total,
            exempt,
            counts: Mutex::new(Counts::default()),
            refused: AtomicU64::new(0),
        })
    }

    /// The cap on all connections.
    pub fn total(&self) -> u64 {
        self.total
    }

    /// A connection from `ip` at `now`: its place, or why it has none.
    pub fn admit_at(self: &Arc<Self>, ip: IpAddr, now: Instant) -> Result<Permit, Refused> {
        let exempt = self.exempt.iter().any(|n| n.contains(ip));
        let ip = limit_key(ip);
        let mut c = self.counts.lock().map_err(|_| Refused::Total)?;
        let holder = match c.holder {
            Some((h, until)) if h == ip => until.is_none_or(|u| now < u),
            _ => false,
        };
        let room = if holder { HOLDER_ROOM } else { 0 };
        let here = c.per_address.get(&ip).copied().unwrap_or(0);
        let refused = if !exempt && here >= self.per_address + room {
            Some(Refused::Address)
        } else if c.total >= self.total + room {
            Some(Refused::Total)
        } else {
            None
        };
        if let Some(why) = refused {
            self.refused.fetch_add(1, Relaxed);
            let said = c
                .warned
                .get(&ip)
                .is_some_and(|&t| now.saturating_duration_since(t) < WARN_EVERY);
            if !said {
                if c.warned.len() >= 1024 {
                    c.warned.clear();
                }
                c.warned.insert(ip, now);
                match why {
                    Refused::Address => tracing::warn!(
                        "connections from {} closed unread: {here} open, at most {} per address (--max-connections-per-address); said once a minute",
                        show_key(ip),
                        self.per_address + room
                    ),
                    Refused::Total => tracing::warn!(
                        "connections closed unread (one from {}): {} open, at most {} in all (--max-connections); said once a minute per address",
                        show_key(ip),
                        c.total,
                        self.total + room
                    ),
                }
            }
            return Err(why);
        }
        c.total += 1;
        *c.per_address.entry(ip).or_insert(0) += 1;
        Ok(Permit {
            limits: self.clone(),
            ip,
        })
    }

    /// [`Self::admit_at`] now.
    pub fn admit(self: &Arc<Self>, ip: IpAddr) -> Result<Permit, Refused> {
        self.admit_at(ip, Instant::now())
    }

    /// The lease was taken by a client at `ip` (Some), or freed (None: the last holder's address
    /// keeps its room for [`RECONNECT_GRACE`] from `now`).
    pub fn lease_held_at(&self, ip: Option<IpAddr>, now: Instant) {
        if let Ok(mut c) = self.counts.lock() {
            c.holder = match ip {
                Some(ip) => Some((limit_key(ip), None)),
                None => c.holder.map(|(h, _)| (h, Some(now + RECONNECT_GRACE))),
            };
        }
    }

    /// [`Self::lease_held_at`] now.
    pub fn lease_held(&self, ip: Option<IpAddr>) {
        self.lease_held_at(ip, Instant::now())
    }

    /// Connections open now.
    pub fn open(&self) -> u64 {
        self.counts.lock().map_or(0, |c| c.total)
    }

    /// The Prometheus text of the counts.
    pub fn render_metrics(&self) -> String {
        format!(
            "# HELP nanopush_connections_open TCP connections open (HTTP and WebSocket), as the connection caps count them.\n# TYPE nanopush_connections_open gauge\nnanopush_connections_open {}\n# HELP nanopush_connections_max The cap on them (--max-connections; the lease holder's address has {HOLDER_ROOM} more).\n# TYPE nanopush_connections_max gauge\nnanopush_connections_max {}\n# HELP nanopush_connections_refused_total Connections closed unread: their address, or all, held their cap.\n# TYPE nanopush_connections_refused_total counter\nnanopush_connections_refused_total {}\n",
            self.open(),
            self.total,
            self.refused.load(Relaxed)
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ip(s: &str) -> IpAddr {
        s.parse().unwrap()
    }

    /// One address is held to its cap, all to theirs; a place comes back when its connection
    /// closes; a trusted proxy has no cap of its own.
    #[test]
    fn each_address_and_all_are_held_to_their_caps() {
        let l = ConnLimits::new(3, 5, vec!["10.0.0.9".parse().unwrap()]);
        let a: Vec<Permit> = (0..3).map(|_| l.admit(ip("10.0.0.1")).unwrap()).collect();
        assert_eq!(l.admit(ip("10.0.0.1")).unwrap_err(), Refused::Address);
        let b = l.admit(ip("10.0.0.2")).unwrap();
        let proxy = l.admit(ip("10.0.0.9")).unwrap();
        assert_eq!(l.open(), 5);
        assert_eq!(l.admit(ip("10.0.0.3")).unwrap_err(), Refused::Total);
        drop(b);
        let _c = l.admit(ip("10.0.0.3")).unwrap();
        drop(a);
        drop(proxy);
        let from_proxy: Vec<Permit> = (0..4).map(|_| l.admit(ip("10.0.0.9")).unwrap()).collect();
        assert_eq!(from_proxy.len(), 4, "a trusted proxy has more than 3");
        assert_eq!(l.refused.load(Relaxed), 2);
        // An IPv4-mapped IPv6 peer is its IPv4 address; an IPv6 one, its /64.
        drop(from_proxy);
        let mapped: Vec<Permit> = (0..3).map(|_| l.admit(ip("::ffff:10.0.0.1")).unwrap()).collect();
        assert_eq!(l.admit(ip("10.0.0.1")).unwrap_err(), Refused::Address);
        drop(mapped);
        let _v6: Vec<Permit> = (1..=3)
            .map(|k| l.admit(ip(&format!("2001:db8::{k}"))).unwrap())
            .collect();
        assert_eq!(l.admit(ip("2001:db8::ffff:1")).unwrap_err(), Refused::Address);
    }

    /// The lease holder's address has 16 places more under both caps, while it holds the lease
    /// and for 2 min after it was freed; then it is an address like any other.
    #[test]
    fn the_lease_holders_address_has_room_beyond_both_caps() {
        let l = ConnLimits::new(2, 4, Vec::new());
        let t0 = Instant::now();
        let op = ip("10.0.0.2");
        l.lease_held_at(Some(op), t0);
        let others: Vec<Permit> = ["10.0.0.3", "10.0.0.3", "10.0.0.4", "10.0.0.4"]
            .iter()
            .map(|a| l.admit_at(ip(a), t0).unwrap())
            .collect();
        assert_eq!(l.admit_at(ip("10.0.0.5"), t0).unwrap_err(), Refused::Total);
        // All full for the others: the holder's address has 16 places more.
        let mine: Vec<Permit> = (0..HOLDER_ROOM).map(|_| l.admit_at(op, t0).unwrap()).collect();
        assert_eq!(l.admit_at(op, t0).unwrap_err(), Refused::Total);
        drop(mine);
        // And 16 more than its own cap of 2.
        let roomy = ConnLimits::new(2, 100, Vec::new());
        roomy.lease_held_at(Some(op), t0);
        let mine: Vec<Permit> = (0..2 + HOLDER_ROOM).map(|_| roomy.admit_at(op, t0).unwrap()).collect();
        assert_eq!(roomy.admit_at(op, t0).unwrap_err(), Refused::Address);
        drop(mine);
        // Freed: the room stays for the reconnect, then goes.
        l.lease_held_at(None, t0);
        let t1 = t0 + RECONNECT_GRACE - Duration::from_millis(1);
        let back = l.admit_at(op, t1).unwrap();
        assert_eq!(l.admit_at(op, t0 + RECONNECT_GRACE).unwrap_err(), Refused::Total);
        drop((others, back));
    }

    #[test]
    fn the_default_cap_leaves_the_servers_files_their_descriptors() {
        assert_eq!(default_total(1024), 1024 - 256 - 16);
        assert_eq!(default_total(100), 64);
    }
}
