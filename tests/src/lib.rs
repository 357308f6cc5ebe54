//! Helpers for the end-to-end tests and the benchmarks (`nanopush-load`, `nanopush-soak`,
//! `nanopush-haptic-latency`): find the workspace's real binaries (building them if they are
//! missing) and run them; start and stop their processes ([`process`]); talk to a running
//! `nanopush serve` ([`client`]); run one cell of the haptic grid with the real processes
//! ([`haptic_grid`]); read its Prometheus exposition ([`metrics`]) and the kernel's
//! accounts of it ([`procfs`]).
#![deny(missing_docs)]

pub mod client;
pub mod haptic_grid;
pub mod layers;
pub mod metrics;
pub mod process;
pub mod procfs;

use std::io::Write;
use std::path::PathBuf;
use std::process::{Command, Output, Stdio};
use std::sync::Once;

pub use process::{Proc, listening_addr, sigterm, stop};

/// The workspace root.
pub fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ is inside the workspace")
        .to_path_buf()
}

fn target_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace().join("target"))
}

static BUILD: Once = Once::new();

/// Path of a workspace binary in the profile these tests were built with. The binaries are
/// built once per test run (`cargo build --bins`), so a stale binary is never tested.
pub fn bin(name: &str) -> PathBuf {
    let release = !cfg!(debug_assertions);
    BUILD.call_once(|| {
        let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
        let mut cmd = Command::new(cargo);
        cmd.current_dir(workspace())
            .args(["build", "--workspace", "--bins", "--quiet"]);
        if release {
            cmd.arg("--release");
        }
        let status = cmd.status().expect("running cargo build for the end-to-end tests");
        assert!(status.success(), "cargo build --workspace --bins failed");
    });
    let path = target_dir().join(if release { "release" } else { "debug" }).join(name);
    assert!(path.exists(), "{} was not built", path.display());
    path
}

/// Runs a workspace binary with arguments and optional stdin, from the workspace root.
pub fn run(name: &str, args: &[&str], stdin: Option<&[u8]>) -> Output {
    let mut child = Command::new(bin(name))
        .current_dir(workspace())
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("starting {name}: {e}"));
    {
        let mut pipe = child.stdin.take().expect("stdin is piped");
        if let Some(input) = stdin {
            pipe.write_all(input).expect("writing stdin");
        }
    }
    child.wait_with_output().expect("waiting for the process")
}

/// Stdout and stderr as text.
pub fn text(o: &Output) -> (String, String) {
    (
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// Core `cpu`'s PM QoS resume latency, which `nanopush serve` sets to `n/a` (poll, never halt)
/// on its loop's core (`server/src/no_halt.rs::setting_path`; this crate does not link the server).
pub fn pm_qos_setting(cpu: usize) -> String {
    format!("/sys/devices/system/cpu/cpu{cpu}/power/pm_qos_resume_latency_us")
}

/// A scene's text with `values` (`key`, `value` in TOML) set in its `[strategy]` section: each
/// key's line replaced where the section has it, else added at the section's top; a scene without
/// the section gets one at its end. (The shipped paper scenes write their strategy out.)
pub fn with_strategy(text: &str, values: &[(&str, &str)]) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let Some(start) = lines.iter().position(|l| l.trim() == "[strategy]") else {
        let mut out = format!("{text}\n[strategy]\n");
        for (k, v) in values {
            out.push_str(&format!("{k} = {v}\n"));
        }
        return out;
    };
    let end = lines[start + 1..]
        .iter()
        .position(|l| l.trim_start().starts_with('['))
        .map_or(lines.len(), |i| start + 1 + i);
    for (k, v) in values {
        let at = (start + 1..end).find(|&i| lines[i].split('=').next().is_some_and(|key| key.trim() == *k));
        match at {
            Some(i) => lines[i] = format!("{k} = {v}"),
            None => lines.insert(start + 1, format!("{k} = {v}")),
        }
    }
    lines.join("\n") + "\n"
}

#[cfg(test)]
mod with_strategy_tests {
    #[test]
    fn keys_are_replaced_in_the_section_or_added() {
        let t = "[push]\nparticle_id = 1\n[strategy]\nstart_height_um = 3.0\nstep_um = 0.1\n\n[physics]\ncapillary = true\n";
        let out = super::with_strategy(t, &[("start_height_um", "2.2"), ("dwell_ms", "2.0")]);
        assert!(out.contains("start_height_um = 2.2\n") && !out.contains("3.0"), "{out}");
        assert!(out.contains("[strategy]\ndwell_ms = 2.0\n"), "{out}");
        assert_eq!(out.matches("[strategy]").count(), 1);
        let none = super::with_strategy("[push]\n", &[("step_um", "0.2")]);
        assert!(none.ends_with("[strategy]\nstep_um = 0.2\n"), "{none}");
    }
}
