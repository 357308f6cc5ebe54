//! `nanopush`: the command line — the model and its studies (`model`, `simulate`, `sweep`,
//! `accuracy`), the instrument (`scan`, `push`), the teleoperation server (`serve`) and its
//! people (`token`).

mod accuracy_cmd;
mod assemble_cmd;
mod campaign_cmd;
mod extremes_cmd;
mod instrument_cmd;
mod model_cmd;
mod plan_cmd;
mod plot;
mod push_cmd;
mod scan_cmd;
mod serve_cmd;
mod simulate_cmd;
mod sweep_cmd;
mod token_cmd;
mod units;
mod whole_pushes;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use nanopush_instrument::scene::Scene;

/// Force-controlled AFM pushing of nanoparticles (Sitti & Hashimoto).
#[derive(Parser, Debug)]
#[command(name = "nanopush", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Print the scene's derived quantities (Eq 9-18), or its force curve (Fig 3).
    Model(model_cmd::ModelArgs),
    /// Simulate a push at constant stage speed (Eq 17) and report the result and the work done.
    Simulate(simulate_cmd::SimulateArgs),
    /// Error against run time for each method and tolerance (work-precision report).
    Accuracy(accuracy_cmd::AccuracyArgs),
    /// The settled particle y and ζ_z against α, β, μ_as^s or Rₐ (Figs 10-13), in parallel.
    Sweep(sweep_cmd::SweepArgs),
    /// Tapping-mode scan of the scene: a height image (GSF + PNG) and the particles located in it.
    Scan(scan_cmd::ScanArgs),
    /// One manipulation (Sec 2.1, Sec 3): scan, locate, plan, park, detect contact, push under
    /// force control, retract; the traces of Figs 9 and 15.
    Push(push_cmd::PushArgs),
    /// The push strategy derived from the scene's model, each setting with its reason (or why
    /// no strategy can push the particle, and the field to change).
    Plan(plan_cmd::PlanArgs),
    /// Particles pushed into a pattern (a file of sites, or a line, grid, ring or text): assigned,
    /// ordered and routed around each other, each move judged by the scan after it.
    Assemble(assemble_cmd::AssembleArgs),
    /// Random valid scenes nobody tuned: planned, pushed and judged (the plan's acceptance, ok
    /// within the tolerance, refusals by reason, cost); `--shard I/N` splits the seeds.
    Campaign(campaign_cmd::CampaignArgs),
    /// The teleoperation server: the 1 kHz control loop, the WebSocket protocol, the web client.
    // Boxed: its arguments are the most numerous (clippy's large_enum_variant).
    Serve(Box<serve_cmd::ServeArgs>),
    /// Named operators and viewers: `token add NAME --role R` (prints the token once),
    /// `token list`, `token revoke NAME` (its sessions on a running server are closed).
    Token(token_cmd::TokenArgs),
}

/// Loads `--scene FILE`, or the embedded default scene; prints its warnings to stderr.
pub fn load_scene(path: Option<&PathBuf>) -> anyhow::Result<Scene> {
    let scene = match path {
        // The error names the file already ("scene FILE: …", "cannot read scene file FILE: …").
        Some(p) => Scene::from_path(p)?,
        None => Scene::default_scene(),
    };
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    Ok(scene)
}

/// Writes the command's output; a closed pipe (`nanopush model | head`) is not an error.
fn print_stdout(text: &str) -> ExitCode {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: writing to stdout: {e}");
            ExitCode::from(2)
        }
    }
}

/// A refusal as the JSON a `--json` caller reads on stdout (the error still goes to stderr and
/// the exit status is 2): `{"schema", "outcome": "refused", "particle", "code", "reason",
/// "field", "advice"}`, `advice` a list of the values the field names, each `{"key", "value",
/// "checked"}` (`checked`: true when the plan passes with it, false when it and every value
/// further that way that was tried did not, null when not checked) and `tried`, the values
/// refused on the way with their codes.
fn refusal_json(schema: &str, e: &anyhow::Error) -> Option<String> {
    let r = e.downcast_ref::<nanopush_instrument::control::derive::Refusal>()?;
    let v = serde_json::json!({
        "schema": schema,
        "version": nanopush_proto::VERSION,
        "outcome": "refused",
        "particle": r.particle,
        "code": r.code,
        "reason": r.reason,
        "field": r.field,
        "advice": r.advice.iter().map(|a| serde_json::json!({
            "key": a.key.field(),
            "value": a.value,
            "checked": a.checked,
            "tried": a.tried.iter().map(|(v, code)| serde_json::json!({"value": v, "code": code})).collect::<Vec<_>>(),
        })).collect::<Vec<_>>(),
    });
    serde_json::to_string_pretty(&v).ok().map(|t| t + "\n")
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // Which command's refusal is printed as JSON (`plan`/`push` with `--json`).
    let json_refusal = match &cli.command {
        Command::Plan(a) if a.json => Some("plan"),
        Command::Push(a) if a.json => Some("push"),
        _ => None,
    };
    let result = match cli.command {
        Command::Model(args) => model_cmd::run(&args),
        Command::Simulate(args) => simulate_cmd::run(&args),
        Command::Accuracy(args) => accuracy_cmd::run(&args),
        Command::Sweep(args) => sweep_cmd::run(&args),
        Command::Scan(args) => scan_cmd::run(&args),
        Command::Plan(args) => plan_cmd::run(&args),
        Command::Campaign(args) => campaign_cmd::run(&args),
        Command::Assemble(args) => match assemble_cmd::run(&args) {
            // An assembly that ran reports first, then exits 1 (a site open) or 2 (refused).
            Ok((text, code)) if code != 0 => {
                let printed = print_stdout(&text);
                return if printed == ExitCode::SUCCESS {
                    ExitCode::from(code)
                } else {
                    printed
                };
            }
            Ok((text, _)) => Ok(text),
            Err(e) => Err(e),
        },
        Command::Push(args) => match push_cmd::run(&args) {
            // A push that ran but failed exits 1 after its report (docs/manipulation.md, "Outcomes
            // that say what happened").
            Ok((text, false)) => {
                let code = print_stdout(&text);
                return if code == ExitCode::SUCCESS {
                    ExitCode::from(push_cmd::EXIT_FAILED_PUSH)
                } else {
                    code
                };
            }
            Ok((text, true)) => Ok(text),
            Err(e) => Err(e),
        },
        Command::Serve(args) => serve_cmd::run(&args),
        Command::Token(args) => token_cmd::run(&args),
    };
    match result {
        Ok(text) => print_stdout(&text),
        Err(e) => {
            if let Some(text) = json_refusal.and_then(|schema| refusal_json(schema, &e)) {
                let _ = print_stdout(&text);
            }
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

/// `nanopush ARGS…` parsed by the real command line, for the subcommands' tests of their
/// defaults.
#[cfg(test)]
fn parse(args: &[&str]) -> Command {
    Cli::try_parse_from(std::iter::once("nanopush").chain(args.iter().copied()))
        .expect("arguments parse")
        .command
}
