//! `nanopush-haptic`: the 1-DOF haptic bridge.
//!
//! `nanopush-haptic --device sim|serial:PATH|none [--operator SCRIPT] [--duration S] [--trace
//! PATH.csv]` runs a device at its own rate (1 kHz default, up to 4 kHz): each cycle it reads the
//! handle, publishes its state to `nanopush serve` over iceoryx2, renders the server's newest
//! force (its local linear model, through the passivity controller and the device's clamp), and
//! writes the force. It exits 0 when a finite operator script ends, when `--duration` has passed,
//! or on SIGINT/SIGTERM (the force is zeroed first); 2 on a bad argument or a device that cannot
//! be used; 3 when the device was lost (an unplugged cable) and is not back at the end, or at
//! once with `--exit-on-device-loss`.
//!
//! `nanopush-haptic render` reads a force curve (`nanopush model --force-curve --json`) on stdin
//! and prints what the operator would feel under a scaling; `nanopush-haptic bench-transport`
//! measures the iceoryx2 link's one-way and round-trip latency between two processes.

mod bench;
mod run;

use std::io::Read;
use std::process::ExitCode;

use anyhow::{Context, bail};
use clap::{Parser, Subcommand};
use nanopush_haptic::scaling::Scaling;
use nanopush_proto::model::ForceCurveReport;

/// The nanopush 1-DOF haptic bridge.
#[derive(Parser, Debug)]
#[command(name = "nanopush-haptic", version, about, args_conflicts_with_subcommands = true)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    #[command(flatten)]
    run: run::RunArgs,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Render a force curve (JSON on stdin) as the operator would feel it through the handle.
    Render {
        /// Tip nanometres per handle millimetre.
        #[arg(long, default_value_t = 10.0)]
        nm_per_mm: f64,
        /// Hand newtons per tip nanonewton.
        #[arg(long, default_value_t = 0.1)]
        n_per_nn: f64,
        /// Peak force the device renders (N).
        #[arg(long, default_value_t = 3.0)]
        peak_n: f64,
    },
    /// Measure the iceoryx2 link between two processes (one-way and round trip).
    BenchTransport(bench::BenchArgs),
    /// Check a serial device against the protocol, one PASS/FAIL line per rule (exit 0 when
    /// every rule holds, 1 when one does not).
    Conformance {
        /// The device: `serial:PATH[@BAUD]`.
        device: String,
    },
}

/// Runs the conformance checks; the exit code says whether every one passed.
fn conformance(device: &str) -> ExitCode {
    let Some(arg) = device.strip_prefix("serial:") else {
        eprintln!("error: conformance checks a serial device: serial:PATH[@BAUD], got {device:?}");
        return ExitCode::from(2);
    };
    match nanopush_haptic::serial::conformance::run(arg) {
        Ok(checks) => {
            let failed = checks.iter().filter(|c| !c.pass).count();
            let mut text: String = checks.iter().map(|c| format!("{c}\n")).collect();
            text += &format!("{} checks, {failed} failed\n", checks.len());
            let _ = print(&text);
            if failed == 0 {
                ExitCode::SUCCESS
            } else {
                ExitCode::from(1)
            }
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(2)
        }
    }
}

fn render(nm_per_mm: f64, n_per_nn: f64, peak_n: f64) -> anyhow::Result<String> {
    let scaling = Scaling::new(nm_per_mm * 1e-9 / 1e-3, n_per_nn / 1e-9, peak_n)?;
    let mut input = String::new();
    std::io::stdin()
        .read_to_string(&mut input)
        .context("reading the force curve from stdin")?;
    let curve: ForceCurveReport =
        serde_json::from_str(&input).context("stdin is not the JSON of `nanopush model --force-curve --json`")?;
    if curve.schema != "nanopush.force_curve" || curve.version != nanopush_proto::VERSION {
        bail!(
            "expected schema nanopush.force_curve version {}, got {} version {}",
            nanopush_proto::VERSION,
            curve.schema,
            curve.version
        );
    }
    let mut out = String::from("branch,handle_mm,hand_force_n,tip_force_nn\n");
    for (branch, pts) in [("approach", &curve.approach), ("retraction", &curve.retraction)] {
        for p in pts {
            let handle_mm = scaling.handle_position(p.distance) * 1e3;
            out += &format!(
                "{branch},{handle_mm:.6},{:.6},{:.6}\n",
                scaling.hand_force(p.force),
                p.force * 1e9
            );
        }
    }
    Ok(out)
}

fn print(text: &str) -> ExitCode {
    use std::io::Write;
    let mut o = std::io::stdout().lock();
    match o.write_all(text.as_bytes()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(2)
        }
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Some(Command::Render {
            nm_per_mm,
            n_per_nn,
            peak_n,
        }) => render(nm_per_mm, n_per_nn, peak_n),
        Some(Command::BenchTransport(a)) => bench::run(&a),
        Some(Command::Conformance { device }) => return conformance(&device),
        None => run::run(&cli.run),
    };
    match result {
        Ok(text) => print(&text),
        Err(e) if e.downcast_ref::<run::DeviceLostAtEnd>().is_some() => {
            let lost = e.downcast_ref::<run::DeviceLostAtEnd>().expect("checked");
            eprintln!("error: {lost}");
            let _ = print(&lost.summary);
            ExitCode::from(3)
        }
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}
