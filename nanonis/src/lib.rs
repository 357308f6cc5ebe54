//! A SPECS Nanonis controller behind nanopush's instrument interface
//! ([`nanopush_instrument::afm::Microscope`]), over the vendor's TCP Programming Interface, and a
//! fake controller ([`fake`]) that speaks the same protocol for the tests.
//!
//! What runs where: the controller's own Z feedback holds the normal force; nanopush sends set
//! points and XY waypoints and reads the deflection from the TCP Logger stream (kHz) or, without
//! it, from polled reads averaged over the acquisition period (10-100 Hz). A force loop of 1 kHz
//! cannot be closed through polled reads, and nanopush does not try.

pub mod backend;
pub mod client;
pub mod commands;
pub mod fake;
pub mod logger;

pub use backend::{NanonisMicroscope, NanonisOptions, find_signal};

/// Parses `nanonis:HOST:PORT[,LOGPORT]` into the command address and the logger port.
pub fn parse_instrument(spec: &str) -> Result<(std::net::SocketAddr, Option<u16>), String> {
    let usage = "expected nanonis:HOST:PORT[,LOGPORT], e.g. nanonis:127.0.0.1:6501,6590";
    let rest = spec
        .strip_prefix("nanonis:")
        .ok_or_else(|| format!("--instrument {spec:?}: unknown backend; {usage} (the simulated AFM is the default)"))?;
    let (addr, log) = match rest.split_once(',') {
        Some((a, l)) => (a, Some(l)),
        None => (rest, None),
    };
    let port_of = |p: &str, what: &str| -> Result<u16, String> {
        p.parse::<u16>()
            .ok()
            .filter(|&p| p > 0)
            .ok_or_else(|| format!("--instrument {spec:?}: {what} {p:?} is not a port in [1, 65535]; {usage}"))
    };
    let (host, port) = addr
        .rsplit_once(':')
        .ok_or_else(|| format!("--instrument {spec:?}: no port; {usage}"))?;
    let port = port_of(port, "port")?;
    let addr = client::resolve(&format!("{host}:{port}")).map_err(|e| format!("--instrument {spec:?}: {e}"))?;
    let log = log.map(|l| port_of(l, "logger port")).transpose()?;
    Ok((addr, log))
}
