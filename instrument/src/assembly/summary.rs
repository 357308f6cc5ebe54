//! An assembly's report as `nanopush_proto::assembly` writes it (`summary.json`, the server's
//! `assembly_done`): the book's site reports and move records in the report's types, SI
//! throughout. One conversion for the command line and the server.

use nanopush_proto::assembly::{AssemblySummary, MoveSummary, SiteSummary};

use super::book::{MoveRecord, SiteReport};
use super::pattern::Pattern;
use super::plan::Purpose;

fn xy(p: (f64, f64)) -> [f64; 2] {
    [p.0, p.1]
}

/// `fill`, `clear` or `park`, and the site a fill is for.
pub fn purpose_words(p: Purpose) -> (&'static str, Option<usize>) {
    match p {
        Purpose::Fill { site } => ("fill", Some(site)),
        Purpose::Clear => ("clear", None),
        Purpose::Park => ("park", None),
    }
}

/// A move as it was made.
pub fn made(m: &MoveRecord) -> MoveSummary {
    let (purpose, site) = purpose_words(m.purpose);
    MoveSummary {
        purpose: purpose.into(),
        site,
        particle: m.particle,
        from: xy(m.from),
        to: xy(m.to),
        outcome: m.outcome.clone(),
        error: m.error,
        pushes: m.pushes,
        push_time: m.push_time,
    }
}

/// A site at the end.
pub fn site(s: &SiteReport) -> SiteSummary {
    SiteSummary {
        target: xy(s.target),
        tolerance: s.tolerance,
        particle: s.particle,
        measured: s.measured.map(xy),
        true_position: s.true_position.map(xy),
        error: s.error,
        status: s.status.into(),
        reason: s.reason.clone(),
    }
}

/// What an assembly ended with, in numbers.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Totals {
    /// Wall time (s).
    pub wall_time: f64,
    /// Simulated time of the pushes (s).
    pub push_time: f64,
    /// Simulated time of the scans at the scene's line rate (s).
    pub scan_time: f64,
    /// Hidden, from the simulation: a pushed particle that went through another (empty where
    /// the truth is not checked).
    pub violations: Vec<String>,
}

/// The whole report.
pub fn summary(
    pattern: &Pattern,
    outcome: &str,
    refusal: Option<String>,
    sites: &[SiteReport],
    moves: &[MoveRecord],
    totals: Totals,
) -> AssemblySummary {
    AssemblySummary {
        schema: "nanopush.assembly".into(),
        version: nanopush_proto::VERSION,
        outcome: outcome.into(),
        refusal,
        pattern: pattern.name.clone(),
        sites: sites.iter().map(site).collect(),
        moves: moves.iter().map(made).collect(),
        wall_time: totals.wall_time,
        push_time: totals.push_time,
        scan_time: totals.scan_time,
        violations: totals.violations,
    }
}
