//! `nanopush serve`: the teleoperation server.

use std::io::{Read as _, Write as _};
use std::net::{IpAddr, SocketAddr};
use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Args;
use nanopush_server::app_state::{AccessConfig, ServeConfig};
use nanopush_server::auth::TokenFile;
use nanopush_server::auth::tokens::TokenTable;
use nanopush_server::client_addr::Cidr;
use nanopush_server::control_loop::LoopConfig;
use nanopush_server::haptic::HapticMode;
use nanopush_server::tls::{self, TlsSource};

/// Arguments of `nanopush serve`.
#[derive(Args, Debug)]
pub struct ServeArgs {
    /// Scene file (TOML); the embedded paper scene when absent.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Address to bind; loopback by default (anything else exposes the instrument).
    #[arg(long, default_value = "127.0.0.1")]
    bind: IpAddr,
    /// Port (0: any free port).
    #[arg(long, default_value_t = 8080)]
    port: u16,
    /// Control loop rate (Hz), in [100, 10000].
    #[arg(long, default_value_t = 1000.0)]
    rate_hz: f64,
    /// Operator token (else NANOPUSH_OPERATOR_TOKEN, else generated and printed in the URL).
    #[arg(long)]
    operator_token: Option<String>,
    /// Viewer token; when absent viewers need none.
    #[arg(long)]
    viewer_token: Option<String>,
    /// Named operators and viewers, one hashed token each (`nanopush token add NAME --role R`);
    /// then every connection needs a token of the file (the generated one is not accepted), and
    /// the file is re-read when it changes (a change is applied once the file has been stable
    /// for 1 s: a revoked token's sessions are closed within about 1.5 s).
    #[arg(long, conflicts_with_all = ["operator_token", "viewer_token"])]
    token_file: Option<PathBuf>,
    /// A reverse proxy whose X-Forwarded-For names the real client (repeatable; an address or a
    /// CIDR block, e.g. 127.0.0.1 or 10.0.0.0/8). From any other peer the header is ignored.
    #[arg(long)]
    trusted_proxy: Vec<String>,
    /// HTTPS with this certificate chain (PEM, leaf first), with --tls-key.
    #[arg(long, requires = "tls_key")]
    tls_cert: Option<PathBuf>,
    /// The private key (PEM) of --tls-cert.
    #[arg(long, requires = "tls_cert")]
    tls_key: Option<PathBuf>,
    /// HTTPS with a self-signed certificate for a lab without a CA: made on the first start
    /// (kept in tls/ of --data-dir), its SHA-256 fingerprint printed at each start for people to
    /// compare with what their browser shows.
    #[arg(long, conflicts_with_all = ["tls_cert", "tls_key"])]
    tls_self_signed: bool,
    /// Another browser origin allowed to connect (repeatable), e.g. http://lab-display:3000.
    #[arg(long)]
    allow_origin: Vec<String>,
    /// Largest client message (bytes), in [256, 1048576]. The default holds an `assemble` of the
    /// most sites (400, about 22 kB as the page writes them).
    #[arg(long, default_value_t = 32768)]
    max_message_bytes: usize,
    /// Messages per second per connection, in [1, 10000].
    #[arg(long, default_value_t = 50.0)]
    max_rate: f64,
    /// Most viewer connections at once, in [1, 100000] (the operator token has 8 more places of
    /// its own: viewers never lock the operator out).
    #[arg(long, default_value_t = 1000)]
    max_clients: u64,
    /// Most viewer connections from one remote address, in [1, 100000].
    #[arg(long, default_value_t = 64)]
    max_clients_per_address: u64,
    /// Most TCP connections at once, counted before anything is read, in [64, 10000000]
    /// (default: the open-files limit less 272, kept for the server's own files and the lease
    /// holder's room). One past it is reset unread.
    #[arg(long)]
    max_connections: Option<u64>,
    /// Most TCP connections at once from one address, before anything is read, in [1, 100000]
    /// (a --trusted-proxy is not held to it; the lease holder's address has 16 more).
    #[arg(long, default_value_t = 128)]
    max_connections_per_address: u64,
    /// An HTTP request's headers must arrive within this long (s), in [0.1, 300].
    #[arg(long, default_value_t = 10.0)]
    header_timeout_s: f64,
    /// A WebSocket ping every this long (s), in [0.1, 300].
    #[arg(long, default_value_t = 10.0)]
    ws_ping_s: f64,
    /// A WebSocket peer silent (no pong, nothing) for longer than this is closed (s), in
    /// [0.2, 3600]; at least twice --ws-ping-s.
    #[arg(long, default_value_t = 30.0)]
    ws_timeout_s: f64,
    /// Directory of the records (push traces, scans).
    #[arg(long, default_value = "records")]
    data_dir: PathBuf,
    /// The audit log's files (DATA/audit/audit.jsonl and its older parts .1 to .3) hold at most
    /// this many bytes in all, in [65536, 2^50]: past a quarter of it audit.jsonl is rotated, and
    /// the oldest part deleted (1 GiB by default).
    #[arg(long, default_value_t = nanopush_server::audit::MAX_BYTES_DEFAULT)]
    audit_max_bytes: u64,
    /// Directory of the web client; `web/` of this workspace when absent.
    #[arg(long)]
    web_dir: Option<PathBuf>,
    /// Scan line rate (lines per second), in [0.1, 1000].
    #[arg(long, default_value_t = 32.0)]
    scan_line_hz: f64,
    /// Telemetry rate to browsers (Hz), in [1, 1000].
    #[arg(long, default_value_t = 60.0)]
    telemetry_hz: f64,
    /// Do not ask for SCHED_FIFO, CPU affinity and a loop core that polls.
    #[arg(long)]
    no_realtime: bool,
    /// Let the loop's core halt between ticks (its PM QoS resume latency is left as it is). Saves
    /// power; a halted core can wake the loop late.
    #[arg(long)]
    allow_cpu_halt: bool,
    /// CPU core for the control loop (default: the last one).
    #[arg(long)]
    cpu: Option<usize>,
    /// The haptic link: `none` (default), `external` (wait for a bridge started separately,
    /// e.g. `nanopush-haptic --device serial:/dev/ttyACM0`), or `sim` (run and supervise a
    /// simulated bridge).
    #[arg(long, default_value = "none", value_parser = ["none", "external", "sim"])]
    haptic: String,
    /// The bridge binary for `--haptic sim` (default: `nanopush-haptic` next to this binary).
    #[arg(long)]
    haptic_bin: Option<PathBuf>,
    /// The haptic link is declared down (z frozen, tip parked) within this long of the last
    /// handle sample (ms), in [2, 1000].
    #[arg(long, default_value_t = 5.0)]
    haptic_timeout_ms: f64,
    #[command(flatten)]
    instrument: crate::instrument_cmd::InstrumentArgs,
}

fn in_range(name: &str, v: f64, lo: f64, hi: f64, unit: &str) -> anyhow::Result<()> {
    if !(v.is_finite() && v >= lo && v <= hi) {
        bail!("{name} {v} is out of range; allowed: [{lo}, {hi}]{unit}");
    }
    Ok(())
}

/// 128 random bits as hex, from the kernel.
fn random_token() -> anyhow::Result<String> {
    let mut b = [0u8; 16];
    std::fs::File::open("/dev/urandom")
        .and_then(|mut f| f.read_exact(&mut b))
        .context("reading /dev/urandom for the operator token")?;
    Ok(b.iter().map(|x| format!("{x:02x}")).collect())
}

/// Restricts the calling thread (and the threads it starts afterwards) to every CPU but `cpu`
/// (best effort: a refusal leaves it as is).
fn avoid_cpu(cpu: usize, ncpu: usize) {
    // SAFETY: a zeroed cpu_set_t is a valid empty set; CPU_SET and sched_setaffinity act on the
    // calling thread with a set of the size we pass.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        for c in (0..ncpu).filter(|&c| c != cpu) {
            libc::CPU_SET(c, &mut set);
        }
        libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set);
    }
}

/// `--haptic` as the server runs it; `sim` needs the bridge binary.
fn haptic_mode(a: &ServeArgs) -> anyhow::Result<HapticMode> {
    Ok(match a.haptic.as_str() {
        "sim" => {
            let bin = match &a.haptic_bin {
                Some(b) => b.clone(),
                None => std::env::current_exe()
                    .context("finding this executable")?
                    .with_file_name("nanopush-haptic"),
            };
            if !bin.is_file() {
                bail!(
                    "--haptic sim: the bridge {} is missing (build it: cargo build --release -p nanopush-haptic, or give --haptic-bin)",
                    bin.display()
                );
            }
            HapticMode::Sim(bin)
        }
        "external" => HapticMode::External,
        _ => HapticMode::None,
    })
}

/// The arguments' ranges and the combinations refused (exit 2 before anything starts).
fn check(a: &ServeArgs) -> anyhow::Result<()> {
    in_range("--rate-hz", a.rate_hz, 100.0, 10_000.0, " Hz")?;
    in_range(
        "--max-message-bytes",
        a.max_message_bytes as f64,
        256.0,
        1_048_576.0,
        " bytes",
    )?;
    in_range("--max-rate", a.max_rate, 1.0, 10_000.0, " messages/s")?;
    in_range("--max-clients", a.max_clients as f64, 1.0, 100_000.0, "")?;
    in_range(
        "--max-clients-per-address",
        a.max_clients_per_address as f64,
        1.0,
        100_000.0,
        "",
    )?;
    if let Some(n) = a.max_connections {
        in_range("--max-connections", n as f64, 64.0, 10_000_000.0, "")?;
    }
    in_range(
        "--max-connections-per-address",
        a.max_connections_per_address as f64,
        1.0,
        100_000.0,
        "",
    )?;
    in_range("--header-timeout-s", a.header_timeout_s, 0.1, 300.0, " s")?;
    in_range("--ws-ping-s", a.ws_ping_s, 0.1, 300.0, " s")?;
    in_range("--ws-timeout-s", a.ws_timeout_s, 0.2, 3600.0, " s")?;
    if a.ws_timeout_s < 2.0 * a.ws_ping_s {
        bail!(
            "--ws-timeout-s {} must be at least twice --ws-ping-s {} (a peer gets two pings to answer)",
            a.ws_timeout_s,
            a.ws_ping_s
        );
    }
    if !(nanopush_server::audit::MAX_BYTES_MIN..=1 << 50).contains(&a.audit_max_bytes) {
        bail!(
            "--audit-max-bytes {} is out of range; allowed: [{}, {}] bytes",
            a.audit_max_bytes,
            nanopush_server::audit::MAX_BYTES_MIN,
            1u64 << 50
        );
    }
    in_range("--scan-line-hz", a.scan_line_hz, 0.1, 1000.0, " Hz")?;
    in_range("--telemetry-hz", a.telemetry_hz, 1.0, 1000.0, " Hz")?;
    in_range("--haptic-timeout-ms", a.haptic_timeout_ms, 2.0, 1000.0, " ms")?;
    if a.haptic != "none" && a.rate_hz < 500.0 {
        bail!(
            "--haptic {} needs --rate-hz of at least 500 Hz (the bridge zeroes its force when the server's samples are 4 ms apart); got {}",
            a.haptic,
            a.rate_hz
        );
    }
    Ok(())
}

/// `--token-file` (read now: a broken file stops the start, naming its line) and
/// `--trusted-proxy`.
fn access(a: &ServeArgs) -> anyhow::Result<AccessConfig> {
    let token_file = match &a.token_file {
        Some(path) => {
            let table = TokenTable::read(path, false).context("--token-file")?;
            if table.entries.is_empty() {
                bail!(
                    "--token-file {}: no tokens in it; add one with `nanopush token add NAME --role operator --token-file {}`",
                    path.display(),
                    path.display()
                );
            }
            Some(TokenFile {
                path: path.clone(),
                table,
            })
        }
        None => None,
    };
    let trusted_proxies = a
        .trusted_proxy
        .iter()
        .map(|s| s.parse::<Cidr>().map_err(|e| anyhow::anyhow!("--trusted-proxy {e}")))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let source = match (&a.tls_cert, &a.tls_key, a.tls_self_signed) {
        (Some(cert), Some(key), _) => Some(TlsSource::Files {
            cert: cert.clone(),
            key: key.clone(),
        }),
        (_, _, true) => {
            // The names a browser on the lab's network may use: this host's, loopback, and the
            // bound address.
            let mut names = vec!["localhost".to_string(), "127.0.0.1".into(), "::1".into()];
            if let Ok(h) = std::fs::read_to_string("/proc/sys/kernel/hostname") {
                names.push(h.trim().to_string());
            }
            if !a.bind.is_unspecified() {
                names.push(a.bind.to_string());
            }
            names.dedup();
            Some(TlsSource::SelfSigned {
                dir: a.data_dir.join("tls"),
                names,
            })
        }
        _ => None,
    };
    let tls = source.map(|s| tls::load(&s)).transpose().context("TLS")?;
    Ok(AccessConfig {
        token_file,
        trusted_proxies,
        tls,
    })
}

/// A real controller for the server: telemetry at its feed rate, Stop and shutdown withdraw the
/// tip; pushes, scans, assemblies and the haptic force loop stay on the simulated AFM.
fn connect_instrument(a: &ServeArgs, spec: &str) -> anyhow::Result<nanopush_server::instrument_loop::RealInstrument> {
    if a.haptic != "none" {
        bail!(
            "--haptic {} with --instrument: the haptic force loop needs the force every millisecond from the simulated AFM's 1 kHz loop; on a real controller it is not offered",
            a.haptic
        );
    }
    if a.instrument.frame_um.is_some() {
        bail!(
            "--frame-um is for nanopush scan and push; the server scans the controller's own frame, or the square a client's scan command gives"
        );
    }
    // Checked though the server locates nothing with them: a value out of range is a mistake.
    crate::instrument_cmd::tip(&a.instrument)?;
    let m = crate::instrument_cmd::connect(&a.instrument, spec, 20e-6)?;
    Ok(nanopush_server::instrument_loop::RealInstrument::new(Box::new(m)))
}

/// Runs the server until SIGINT or SIGTERM.
pub fn run(a: &ServeArgs) -> anyhow::Result<String> {
    check(a)?;
    let scene = crate::load_scene(a.scene.as_ref())?;
    let operator_token = match a
        .operator_token
        .clone()
        .or_else(|| std::env::var("NANOPUSH_OPERATOR_TOKEN").ok())
    {
        Some(t) if t.len() >= 8 => t,
        Some(_) => bail!("the operator token must be at least 8 characters"),
        None => random_token()?,
    };
    let web_dir = a.web_dir.clone().unwrap_or_else(|| {
        let here = PathBuf::from("web");
        if here.join("index.html").exists() {
            here
        } else {
            PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../web"))
        }
    });
    let access = access(a)?;
    let tls_note = access.tls.as_ref().map(|t| {
        format!(
            "TLS certificate {} SHA-256 fingerprint {}",
            t.cert_path.display(),
            t.fingerprint
        )
    });
    let instrument = match &a.instrument.instrument {
        None => None,
        Some(spec) => Some(std::sync::Arc::new(connect_instrument(a, spec)?)),
    };
    let instrument_note = instrument.as_ref().map(|real| {
        format!(
            "instrument: {}, signals at {:.0} Hz{}",
            real.caps.backend,
            real.caps.feed_rate_hz,
            if real.caps.read_only { ", read-only" } else { "" }
        )
    });
    let cfg = ServeConfig {
        instrument,
        operator_token,
        viewer_token: a.viewer_token.clone(),
        allow_origins: a.allow_origin.clone(),
        max_message_bytes: a.max_message_bytes,
        max_rate: a.max_rate,
        max_clients: a.max_clients,
        max_clients_per_address: a.max_clients_per_address,
        max_connections: a.max_connections,
        max_connections_per_address: a.max_connections_per_address,
        ws_ping: std::time::Duration::from_secs_f64(a.ws_ping_s),
        ws_timeout: std::time::Duration::from_secs_f64(a.ws_timeout_s),
        header_timeout: std::time::Duration::from_secs_f64(a.header_timeout_s),
        data_dir: a.data_dir.clone(),
        audit_max_bytes: a.audit_max_bytes,
        web_dir,
        scan_line_hz: a.scan_line_hz,
        telemetry_hz: a.telemetry_hz,
        haptic: haptic_mode(a)?,
        access,
    };
    let loop_cfg = LoopConfig {
        rate_hz: a.rate_hz,
        realtime: !a.no_realtime,
        cpu: a.cpu,
        no_halt: !a.allow_cpu_halt,
        haptic: a.haptic != "none",
        haptic_timeout: std::time::Duration::from_secs_f64(a.haptic_timeout_ms * 1e-3),
    };
    tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info,iceoryx2=warn".into()),
        )
        .try_init()
        .ok();
    let bind = SocketAddr::new(a.bind, a.port);
    // Everything but the control loop stays off the loop's core when there is another one: this
    // thread is restricted before it starts any other, and every thread inherits its mask (the
    // tokio workers and blocking pool, the recorder, the haptic monitor, scans), including the
    // accept loop, which runs here in `block_on`. The loop then pins itself to its core.
    let ncpu = std::thread::available_parallelism().map_or(1, |n| n.get());
    let loop_cpu = a.cpu.unwrap_or(ncpu - 1).min(ncpu - 1);
    if !a.no_realtime && ncpu > 1 {
        avoid_cpu(loop_cpu, ncpu);
    }
    // One worker per CPU the runtime may use (tokio counts them from the mask): two workers
    // sharing one core made the operator's telemetry wait for the scheduler to switch between
    // them (60 s soaks: p99 gap +4.6 ms beyond the period with two, +1.6 ms with one). Work that takes
    // long (a push's preparation, a scan) runs on threads of its own.
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the tokio runtime")?;
    rt.block_on(async move {
        // The handlers are installed before the loop starts (and takes its core): a signal
        // during the start ends the server as one later does, its core given back. SIGHUP (its
        // terminal or ssh session closed) too.
        use tokio::signal::unix::{SignalKind, signal};
        let mut term = signal(SignalKind::terminate()).context("installing the SIGTERM handler")?;
        let mut int = signal(SignalKind::interrupt()).context("installing the SIGINT handler")?;
        let mut hup = signal(SignalKind::hangup()).context("installing the SIGHUP handler")?;
        let shutdown = async move {
            tokio::select! {
                _ = int.recv() => tracing::info!("SIGINT"),
                _ = term.recv() => tracing::info!("SIGTERM"),
                _ = hup.recv() => tracing::info!("SIGHUP"),
            }
        };
        nanopush_server::run(
            scene,
            cfg,
            loop_cfg,
            bind,
            |s| {
                let mut out = std::io::stdout().lock();
                let _ = writeln!(out, "nanopush serve: listening on {}", s.addr);
                let _ = writeln!(out, "open {}", s.url);
                if let Some(note) = &tls_note {
                    let _ = writeln!(out, "{note}");
                }
                if let Some(note) = &instrument_note {
                    let _ = writeln!(out, "{note}");
                }
                let _ = out.flush();
            },
            shutdown,
        )
        .await?;
        anyhow::Ok(())
    })?;
    Ok(String::new())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Command;

    fn parse(args: &[&str]) -> ServeArgs {
        let argv: Vec<&str> = std::iter::once("serve").chain(args.iter().copied()).collect();
        let Command::Serve(a) = crate::parse(&argv) else {
            unreachable!("`serve` parses as Serve")
        };
        *a
    }

    /// docs/server.md, "The teleoperation server": the synopsis's defaults, `--bind 127.0.0.1
    /// --port 8080 --rate-hz 1000 --max-message-bytes 32768 --max-rate 50 --max-clients 1000
    /// --max-clients-per-address 64 --header-timeout-s 10 --ws-ping-s 10 --ws-timeout-s 30
    /// --data-dir records --scan-line-hz 32 --telemetry-hz 60 --haptic none
    /// --haptic-timeout-ms 5`, and that they pass the range checks.
    #[test]
    fn serve_defaults_are_the_documented_synopsis() {
        let a = parse(&[]);
        assert_eq!(a.bind, IpAddr::from([127, 0, 0, 1]));
        assert_eq!(a.port, 8080);
        assert_eq!(a.rate_hz, 1000.0);
        assert_eq!(a.max_message_bytes, 32768);
        assert_eq!(a.max_rate, 50.0);
        assert_eq!(a.max_clients, 1000);
        assert_eq!(a.max_clients_per_address, 64);
        assert_eq!(a.header_timeout_s, 10.0);
        assert_eq!(a.ws_ping_s, 10.0);
        assert_eq!(a.ws_timeout_s, 30.0);
        assert_eq!(a.data_dir, PathBuf::from("records"));
        assert_eq!(a.scan_line_hz, 32.0);
        assert_eq!(a.telemetry_hz, 60.0);
        assert_eq!(a.haptic, "none");
        assert_eq!(a.haptic_timeout_ms, 5.0);
        assert_eq!(a.haptic_timeout_ms, nanopush_server::haptic::DEFAULT_TIMEOUT_MS);
        // Real-time by default, idle cores polling with it.
        assert!(!a.no_realtime && !a.allow_cpu_halt);
        check(&a).unwrap();
    }

    /// docs/haptics.md, "Faults": "`--haptic` needs a loop of at least 500 Hz": refused at 499 Hz
    /// with either link, accepted at 500 Hz; without a link any rate in [100, 10000] Hz is fine.
    #[test]
    fn haptic_is_refused_on_a_loop_too_slow_for_it() {
        for link in ["external", "sim"] {
            let e = check(&parse(&["--haptic", link, "--rate-hz", "499"])).unwrap_err();
            assert!(e.to_string().contains("at least 500 Hz"), "{e}");
            check(&parse(&["--haptic", link, "--rate-hz", "500"])).unwrap();
        }
        check(&parse(&["--rate-hz", "100"])).unwrap();
    }

    /// docs/deployment.md: a token file excludes the generated tokens, a certificate needs its
    /// key, a self-signed certificate excludes given files, and a bad `--trusted-proxy` or a
    /// missing or empty token file stops the start with what was wrong.
    #[test]
    fn access_flags_are_checked_before_the_start() {
        let refused = |args: &[&str]| {
            let argv = std::iter::once("nanopush")
                .chain(std::iter::once("serve"))
                .chain(args.iter().copied());
            <crate::Cli as clap::Parser>::try_parse_from(argv).is_err()
        };
        assert!(refused(&["--token-file", "t", "--operator-token", "abcdefgh"]));
        assert!(refused(&["--token-file", "t", "--viewer-token", "abcdefgh"]));
        assert!(refused(&["--tls-cert", "c.pem"]));
        assert!(refused(&["--tls-key", "k.pem"]));
        assert!(refused(&[
            "--tls-self-signed",
            "--tls-cert",
            "c.pem",
            "--tls-key",
            "k.pem"
        ]));
        let e = access(&parse(&["--trusted-proxy", "10.0.0.0/40"])).unwrap_err();
        assert!(
            e.to_string().contains("--trusted-proxy") && e.to_string().contains("[0, 32]"),
            "{e}"
        );
        let dir = std::env::temp_dir().join(format!("nanopush-access-flags-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("tokens");
        let e = access(&parse(&["--token-file", file.to_str().unwrap()])).unwrap_err();
        assert!(format!("{e:#}").contains("No such file"), "{e:#}");
        std::fs::write(&file, "# nobody yet\n").unwrap();
        let e = access(&parse(&["--token-file", file.to_str().unwrap()])).unwrap_err();
        assert!(e.to_string().contains("no tokens in it"), "{e}");
        let a = access(&parse(&[
            "--trusted-proxy",
            "127.0.0.1",
            "--trusted-proxy",
            "10.0.0.0/8",
        ]))
        .unwrap();
        assert_eq!(a.trusted_proxies.len(), 2);
        assert!(a.token_file.is_none() && a.tls.is_none());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
