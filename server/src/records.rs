//! Recording: every push and every scan is saved in the data directory — push trace CSV and
//! JSON summary, scan GSF and JSON summary — each written to a `.partial` file and renamed, so a
//! crash never leaves a partial record under a record's name.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use serde::Serialize;

use nanopush_instrument::files::partial;
pub use nanopush_instrument::files::write_atomic;

use crate::clock::{unix_now, unix_secs};
use crate::control_loop::{LoopEvent, RecordMsg, Shared};

/// One entry of `/api/records`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RecordEntry {
    /// File name.
    pub name: String,
    /// `push` or `scan`.
    pub kind: String,
    /// Size (bytes).
    pub bytes: u64,
    /// Last modification (Unix seconds).
    pub modified: u64,
}

/// Whether `name` is a record's file name: letters, digits, `-`, `_`, `.`; no path.
pub fn valid_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 128
        && !name.starts_with('.')
        && !name.ends_with(".partial")
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
}

/// The finished records in `dir`, newest first.
pub fn list(dir: &Path) -> std::io::Result<Vec<RecordEntry>> {
    let mut out = Vec::new();
    let rd = match std::fs::read_dir(dir) {
        Ok(rd) => rd,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(out),
        Err(e) => return Err(e),
    };
    for e in rd.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        if !valid_name(&name) {
            continue;
        }
        // A plain file only: a symlink (to anywhere) is never listed or served.
        if !e.file_type().is_ok_and(|t| t.is_file()) {
            continue;
        }
        let Ok(meta) = e.metadata() else { continue };
        let kind = name.split('-').next().unwrap_or("").to_string();
        let modified = meta.modified().map_or(0, unix_secs);
        out.push(RecordEntry {
            name,
            kind,
            bytes: meta.len(),
            modified,
        });
    }
    out.sort_by(|a, b| b.modified.cmp(&a.modified).then(b.name.cmp(&a.name)));
    Ok(out)
}

/// How many runs `/api/runs` returns at most.
pub const RUNS_MAX: usize = 50;

/// A push summary is well under a kilobyte: a file of its name larger than this is not one, and
/// is not read (the monitors ask for the history every 5 s).
pub const SUMMARY_MAX_BYTES: u64 = 64 * 1024;

/// One push of the run history (`/api/runs`), from its record's JSON summary.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunEntry {
    /// The summary's file name (`push-….json`).
    pub record: String,
    /// When it was written (Unix seconds).
    pub modified: u64,
    /// The server run that wrote it (`welcome`'s `instance`; none in older records).
    pub instance: Option<String>,
    /// Run number (per server run: numbers start again after a restart).
    pub run: u64,
    /// Who ran it (none in records older than the audit trail).
    pub person: Option<String>,
    /// Particle id.
    pub particle: u32,
    /// `ok` or the failure code.
    pub outcome: String,
    /// The failure in words.
    pub failure: Option<String>,
    /// Final centre (m): where the scan after the push found it (`judged.measured`), else the
    /// controller's estimate.
    pub estimate: [f64; 2],
}

/// The pushes recorded in `dir`, newest first, at most `max`: read from their JSON summaries (a
/// summary that cannot be read or parsed, or is larger than [`SUMMARY_MAX_BYTES`], is skipped),
/// so the history survives restarts.
pub fn run_history(dir: &Path, max: usize) -> std::io::Result<Vec<RunEntry>> {
    Ok(runs_in(dir, &list(dir)?, max))
}

/// [`run_history`] from a listing of `dir` already made ([`list`]).
pub fn runs_in(dir: &Path, listed: &[RecordEntry], max: usize) -> Vec<RunEntry> {
    let mut out = Vec::new();
    for e in listed {
        if out.len() >= max {
            break;
        }
        if e.kind != "push" || !e.name.ends_with(".json") || e.bytes > SUMMARY_MAX_BYTES {
            continue;
        }
        let Ok(bytes) = std::fs::read(dir.join(&e.name)) else {
            continue;
        };
        let Ok(v) = serde_json::from_slice::<serde_json::Value>(&bytes) else {
            continue;
        };
        let (Some(run), Some(particle), Some(outcome)) = (
            v.get("run").and_then(serde_json::Value::as_u64),
            v.get("particle")
                .and_then(serde_json::Value::as_u64)
                .and_then(|p| u32::try_from(p).ok()),
            v.get("outcome").and_then(serde_json::Value::as_str),
        ) else {
            continue;
        };
        // Where the scan after the push found the particle, else where the controller believed it.
        let est = v
            .get("judged")
            .and_then(|j| j.get("measured"))
            .or_else(|| v.get("estimate"))
            .and_then(serde_json::Value::as_array);
        let at = |i: usize| est.and_then(|a| a.get(i)).and_then(serde_json::Value::as_f64);
        out.push(RunEntry {
            record: e.name.clone(),
            modified: e.modified,
            instance: v
                .get("instance")
                .and_then(serde_json::Value::as_str)
                .map(str::to_string),
            run,
            person: v.get("person").and_then(serde_json::Value::as_str).map(str::to_string),
            particle,
            outcome: outcome.to_string(),
            failure: v.get("failure").and_then(serde_json::Value::as_str).map(str::to_string),
            estimate: [at(0).unwrap_or(f64::NAN), at(1).unwrap_or(f64::NAN)],
        });
    }
    out
}

/// The JSON summary of a push record.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PushSummary {
    /// `"push-record"`.
    pub schema: &'static str,
    /// The server run that wrote it (`welcome`'s `instance`): run numbers start again after a
    /// restart, the pair names one push.
    pub instance: String,
    /// Run number.
    pub run: u64,
    /// Who ran it (their token's name; `operator` without a token file).
    pub person: Option<String>,
    /// Particle id.
    pub particle: u32,
    /// `ok` or the failure code.
    pub outcome: String,
    /// The failure in words.
    pub failure: Option<String>,
    /// Legs run.
    pub legs: usize,
    /// Estimated final centre (m).
    pub estimate: [f64; 2],
    /// True final centre (m), from the simulator.
    pub truth: [f64; 2],
    /// Trace rows written.
    pub rows: u64,
    /// The trace file.
    pub trace: String,
}

struct Open {
    run: u64,
    particle: u32,
    name: String,
    file: std::io::BufWriter<std::fs::File>,
    rows: u64,
}

/// A record's name, or why it could not be written.
pub type Recorded = Result<String, String>;

/// Removes the `.partial` files a crash (or a kill) left in `dir`; how many. Called by the
/// directory's holder only (`data_dir.rs`): another live server's are never there.
pub fn clean_partials(dir: &Path) -> usize {
    let Ok(rd) = std::fs::read_dir(dir) else { return 0 };
    rd.flatten()
        .filter(|e| e.file_name().to_string_lossy().ends_with(".partial"))
        .filter(|e| std::fs::remove_file(e.path()).is_ok())
        .count()
}

/// Drains the loop's trace rows and events, writes the records (each summary names `instance`,
/// the server run), and forwards each event with its record's name — or the reason it could not
/// be written. `people` names who ran each push. Ends when the loop has finished and everything
/// is written.
pub fn run_recorder(
    shared: Arc<Shared>,
    dir: PathBuf,
    instance: String,
    people: crate::audit::RunPeople,
    out: tokio::sync::mpsc::UnboundedSender<(LoopEvent, Recorded)>,
) {
    if let Err(e) = std::fs::create_dir_all(&dir) {
        tracing::error!("records: cannot create {}: {e}", dir.display());
    }
    let mut open: Option<Open> = None;
    let mut done: Vec<(u64, String, u64)> = Vec::new();
    let mut failed: Vec<(u64, String)> = Vec::new();
    loop {
        let finished = shared.finished.load(std::sync::atomic::Ordering::Acquire);
        let mut events = Vec::new();
        while let Some(e) = shared.events.pop() {
            events.push(e);
        }
        while let Some(msg) = shared.records.pop() {
            handle(&dir, &instance, msg, &mut open, &mut done, &mut failed);
        }
        for e in events {
            let LoopEvent::RunDone {
                run,
                particle,
                outcome,
                ref failure,
                estimate,
                truth,
                legs,
            } = e;
            let mut record: Recorded = Err("no trace was recorded for this run".into());
            if let Some(pos) = failed.iter().position(|f| f.0 == run) {
                record = Err(failed.remove(pos).1);
            } else if let Some(pos) = done.iter().position(|d| d.0 == run) {
                let (_, trace, rows) = done.remove(pos);
                let stem = trace.trim_end_matches(".csv").to_string();
                let summary = PushSummary {
                    schema: "push-record",
                    instance: instance.clone(),
                    run,
                    person: people.lock().ok().and_then(|p| p.get(&run).cloned()),
                    particle,
                    outcome: outcome.into(),
                    failure: failure.clone(),
                    legs,
                    estimate,
                    truth,
                    rows,
                    trace,
                };
                let json = format!("{stem}.json");
                match serde_json::to_vec_pretty(&summary).map_err(std::io::Error::other) {
                    Ok(bytes) => match write_atomic(&dir.join(&json), &bytes) {
                        Ok(()) => record = Ok(json),
                        Err(e) => {
                            tracing::error!("records: writing {json}: {e}");
                            record = Err(format!("writing {json} in {}: {e}", dir.display()));
                        }
                    },
                    Err(e) => {
                        tracing::error!("records: {e}");
                        record = Err(e.to_string());
                    }
                }
            }
            if record.is_err() {
                shared
                    .metrics
                    .record_failures
                    .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            }
            let _ = out.send((e, record));
        }
        if finished && shared.records.is_empty() && shared.events.is_empty() {
            break;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    if let Some(o) = open.take() {
        // The loop ended inside a run (it always sends End first; this is a safety net).
        finish(&dir, o, &mut done, &mut failed);
    }
}

fn handle(
    dir: &Path,
    instance: &str,
    msg: RecordMsg,
    open: &mut Option<Open>,
    done: &mut Vec<(u64, String, u64)>,
    failed: &mut Vec<(u64, String)>,
) {
    match msg {
        RecordMsg::Begin { run, particle } => {
            if let Some(o) = open.take() {
                finish(dir, o, done, failed);
            }
            // The server run in the name: runs one after the other never reuse a name.
            let name = format!("push-{}-{instance}-r{run}-p{particle}.csv", unix_now());
            match std::fs::File::create(partial(&dir.join(&name))) {
                Ok(f) => {
                    let mut file = std::io::BufWriter::new(f);
                    let _ = writeln!(file, "leg,t_s,phase,stage_x_m,stage_y_m,stage_z_m,volts,estimate_m");
                    *open = Some(Open {
                        run,
                        particle,
                        name,
                        file,
                        rows: 0,
                    });
                }
                Err(e) => {
                    tracing::error!("records: creating {name}: {e}");
                    failed.push((run, format!("creating {name} in {}: {e}", dir.display())));
                }
            }
        }
        RecordMsg::Row {
            leg,
            t,
            phase,
            stage,
            volts,
            estimate,
        } => {
            if let Some(o) = open {
                let _ = writeln!(
                    o.file,
                    "{leg},{t:.4},{phase},{:e},{:e},{:e},{volts:.5},{estimate:e}",
                    stage[0], stage[1], stage[2]
                );
                o.rows += 1;
            }
        }
        RecordMsg::End { run } => {
            if let Some(o) = open.take() {
                if o.run == run {
                    finish(dir, o, done, failed);
                } else {
                    *open = Some(o);
                }
            }
        }
    }
}

/// Writes the move's verdict into the JSON summary `name` in `dir` (atomically): its `outcome`
/// and `failure` become the verdict's, and `judged` says what the scan after the push measured
/// (when it found the particle).
/// The loop wrote the summary when the push's legs ended (`pushed`): the verdict comes from the
/// scan after it.
pub fn amend(
    dir: &Path,
    name: &str,
    outcome: &str,
    failure: Option<&str>,
    judged: Option<&nanopush_proto::ws::Judged>,
) -> Result<(), String> {
    let path = dir.join(name);
    let bytes = std::fs::read(&path).map_err(|e| format!("reading {name} to add the verdict: {e}"))?;
    let mut v: serde_json::Value =
        serde_json::from_slice(&bytes).map_err(|e| format!("{name} is not a push summary: {e}"))?;
    let Some(o) = v.as_object_mut() else {
        return Err(format!("{name} is not a push summary: not a JSON object"));
    };
    o.insert("outcome".into(), outcome.into());
    o.insert("failure".into(), failure.into());
    if let Some(j) = judged {
        o.insert("judged".into(), serde_json::to_value(j).map_err(|e| e.to_string())?);
    }
    let bytes = serde_json::to_vec_pretty(&v).map_err(|e| e.to_string())?;
    write_atomic(&path, &bytes).map_err(|e| format!("writing the verdict into {name} in {}: {e}", dir.display()))
}

fn finish(dir: &Path, mut o: Open, done: &mut Vec<(u64, String, u64)>, failed: &mut Vec<(u64, String)>) {
    let path = dir.join(&o.name);
    let ok = o.file.flush().and_then(|()| o.file.get_ref().sync_all());
    match ok.and_then(|()| std::fs::rename(partial(&path), &path)) {
        Ok(()) => done.push((o.run, o.name, o.rows)),
        Err(e) => {
            tracing::error!("records: finishing {} (particle {}): {e}", o.name, o.particle);
            let _ = std::fs::remove_file(partial(&path));
            failed.push((o.run, format!("finishing {} in {}: {e}", o.name, dir.display())));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_verdict_is_written_into_the_summary_and_the_history_reads_it() {
        let dir = std::env::temp_dir().join(format!("nanopush-amend-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let summary = PushSummary {
            schema: "push-record",
            instance: "18f-2a".into(),
            run: 4,
            person: None,
            particle: 1,
            outcome: "pushed".into(),
            failure: None,
            legs: 1,
            estimate: [41e-6, 40e-6],
            truth: [41.03e-6, 40e-6],
            rows: 10,
            trace: "push-9-r4-p1.csv".into(),
        };
        let name = "push-9-r4-p1.json";
        write_atomic(&dir.join(name), &serde_json::to_vec(&summary).unwrap()).unwrap();
        let judged = nanopush_proto::ws::Judged {
            measured: [41.03e-6, 40e-6],
            target: [41e-6, 40e-6],
            error_m: 30e-9,
            tolerance_m: 25e-9,
            attempts: 3,
        };
        let why = "the scan after found it 30.0 nm from the target";
        amend(&dir, name, "missed", Some(why), Some(&judged)).unwrap();
        let v: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join(name)).unwrap()).unwrap();
        assert_eq!(v["outcome"], "missed");
        assert_eq!(v["failure"], why);
        assert_eq!(v["judged"]["attempts"], 3);
        assert_eq!(v["truth"][0], 41.03e-6, "the rest is kept");
        let runs = run_history(&dir, 10).unwrap();
        assert_eq!(
            (runs[0].outcome.as_str(), runs[0].failure.as_deref()),
            ("missed", Some(why))
        );
        assert_eq!(runs[0].estimate, judged.measured, "where the scan found it");
        // A summary that is gone or not one is an error in words, not a panic.
        assert!(
            amend(&dir, "push-gone.json", "ok", None, Some(&judged))
                .unwrap_err()
                .contains("push-gone.json")
        );
        std::fs::write(dir.join("push-bad.json"), b"[1]").unwrap();
        assert!(
            amend(&dir, "push-bad.json", "ok", None, None)
                .unwrap_err()
                .contains("not a JSON object")
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn record_names_are_plain_file_names() {
        assert!(valid_name("push-1700000000-r1-p1.csv"));
        assert!(valid_name("scan-1700000000-3.gsf"));
        for bad in ["", "../etc/passwd", "a/b", ".hidden", "x.csv.partial", "a b", "é"] {
            assert!(!valid_name(bad), "{bad}");
        }
    }

    #[test]
    fn atomic_writes_leave_no_partial_file_and_lists_skip_partials() {
        let dir = std::env::temp_dir().join(format!("nanopush-records-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        write_atomic(&dir.join("scan-1-1.json"), b"{}").unwrap();
        std::fs::write(dir.join("push-2-r1-p1.csv.partial"), b"half").unwrap();
        let l = list(&dir).unwrap();
        assert_eq!(l.len(), 1);
        assert_eq!(l[0].name, "scan-1-1.json");
        assert_eq!(l[0].kind, "scan");
        assert_eq!(l[0].bytes, 2);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn the_run_history_reads_push_summaries_newest_first_and_skips_the_rest() {
        let dir = std::env::temp_dir().join(format!("nanopush-runs-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let summary = |run: u64, outcome: &str, failure: Option<&str>| {
            serde_json::to_vec(&PushSummary {
                schema: "push-record",
                instance: "18f-2a".into(),
                run,
                person: Some("alice".into()),
                particle: 2,
                outcome: outcome.into(),
                failure: failure.map(str::to_string),
                legs: 1,
                estimate: [1e-6, 2e-6],
                truth: [1e-6, 2e-6],
                rows: 10,
                trace: format!("push-1-r{run}-p2.csv"),
            })
            .unwrap()
        };
        std::fs::write(dir.join("push-1-r1-p2.json"), summary(1, "ok", None)).unwrap();
        std::fs::write(
            dir.join("push-2-r2-p2.json"),
            summary(2, "stopped", Some("stopped: the lease holder disconnected")),
        )
        .unwrap();
        std::fs::write(dir.join("push-3-r3-p2.json"), b"not json").unwrap();
        // A file of a summary's name but megabytes long (copied there by hand) is not read: the
        // monitors ask for the history every 5 s.
        let mut big = br#"{"run":5,"particle":2,"outcome":"ok","pad":""#.to_vec();
        big.extend(std::iter::repeat_n(b'x', SUMMARY_MAX_BYTES as usize));
        big.extend(br#""}"#);
        std::fs::write(dir.join("push-3-r5-p2.json"), big).unwrap();
        // A particle id no particle has (beyond u32) is no run, not particle 4294967295.
        std::fs::write(
            dir.join("push-3-r4-p2.json"),
            br#"{"run":4,"particle":99999999999,"outcome":"ok"}"#,
        )
        .unwrap();
        std::fs::write(dir.join("push-1-r1-p2.csv"), b"t\n").unwrap();
        std::fs::write(dir.join("scan-1-1.json"), b"{}").unwrap();
        let h = run_history(&dir, 10).unwrap();
        assert_eq!(h.len(), 2, "{h:?}");
        // Same second: the newer name first.
        assert_eq!(h[0].record, "push-2-r2-p2.json");
        assert_eq!(h[0].outcome, "stopped");
        assert_eq!(h[0].failure.as_deref(), Some("stopped: the lease holder disconnected"));
        assert_eq!(h[1].run, 1);
        assert_eq!(h[1].instance.as_deref(), Some("18f-2a"), "which server run wrote it");
        assert_eq!(h[1].person.as_deref(), Some("alice"), "who ran it");
        assert_eq!(h[1].estimate, [1e-6, 2e-6]);
        assert_eq!(run_history(&dir, 1).unwrap().len(), 1);
        assert!(run_history(&dir.join("missing"), 10).unwrap().is_empty());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
