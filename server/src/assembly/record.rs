//! An assembly's record and its end: its full frames as scan records, its JSON summary
//! (`assembly-<time>-<instance>-a<n>.json`: the pattern, the first plan, the runs of its pushes,
//! the frames' records and the report `nanopush assemble` writes), the audit log's line, and
//! `assembly_done` to everyone with the instrument free.

use std::sync::atomic::Ordering::Relaxed;

use nanopush_instrument::scan::HeightImage;
use nanopush_proto::assembly::AssemblySummary;
use nanopush_proto::ws::{AssemblyPlan, ServerMessage};

use super::AssemblyJob;
use crate::app_state::AppState;
use crate::clock::unix_now;
use crate::records::{Recorded, write_atomic};

/// How an assembly ended.
pub(crate) struct Ending {
    /// `filled`, `incomplete`, `refused`, `stopped`, `planned` or `error`.
    pub outcome: &'static str,
    /// Why it was refused or stopped.
    pub reason: Option<String>,
    /// The report.
    pub summary: Option<AssemblySummary>,
    /// Its record, or why none was written (none at all for `planned`).
    pub record: Option<Recorded>,
}

/// A full frame's scan record (and the latest scan from now on).
pub(crate) fn frame(st: &AppState, img: &HeightImage, person: &str) -> Recorded {
    crate::scan_job::record_frame(st, img, person)
}

/// What an assembly's record holds from its first plan on, and its name.
pub(crate) struct Opened {
    /// `assembly-<time>-<instance>-a<n>.json`.
    pub name: String,
    /// The first plan.
    pub first_plan: AssemblyPlan,
    /// The first full frame's scan record (none for `plan_only`).
    pub first_frame: Option<Recorded>,
}

/// The name of assembly `job`'s record, fixed when it opens.
pub(crate) fn name(st: &AppState, job: &AssemblyJob) -> String {
    format!("assembly-{}-{}-a{}.json", unix_now(), st.instance.id, job.number)
}

/// The assembly's JSON summary as it stands, written whole under its name (a `.partial`
/// renamed, so a reader never sees half of it): at the first plan and after every move with the
/// summary's outcome `running`, at the end with its outcome. A server killed in the middle
/// leaves it `running`, with the moves made. Its name, or why it could not be written.
pub(crate) fn write(
    st: &AppState,
    job: &AssemblyJob,
    opened: &Opened,
    summary: &AssemblySummary,
    last_frame: &Option<Recorded>,
    (runs, push_records): (&[u64], &[String]),
) -> Recorded {
    let Opened {
        name,
        first_plan,
        first_frame,
    } = opened;
    let frame = |r: &Option<Recorded>| match r {
        Some(Ok(name)) => serde_json::json!({ "record": name }),
        Some(Err(why)) => serde_json::json!({ "record": null, "record_error": why }),
        None => serde_json::Value::Null,
    };
    let doc = serde_json::json!({
        "schema": "assembly-record",
        "instance": st.instance.id,
        "assembly": job.number,
        "person": job.person,
        "pattern": job.pattern.name,
        "sites": super::wire::sites(&job.pattern, job.options.tolerance),
        "first_plan": first_plan,
        "first_frame": frame(first_frame),
        "final_frame": frame(last_frame),
        "runs": runs,
        "push_records": push_records,
        "summary": summary,
    });
    let written = serde_json::to_vec_pretty(&doc)
        .map_err(|e| e.to_string())
        .and_then(|bytes| write_atomic(&st.cfg.data_dir.join(name), &bytes).map_err(|e| e.to_string()));
    match written {
        Ok(()) => Ok(name.clone()),
        Err(e) => {
            tracing::error!("records: assembly {}: {e}", job.number);
            st.shared.metrics.record_failures.fetch_add(1, Relaxed);
            Err(format!("writing {name} in {}: {e}", st.cfg.data_dir.display()))
        }
    }
}

/// The assembly ends: the audit log's `assembly_done`, the instrument free, `assembly_done` to
/// everyone (freed first: a client that starts another on hearing it is not refused).
pub(crate) fn finish(st: &AppState, job: &AssemblyJob, end: Ending) {
    let (record, record_error) = match end.record {
        Some(Ok(name)) => (Some(name), None),
        Some(Err(why)) => (None, Some(why)),
        None => (None, None),
    };
    let mut args = serde_json::Map::new();
    args.insert("assembly".into(), job.number.into());
    if let Some(r) = &record {
        args.insert("record".into(), r.clone().into());
    }
    st.audit.event(crate::audit::Happened {
        person: &job.person,
        address: None,
        client: Some(job.by),
        command: "assembly_done",
        args,
        outcome: end.outcome,
        message: end.reason.as_deref(),
    });
    tracing::info!(
        "assembly {} ended {}{}",
        job.number,
        end.outcome,
        end.reason.as_deref().map_or(String::new(), |r| format!(": {r}"))
    );
    if let Ok(mut now) = st.activity.assembly_now.lock() {
        *now = None;
    }
    st.activity.assembling.store(false, Relaxed);
    st.broadcast_event(&ServerMessage::AssemblyDone {
        assembly: job.number,
        outcome: end.outcome.into(),
        reason: end.reason,
        summary: end.summary,
        record,
        record_error,
    });
}
