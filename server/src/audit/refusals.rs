//! Refused commands, per client: the first [`BURST`] logged one by one, then one every
//! [`REFILL`]; the others counted, and said in one summary line per command once the client has
//! refused nothing of it for [`QUIET`], or every [`EVERY`] while it goes on ("viewer bob from
//! 10.4.7.30: 675 refused take_lease in 15 s, …"). A client is a person (named by their token,
//! from wherever they connect), or, for an anonymous viewer, an address (an IPv6 client's /64:
//! `client_addr::limit_key`), whatever its connections: thirty sockets of one viewer share one
//! budget. So a refusal flood (a viewer's script asking for the lease 45 times a second on 30
//! sockets) grows the log by a few lines a minute instead of 360 KB a second, and nothing it did
//! is lost from the count.

use std::collections::{BTreeMap, HashMap};
use std::net::IpAddr;
use std::time::{Duration, Instant};

use nanopush_proto::ws::{ErrorCode, Role};

use crate::auth::tokens::role_name;
use crate::client_addr::{limit_key, show_key};

/// Refusals of one client logged one by one in a row.
pub const BURST: f64 = 10.0;

/// One more refusal logged one by one every this long.
pub const REFILL: Duration = Duration::from_secs(6);

/// A command's summary is written once its client has refused nothing of it for this long.
pub const QUIET: Duration = Duration::from_secs(2);

/// ... or this long after the first refusal it counts, while the refusals go on.
pub const EVERY: Duration = Duration::from_secs(60);

/// Most clients remembered: beyond it, those with nothing counted and a full budget are
/// forgotten, and while none can be, the refusals of new clients share one budget.
pub const CLIENTS_MAX: usize = 10_000;

/// A client: a named person, or an anonymous viewer's address (its [`limit_key`]).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
enum Who {
    Person {
        name: String,
        role: Role,
    },
    Anonymous {
        name: String,
        network: IpAddr,
    },
    /// New clients while [`CLIENTS_MAX`] are remembered.
    Others,
}

/// The refusals of one command counted and not yet said.
#[derive(Debug, Clone)]
struct Counted {
    count: u64,
    first: Instant,
    last: Instant,
    first_unix_ms: u64,
    last_unix_ms: u64,
    code: ErrorCode,
    message: String,
}

/// One client's budget and counts.
#[derive(Debug)]
struct Client {
    /// Refusals it may still have logged one by one, and when that was reckoned.
    level: f64,
    at: Instant,
    counted: BTreeMap<String, Counted>,
    /// Its role, and where its last refusal came from (as the summary says it).
    role: Role,
    address: String,
}

/// A summary of refusals not logged one by one.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// Who (`-`: clients beyond the [`CLIENTS_MAX`] remembered).
    pub person: String,
    /// Their role.
    pub role: Role,
    /// From where: the last refusal's address (an anonymous viewer's network, `2001:db8::/64`).
    pub address: String,
    /// The command refused.
    pub command: String,
    /// How many times.
    pub count: u64,
    /// The first (ms since the Unix epoch).
    pub first_unix_ms: u64,
    /// The last.
    pub last_unix_ms: u64,
    /// The last refusal's code.
    pub code: ErrorCode,
    /// The last refusal's message.
    pub message: String,
}

impl Summary {
    /// What the line's `message` says: who, how many, what, over how long, and the last refusal.
    pub fn text(&self) -> String {
        let secs = (self.last_unix_ms.saturating_sub(self.first_unix_ms) as f64 / 1e3)
            .ceil()
            .max(1.0);
        if self.person == "-" {
            return format!(
                "{} refused {} in {secs:.0} s from clients beyond the {CLIENTS_MAX} remembered, not logged one by one (the last: {})",
                self.count, self.command, self.message
            );
        }
        format!(
            "{} {} from {}: {} refused {} in {secs:.0} s, not logged one by one (the last: {})",
            role_name(self.role),
            self.person,
            self.address,
            self.count,
            self.command,
            self.message
        )
    }
}

/// The refusals of every client.
#[derive(Debug, Default)]
pub struct Refusals {
    clients: HashMap<Who, Client>,
}

impl Refusals {
    /// A refusal of `command` to `person` (`role`; `anonymous`: a viewer without a credential)
    /// at `address`, at `now` (`unix_ms`): whether to log it one by one (`true`), or it is
    /// counted for a summary (`false`).
    pub fn refused(
        &mut self,
        (person, role, anonymous): (&str, Role, bool),
        address: IpAddr,
        command: &str,
        (code, message): (ErrorCode, &str),
        (now, unix_ms): (Instant, u64),
    ) -> bool {
        let mut who = if anonymous {
            Who::Anonymous {
                name: person.to_string(),
                network: limit_key(address),
            }
        } else {
            Who::Person {
                name: person.to_string(),
                role,
            }
        };
        if !self.clients.contains_key(&who) && !self.make_room(now) {
            who = Who::Others;
        }
        let shown = if anonymous {
            show_key(limit_key(address))
        } else {
            address.to_canonical().to_string()
        };
        let c = self.clients.entry(who).or_insert(Client {
            level: BURST,
            at: now,
            counted: BTreeMap::new(),
            role,
            address: String::new(),
        });
        c.address = shown;
        c.level = (c.level + now.saturating_duration_since(c.at).as_secs_f64() / REFILL.as_secs_f64()).min(BURST);
        c.at = now;
        if c.level >= 1.0 {
            c.level -= 1.0;
            return true;
        }
        let k = c.counted.entry(command.to_string()).or_insert(Counted {
            count: 0,
            first: now,
            last: now,
            first_unix_ms: unix_ms,
            last_unix_ms: unix_ms,
            code,
            message: String::new(),
        });
        k.count += 1;
        k.last = now;
        k.last_unix_ms = unix_ms;
        k.code = code;
        message.clone_into(&mut k.message);
        false
    }

    /// Room for one more client: those with nothing counted and a full budget forgotten when
    /// [`CLIENTS_MAX`] are remembered; false when none could be.
    fn make_room(&mut self, now: Instant) -> bool {
        if self.clients.len() < CLIENTS_MAX {
            return true;
        }
        self.clients.retain(|who, c| {
            *who == Who::Others
                || !c.counted.is_empty()
                || c.level + now.saturating_duration_since(c.at).as_secs_f64() / REFILL.as_secs_f64() < BURST
        });
        self.clients.len() < CLIENTS_MAX
    }

    /// The summaries due at `now` (each command quiet for [`QUIET`], or counting for [`EVERY`]),
    /// taken; every summary when `all` (the log closes).
    pub fn due(&mut self, now: Instant, all: bool) -> Vec<Summary> {
        let mut out = Vec::new();
        for (who, c) in &mut self.clients {
            let person = match who {
                Who::Person { name, .. } | Who::Anonymous { name, .. } => name.clone(),
                Who::Others => "-".into(),
            };
            c.counted.retain(|command, k| {
                let due = all
                    || now.saturating_duration_since(k.last) >= QUIET
                    || now.saturating_duration_since(k.first) >= EVERY;
                if due {
                    out.push(Summary {
                        person: person.clone(),
                        role: c.role,
                        address: c.address.clone(),
                        command: command.clone(),
                        count: k.count,
                        first_unix_ms: k.first_unix_ms,
                        last_unix_ms: k.last_unix_ms,
                        code: k.code,
                        message: std::mem::take(&mut k.message),
                    });
                }
                !due
            });
        }
        out.sort_by_key(|s| s.first_unix_ms);
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FORBIDDEN: (ErrorCode, &str) = (ErrorCode::Forbidden, "viewers cannot take the lease");
    const BOB: (&str, Role, bool) = ("bob", Role::Viewer, false);
    const ANONYMOUS: (&str, Role, bool) = ("anonymous", Role::Viewer, true);

    fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    fn ip(s: &str) -> IpAddr {
        s.parse().unwrap()
    }

    /// A flood of one client's refusals: the first 10 logged, then one every 6 s; the rest
    /// counted, and summarised once the client has been quiet for 2 s: 675 in all, each once.
    #[test]
    fn one_clients_flood_is_logged_ten_times_then_summarised() {
        let mut r = Refusals::default();
        let bob = ip("10.4.7.30");
        let t0 = Instant::now();
        let mut logged = 0;
        // 45 a second for 15 s, as 30 sockets of one viewer would send them.
        for k in 0..675u64 {
            let at = t0 + ms(k * 1000 / 45);
            if r.refused(BOB, bob, "take_lease", FORBIDDEN, (at, 1_000_000 + k * 1000 / 45)) {
                logged += 1;
            }
            assert!(r.due(at, false).is_empty(), "nothing due while the flood goes on");
        }
        // 10 at once, then one every 6 s of the 15 s: 12.
        assert_eq!(logged, 12);
        let end = t0 + ms(674 * 1000 / 45);
        assert!(r.due(end + ms(1999), false).is_empty());
        let s = r.due(end + QUIET, false);
        assert_eq!(s.len(), 1);
        assert_eq!(s[0].count, 675 - 12);
        assert_eq!(
            s[0].text(),
            "viewer bob from 10.4.7.30: 663 refused take_lease in 15 s, not logged one by one (the last: viewers cannot take the lease)"
        );
        assert!(r.due(end + QUIET * 10, false).is_empty(), "said once");
        // Another person: a budget of their own. Bob from another address: his, and the
        // summary says the address of the last.
        assert!(r.refused(("eve", Role::Viewer, false), bob, "take_lease", FORBIDDEN, (end, 0)));
        for _ in 0..2 {
            assert!(!r.refused(BOB, ip("10.4.7.31"), "take_lease", FORBIDDEN, (end, 0)));
        }
        let s = r.due(end + QUIET, false);
        assert_eq!((s[0].count, s[0].address.as_str()), (2, "10.4.7.31"));
    }

    /// A flood that goes on is summarised every minute; the rest is said when the log closes.
    #[test]
    fn a_flood_that_goes_on_is_summarised_every_minute() {
        let mut r = Refusals::default();
        let a = ip("10.0.0.1");
        let t0 = Instant::now();
        let mut summaries = Vec::new();
        for k in 0..1500u64 {
            let at = t0 + ms(k * 100);
            r.refused(ANONYMOUS, a, "stop", (ErrorCode::Forbidden, "no"), (at, k * 100));
            summaries.extend(r.due(at, false));
        }
        // 150 s: summaries at 60 s and 120 s of counting, the rest when the log closes.
        assert_eq!(summaries.len(), 2, "{summaries:?}");
        summaries.extend(r.due(t0 + ms(150_000), true));
        let logged = 1500 - summaries.iter().map(|s| s.count).sum::<u64>();
        // 10 at once, then one every 6 s of the 150 s.
        assert_eq!(logged, 10 + 24);
    }

    /// Anonymous viewers are told apart by their address, an IPv6 one by its /64: a client with
    /// a whole /64 has one budget, not 2^64.
    #[test]
    fn anonymous_viewers_are_counted_by_address_and_ipv6_by_its_64() {
        let mut r = Refusals::default();
        let t0 = Instant::now();
        let logged = (1..=100u32)
            .filter(|k| {
                r.refused(
                    ANONYMOUS,
                    ip(&format!("2001:db8:1:2::{k:x}")),
                    "take_lease",
                    FORBIDDEN,
                    (t0, 0),
                )
            })
            .count();
        assert_eq!(logged, 10, "one budget for the /64");
        assert!(r.refused(ANONYMOUS, ip("2001:db8:1:3::1"), "take_lease", FORBIDDEN, (t0, 0)));
        assert!(r.refused(ANONYMOUS, ip("10.0.0.1"), "take_lease", FORBIDDEN, (t0, 0)));
        let s = r.due(t0 + QUIET, false);
        assert_eq!(s.len(), 1);
        assert!(
            s[0].text()
                .starts_with("viewer anonymous from 2001:db8:1:2::/64: 90 refused take_lease"),
            "{}",
            s[0].text()
        );
    }

    /// Past the clients remembered, new clients share one budget: a flood from many addresses
    /// does not get ten lines for each.
    #[test]
    fn clients_beyond_those_remembered_share_one_budget() {
        let mut r = Refusals::default();
        let t0 = Instant::now();
        let v4 = |k: usize| IpAddr::from(std::net::Ipv4Addr::from(0x0a00_0000 + k as u32));
        for k in 0..CLIENTS_MAX {
            // Each with something counted: none can be forgotten.
            for _ in 0..11 {
                r.refused(ANONYMOUS, v4(k), "stop", FORBIDDEN, (t0, 0));
            }
        }
        let logged = (0..100)
            .filter(|k| r.refused(ANONYMOUS, v4(CLIENTS_MAX + k), "stop", FORBIDDEN, (t0, 0)))
            .count();
        assert_eq!(logged, 10);
        let others: Vec<Summary> = r
            .due(t0 + QUIET, false)
            .into_iter()
            .filter(|s| s.person == "-")
            .collect();
        assert_eq!(others.len(), 1);
        assert!(
            others[0]
                .text()
                .starts_with("90 refused stop in 1 s from clients beyond the 10000 remembered"),
            "{}",
            others[0].text()
        );
    }
}
