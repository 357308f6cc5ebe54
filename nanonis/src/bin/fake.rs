//! `nanopush-fake-nanonis`: a fake Nanonis controller on 127.0.0.1 for trying nanopush without a
//! microscope, and for the end-to-end tests. Prints `command port P, logger port L` and serves
//! until killed.

use anyhow::Context;
use clap::Parser;
use nanopush_nanonis::fake::faults::Fault;
use nanopush_nanonis::fake::{FakeController, FakeOptions};

/// A fake Nanonis controller: the TCP Programming Interface's framing, a logger stream and a small
/// simulated microscope, with faults on demand.
#[derive(Parser, Debug)]
struct Args {
    /// Command port (0: any free one).
    #[arg(long, default_value_t = 6501)]
    port: u16,
    /// Logger stream port (0: any free one).
    #[arg(long, default_value_t = 6590)]
    logger_port: u16,
    /// The sample: a scene file (TOML); the embedded paper scene when absent.
    #[arg(long)]
    scene: Option<std::path::PathBuf>,
    /// Scan lines per second, in (0, 10000].
    #[arg(long, default_value_t = 400.0)]
    line_rate: f64,
    /// Logger frames per second, in [1, 5000].
    #[arg(long, default_value_t = 1000.0)]
    logger_rate_hz: f64,
    /// A fault, `KIND:COMMAND[:MS][*TIMES]` (slow, error, drop, wrong-name, short; or
    /// logger-drop:MS); repeatable.
    #[arg(long = "fault")]
    faults: Vec<Fault>,
}

fn main() -> anyhow::Result<()> {
    let a = Args::parse();
    if !(a.line_rate > 0.0 && a.line_rate <= 10_000.0) {
        anyhow::bail!(
            "--line-rate {} is out of range; allowed: (0, 10000] lines/s",
            a.line_rate
        );
    }
    if !(1.0..=5000.0).contains(&a.logger_rate_hz) {
        anyhow::bail!(
            "--logger-rate-hz {} is out of range; allowed: [1, 5000] Hz",
            a.logger_rate_hz
        );
    }
    let scene = match &a.scene {
        Some(p) => {
            let text = std::fs::read_to_string(p).with_context(|| format!("--scene {}", p.display()))?;
            nanopush_instrument::scene::Scene::parse(&p.display().to_string(), &text)?
        }
        None => nanopush_instrument::scene::Scene::default_scene(),
    };
    let fake = FakeController::start(FakeOptions {
        scene,
        line_rate: a.line_rate,
        logger_rate_hz: a.logger_rate_hz,
        faults: a.faults,
        port: a.port,
        logger_port: a.logger_port,
    })
    .context("listening on 127.0.0.1")?;
    println!(
        "command port {}, logger port {}",
        fake.addr().port(),
        fake.logger_port()
    );
    loop {
        std::thread::park();
    }
}
