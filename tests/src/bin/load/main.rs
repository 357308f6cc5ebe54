//! `nanopush-load`: a load benchmark of `nanopush serve`. A benchmark, not a test: it measures
//! and prints, and asserts nothing about timing.
//!
//! For each level of viewers it starts a fresh server (so the server's histograms and maximum
//! cover that level only), connects N WebSocket viewers that subscribe to `tip`, scrapes
//! `/metrics` once every viewer is subscribed and again at the end of the measuring window, and
//! reports from the difference of the two scrapes: the control loop's period error (p50 and p99
//! as bucket upper bounds, the bucket holding the largest value, the mean), overruns and ticks;
//! per client, the telemetry rate delivered and the frames skipped (`lagged`). The maximum from
//! `/api/status` covers the server's whole life, connection setup included. Then it sends the
//! server SIGTERM and waits for it.
//!
//! The viewers run in this process on one tokio current-thread runtime: the benchmark shares the
//! machine's cores with the server it measures, and its figures include that cost. The CPU time
//! of the server, of its control-loop thread, of this process and of everything else on the
//! machine over the window is read from `/proc` and printed with the figures.

mod cpu;
mod level;
mod prometheus;
mod report;
mod server;
mod viewers;

use std::path::PathBuf;
use std::time::Duration;

use serde_json::json;

use level::run_level;
use report::{level_json, print_tables};

/// The operator token the server is started with (the viewers need none).
const TOKEN: &str = "nanopush-load-operator-token";
/// Viewers connecting at once (the rest wait their turn).
const CONNECT_CONCURRENCY: usize = 32;
/// The period-error threshold the goal in docs/benchmarks.md ("Load: `nanopush-load`") names (s); a bucket bound of the histogram.
const GOAL_P99_S: f64 = 20e-6;

const USAGE: &str = "\
nanopush-load: load benchmark of `nanopush serve` (a benchmark: it asserts nothing)

Usage: nanopush-load [--viewers 50,200,500] [--seconds 30] [--rate-hz 1000]
                     [--server target/release/nanopush] [--allow-cpu-halt] [--json]

  --viewers LIST   levels of WebSocket viewers, comma-separated (a fresh server for each;
                   0 is a baseline: the server alone)
  --seconds S      measuring window per level, after every viewer has subscribed (default 30)
  --rate-hz HZ     control loop rate passed to the server (default 1000)
  --server PATH    the nanopush binary (default: this workspace's target/release/nanopush)
  --allow-cpu-halt passed to the server: idle cores may halt (no zero CPU latency request)
  --json           print one JSON document instead of tables (progress still goes to stderr)
";

/// The command line.
#[derive(Debug, Clone)]
pub struct Opts {
    pub viewers: Vec<usize>,
    pub seconds: f64,
    pub rate_hz: f64,
    pub server: PathBuf,
    pub allow_cpu_halt: bool,
    pub json: bool,
}

/// The options from the command line, checked.
fn parse_args() -> Result<Opts, String> {
    let mut o = Opts {
        viewers: vec![50, 200, 500],
        seconds: 30.0,
        rate_hz: 1000.0,
        server: nanopush_e2e::workspace().join("target/release/nanopush"),
        allow_cpu_halt: false,
        json: false,
    };
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let (key, inline) = match a.split_once('=') {
            Some((k, v)) => (k.to_string(), Some(v.to_string())),
            None => (a.clone(), None),
        };
        let mut value = |name: &str| {
            inline
                .clone()
                .or_else(|| args.next())
                .ok_or_else(|| format!("{name} needs a value\n\n{USAGE}"))
        };
        match key.as_str() {
            "--viewers" => {
                o.viewers = value("--viewers")?
                    .split(',')
                    .map(|v| v.trim().parse::<usize>().map_err(|e| format!("--viewers {v:?}: {e}")))
                    .collect::<Result<_, _>>()?;
            }
            "--seconds" => o.seconds = value("--seconds")?.parse().map_err(|e| format!("--seconds: {e}"))?,
            "--rate-hz" => o.rate_hz = value("--rate-hz")?.parse().map_err(|e| format!("--rate-hz: {e}"))?,
            "--server" => o.server = PathBuf::from(value("--server")?),
            "--allow-cpu-halt" => o.allow_cpu_halt = true,
            "--json" => o.json = true,
            "-h" | "--help" => {
                print!("{USAGE}");
                std::process::exit(0);
            }
            _ => return Err(format!("unknown argument {a:?}\n\n{USAGE}")),
        }
    }
    if o.viewers.is_empty() || o.viewers.iter().any(|&n| n > 1900) {
        return Err("--viewers: each level must be in [0, 1900] (the server runs with --max-clients 2000)".into());
    }
    if !(1.0..=3600.0).contains(&o.seconds) {
        return Err(format!("--seconds {} is out of range; allowed: [1, 3600]", o.seconds));
    }
    if !(100.0..=10_000.0).contains(&o.rate_hz) {
        return Err(format!(
            "--rate-hz {} is out of range; allowed: [100, 10000]",
            o.rate_hz
        ));
    }
    if !o.server.exists() {
        return Err(format!(
            "no server binary at {}; build it with `cargo build --release -p nanopush-instrument` or pass --server",
            o.server.display()
        ));
    }
    Ok(o)
}

fn main() {
    let o = match parse_args() {
        Ok(o) => o,
        Err(e) => {
            eprintln!("nanopush-load: {e}");
            std::process::exit(2);
        }
    };
    let cpus = std::thread::available_parallelism().map_or(1, usize::from);
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("building the tokio runtime");
    let mut levels = Vec::new();
    for (i, &n) in o.viewers.iter().enumerate() {
        if i > 0 {
            // Let the previous level's sockets and threads go.
            std::thread::sleep(Duration::from_secs(2));
        }
        match rt.block_on(run_level(&o, n)) {
            Ok(l) => levels.push(l),
            Err(e) => {
                eprintln!("nanopush-load: {n} viewers: {e}");
                std::process::exit(1);
            }
        }
    }
    if o.json {
        let doc = json!({
            "schema": "nanopush-load",
            "version": 1,
            "cpus": cpus,
            "rate_hz": o.rate_hz,
            "seconds": o.seconds,
            "note": "the viewers run in this process, on the same cores as the server",
            "levels": levels.iter().map(level_json).collect::<Vec<_>>(),
        });
        println!("{}", serde_json::to_string_pretty(&doc).expect("serializing"));
    } else {
        print_tables(&o, cpus, &levels);
    }
}
