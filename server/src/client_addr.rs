//! The client's real address behind a reverse proxy. A connection from a `--trusted-proxy`
//! address carries the client's address in `X-Forwarded-For` (each proxy appends the address it
//! was connected from): read from the right, the first address that is not a trusted proxy is
//! the client. From anyone else the header is ignored (a client could write anything in it), so
//! per-address limits and the audit log cannot be fooled.

use std::net::{IpAddr, Ipv6Addr};
use std::str::FromStr;

use axum::http::HeaderMap;

/// An address or a block of them (`10.0.0.0/8`, `::1`, `192.168.1.7`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Cidr {
    net: IpAddr,
    prefix: u8,
}

impl FromStr for Cidr {
    type Err = String;

    fn from_str(s: &str) -> Result<Cidr, String> {
        let (addr, prefix) = match s.split_once('/') {
            Some((a, p)) => (a, Some(p)),
            None => (s, None),
        };
        let net: IpAddr = addr
            .parse()
            .map_err(|_| format!("{s:?} is not an address or a CIDR block (e.g. 10.0.0.0/8, ::1)"))?;
        let max = if net.is_ipv4() { 32 } else { 128 };
        let prefix = match prefix {
            None => max,
            Some(p) => p
                .parse::<u8>()
                .ok()
                .filter(|&p| p <= max)
                .ok_or_else(|| format!("{s:?}: the prefix length must be in [0, {max}]"))?,
        };
        Ok(Cidr { net, prefix })
    }
}

impl Cidr {
    /// Whether `ip` is in the block (an IPv4-mapped IPv6 address counts as its IPv4 one).
    pub fn contains(&self, ip: IpAddr) -> bool {
        match (self.net, ip.to_canonical()) {
            (IpAddr::V4(n), IpAddr::V4(a)) => {
                let mask = u32::MAX.checked_shl(32 - u32::from(self.prefix)).unwrap_or(0);
                u32::from(n) & mask == u32::from(a) & mask
            }
            (IpAddr::V6(n), IpAddr::V6(a)) => {
                let mask = u128::MAX.checked_shl(128 - u32::from(self.prefix)).unwrap_or(0);
                u128::from(n) & mask == u128::from(a) & mask
            }
            _ => false,
        }
    }
}

/// The client's address for a connection from `peer` with these headers.
pub fn client_ip(peer: IpAddr, headers: &HeaderMap, trusted: &[Cidr]) -> IpAddr {
    let peer = peer.to_canonical();
    let is_trusted = |ip: IpAddr| trusted.iter().any(|c| c.contains(ip));
    if !is_trusted(peer) {
        return peer;
    }
    let hops: Vec<&str> = headers
        .get_all("x-forwarded-for")
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .map(str::trim)
        .collect();
    let mut client = peer;
    for hop in hops.iter().rev() {
        // A hop that is not an address (garbled, `unknown`) ends the chain: the last trusted
        // hop is the best we know.
        let Ok(ip) = hop.parse::<IpAddr>().map(|ip| ip.to_canonical()) else {
            break;
        };
        client = ip;
        if !is_trusted(ip) {
            break;
        }
    }
    client
}

/// What a per-client limit counts `ip` under: an IPv4 address itself (an IPv4-mapped IPv6
/// address as its IPv4 one), an IPv6 address its /64 network (a host is commonly given a whole
/// /64: its addresses are one client's, and counted apart, a client would have 2^64 budgets).
pub fn limit_key(ip: IpAddr) -> IpAddr {
    match ip.to_canonical() {
        IpAddr::V6(v6) => IpAddr::V6(Ipv6Addr::from(u128::from(v6) & !(u64::MAX as u128))),
        v4 => v4,
    }
}

/// A [`limit_key`] in words: `10.4.7.30`, `2001:db8:1:2::/64`.
pub fn show_key(key: IpAddr) -> String {
    match key {
        IpAddr::V6(v6) => format!("{v6}/64"),
        v4 => v4.to_string(),
    }
}

/// Whether the request came to a trusted proxy over HTTPS (`X-Forwarded-Proto: https`).
pub fn forwarded_https(peer: IpAddr, headers: &HeaderMap, trusted: &[Cidr]) -> bool {
    trusted.iter().any(|c| c.contains(peer))
        && headers
            .get("x-forwarded-proto")
            .and_then(|v| v.to_str().ok())
            .is_some_and(|v| v.trim().eq_ignore_ascii_case("https"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn h(xff: &str) -> HeaderMap {
        let mut m = HeaderMap::new();
        m.insert("x-forwarded-for", xff.parse().unwrap());
        m
    }

    #[test]
    fn blocks_parse_and_contain_their_addresses() {
        let c: Cidr = "10.1.0.0/16".parse().unwrap();
        assert!(c.contains("10.1.200.3".parse().unwrap()));
        assert!(!c.contains("10.2.0.1".parse().unwrap()));
        assert!(c.contains("::ffff:10.1.0.9".parse().unwrap()), "IPv4-mapped");
        let one: Cidr = "127.0.0.1".parse().unwrap();
        assert!(one.contains("127.0.0.1".parse().unwrap()) && !one.contains("127.0.0.2".parse().unwrap()));
        let all: Cidr = "0.0.0.0/0".parse().unwrap();
        assert!(all.contains("8.8.8.8".parse().unwrap()));
        let v6: Cidr = "fd00::/8".parse().unwrap();
        assert!(v6.contains("fd12::1".parse().unwrap()) && !v6.contains("fe80::1".parse().unwrap()));
        assert!("10.0.0.0/33".parse::<Cidr>().unwrap_err().contains("[0, 32]"));
        assert!("lab".parse::<Cidr>().unwrap_err().contains("not an address"));
    }

    /// An IPv6 client is its /64; an IPv4 one (mapped or not) its address.
    #[test]
    fn a_limit_counts_an_ipv6_client_by_its_64() {
        let ip = |s: &str| s.parse::<IpAddr>().unwrap();
        assert_eq!(
            limit_key(ip("2001:db8:1:2:aaaa::1")),
            limit_key(ip("2001:db8:1:2:ffff::9"))
        );
        assert_ne!(limit_key(ip("2001:db8:1:2::1")), limit_key(ip("2001:db8:1:3::1")));
        assert_eq!(show_key(limit_key(ip("2001:db8:1:2:aaaa::1"))), "2001:db8:1:2::/64");
        assert_eq!(limit_key(ip("::ffff:10.4.7.30")), ip("10.4.7.30"));
        assert_eq!(show_key(limit_key(ip("10.4.7.30"))), "10.4.7.30");
    }

    #[test]
    fn forwarded_for_is_believed_only_from_a_trusted_proxy() {
        let proxy: IpAddr = "127.0.0.1".parse().unwrap();
        let trusted = ["127.0.0.1".parse().unwrap(), "10.9.0.0/16".parse().unwrap()];
        // From the proxy: the client it names.
        assert_eq!(
            client_ip(proxy, &h("192.168.5.7"), &trusted),
            "192.168.5.7".parse::<IpAddr>().unwrap()
        );
        // A client that forged a first hop: the proxy appended the real one, which wins.
        assert_eq!(
            client_ip(proxy, &h("1.2.3.4, 192.168.5.7"), &trusted),
            "192.168.5.7".parse::<IpAddr>().unwrap()
        );
        // Two proxies (the inner one trusted too): the address before them.
        assert_eq!(
            client_ip(proxy, &h("192.168.5.7, 10.9.1.1"), &trusted),
            "192.168.5.7".parse::<IpAddr>().unwrap()
        );
        // From anyone else, the header is ignored.
        let other: IpAddr = "192.168.5.8".parse().unwrap();
        assert_eq!(client_ip(other, &h("1.2.3.4"), &trusted), other);
        assert_eq!(client_ip(proxy, &h("1.2.3.4"), &[]), proxy, "no trusted proxy");
        // No header, or garbage: the proxy itself.
        assert_eq!(client_ip(proxy, &HeaderMap::new(), &trusted), proxy);
        assert_eq!(client_ip(proxy, &h("unknown"), &trusted), proxy);
    }
}
