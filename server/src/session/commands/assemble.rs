//! `assemble`: the pattern checked here (the sites or the generator, each number against its
//! range in the protocol's units), then the assembly on a thread of its own (`assembly`), the
//! instrument busy until its `assembly_done`.

use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;

use nanopush_instrument::assembly::{AssemblyOptions, Pattern, Site};
use nanopush_proto::ws::{ASSEMBLE_MAX_GENERATOR, ASSEMBLE_MAX_SITES, AssemblyNow, ClientMessage, ErrorCode, SiteUm};

use super::instrument::busy;
use super::{Accepted, Client, misrouted};
use crate::app_state::AppState;
use crate::assembly::{AssemblyJob, run_assembly, wire};
use crate::command_checks::{Refusal, number, push_tolerance};

/// The fields of an `assemble` that go together, whoever sends it: the sites or a generator
/// (one of the two), its centre only with a generator and whole, at least one site and at most
/// [`ASSEMBLE_MAX_SITES`], a generator's text at most [`ASSEMBLE_MAX_GENERATOR`] characters.
pub(super) fn fields_agree(msg: &ClientMessage) -> Result<(), Refusal> {
    let ClientMessage::Assemble {
        sites,
        generator,
        at_x_um,
        at_y_um,
        ..
    } = msg
    else {
        return Ok(());
    };
    let invalid = |m: &str| Err(Refusal::new(ErrorCode::Invalid, m));
    match (sites, generator) {
        (Some(_), Some(_)) => return invalid("assemble takes either sites or generator, not both"),
        (None, None) => {
            return invalid(
                "assemble needs sites ([{\"x_um\": …, \"y_um\": …}, …]) or a generator (e.g. \"ring:n=8,radius_um=6\")",
            );
        }
        (Some(_), None) if at_x_um.is_some() || at_y_um.is_some() => {
            return invalid("at_x_um and at_y_um place a generator's pattern; the sites given are where they are");
        }
        _ => {}
    }
    if at_x_um.is_some() != at_y_um.is_some() {
        return invalid("at_x_um and at_y_um go together");
    }
    if let Some(s) = sites
        && !(1..=ASSEMBLE_MAX_SITES).contains(&s.len())
    {
        return Err(Refusal::new(
            ErrorCode::OutOfRange,
            format!("sites has {} entries; allowed: 1 to {ASSEMBLE_MAX_SITES}", s.len()),
        ));
    }
    if let Some(g) = generator
        && g.chars().count() > ASSEMBLE_MAX_GENERATOR
    {
        return Err(Refusal::new(
            ErrorCode::OutOfRange,
            format!(
                "generator is {} characters long; allowed: at most {ASSEMBLE_MAX_GENERATOR}",
                g.chars().count()
            ),
        ));
    }
    Ok(())
}

/// `assemble`, from the lease holder: the pattern made and checked, then the assembly started.
pub(super) fn run(st: &Arc<AppState>, c: &mut Client, msg: ClientMessage) -> Result<Accepted, Refusal> {
    super::instrument::simulated(st, "assemble")?;
    let ClientMessage::Assemble {
        sites,
        generator,
        at_x_um,
        at_y_um,
        tolerance_nm,
        plan_only,
        ..
    } = msg
    else {
        return Err(misrouted(&msg));
    };
    let range_um = st.scene.file.stage.range_um;
    let tolerance = push_tolerance(tolerance_nm)?;
    let pattern = match (sites, generator) {
        (Some(sites), None) => from_sites(&sites, range_um)?,
        (None, Some(spec)) => {
            let x = number("at_x_um", at_x_um.unwrap_or(range_um / 2.0), 0.0, range_um, false, "µm")?;
            let y = number("at_y_um", at_y_um.unwrap_or(range_um / 2.0), 0.0, range_um, false, "µm")?;
            Pattern::generate(&spec, (x * 1e-6, y * 1e-6))
                .map_err(|e| Refusal::new(ErrorCode::Invalid, e.to_string()))?
        }
        // `fields_agree` let none other through.
        _ => return Err(misrouted(&ClientMessage::Ping { id: None })),
    };
    busy(st)?;
    let number = st.activity.next_assembly.fetch_add(1, Relaxed);
    let job = AssemblyJob {
        number,
        options: AssemblyOptions {
            tolerance,
            ..AssemblyOptions::default()
        },
        plan_only,
        by: c.id,
        person: c.person.name.clone(),
        generation: st.activity.generation.load(Relaxed),
        pattern,
    };
    st.activity.assembling.store(true, Relaxed);
    if let Ok(mut now) = st.activity.assembly_now.lock() {
        *now = Some(AssemblyNow {
            assembly: number,
            by: c.id,
            plan_only,
            pattern: job.pattern.name.clone(),
            sites: wire::sites(&job.pattern, tolerance),
            phase: "planning".into(),
            plan: None,
            moves: Vec::new(),
            filled: Vec::new(),
            moving: None,
        });
    }
    let st2 = st.clone();
    std::thread::Builder::new()
        .name(format!("assembly-{number}"))
        .spawn(move || run_assembly(&st2, job))
        .map_err(|e| {
            st.activity.assembling.store(false, Relaxed);
            if let Ok(mut now) = st.activity.assembly_now.lock() {
                *now = None;
            }
            Refusal::new(ErrorCode::Busy, format!("the assembly could not start: {e}"))
        })?;
    Ok(Accepted::PLAIN)
}

/// The pattern of the sites given, each checked in the protocol's units.
fn from_sites(sites: &[SiteUm], range_um: f64) -> Result<Pattern, Refusal> {
    let (lo, hi) = nanopush_proto::push::TOLERANCE_RANGE_NM;
    let sites = sites
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let x = number(&format!("sites[{i}].x_um"), s.x_um, 0.0, range_um, false, "µm")?;
            let y = number(&format!("sites[{i}].y_um"), s.y_um, 0.0, range_um, false, "µm")?;
            let tolerance = s
                .tolerance_nm
                .map(|t| number(&format!("sites[{i}].tolerance_nm"), t, lo, hi, false, "nm"))
                .transpose()?;
            Ok(Site {
                x: x * 1e-6,
                y: y * 1e-6,
                tolerance: tolerance.map(|t| t * 1e-9),
            })
        })
        .collect::<Result<Vec<Site>, Refusal>>()?;
    Ok(Pattern {
        name: "sites".into(),
        sites,
        radius: None,
    })
}

#[cfg(test)]
mod tests {
    use std::sync::atomic::Ordering::Relaxed;

    use nanopush_proto::ws::{ErrorCode, Role};

    use crate::app_state::test_state;
    use crate::session::tests::{client, command};

    const TWO: &str = r#"{"type":"assemble","sites":[{"x_um":42,"y_um":30},{"x_um":44,"y_um":32}]}"#;

    /// An assembly needs the instrument to itself: refused while a push, a scan or another
    /// assembly runs, naming which.
    #[test]
    fn an_assembly_is_refused_while_anything_else_runs() {
        let st = test_state();
        let mut op = client(1, Role::Operator);
        command(&st, &mut op, r#"{"type":"take_lease"}"#).unwrap();
        for (flag, what) in [
            (&st.shared.busy, "a push is running"),
            (&st.activity.scanning, "a scan is running"),
            (&st.activity.assembling, "an assembly is running"),
        ] {
            flag.store(true, Relaxed);
            let e = command(&st, &mut op, TWO).unwrap_err();
            assert_eq!(e.code, ErrorCode::Busy);
            assert!(e.message.starts_with(what), "{}", e.message);
            flag.store(false, Relaxed);
        }
        // And while one runs, neither a push nor a scan starts.
        st.activity.assembling.store(true, Relaxed);
        for other in [
            r#"{"type":"push","particle":1,"distance_um":1,"direction_deg":0}"#,
            r#"{"type":"scan"}"#,
        ] {
            let e = command(&st, &mut op, other).unwrap_err();
            assert_eq!(e.message, "an assembly is running; send stop first");
        }
    }

    /// A generator's text too long or a site list too long is refused before anything else,
    /// even to a viewer; a site off the stage names the field and the range.
    #[test]
    fn sizes_and_ranges_are_refused_naming_the_field() {
        let st = test_state();
        let sites: Vec<String> = (0..401).map(|_| r#"{"x_um":1,"y_um":1}"#.to_string()).collect();
        let many = format!(r#"{{"type":"assemble","sites":[{}]}}"#, sites.join(","));
        let e = command(&st, &mut client(2, Role::Viewer), &many).unwrap_err();
        assert_eq!(
            (e.code, e.message.as_str()),
            (ErrorCode::OutOfRange, "sites has 401 entries; allowed: 1 to 400")
        );
        let mut op = client(1, Role::Operator);
        command(&st, &mut op, r#"{"type":"take_lease"}"#).unwrap();
        let e = command(&st, &mut op, r#"{"type":"assemble","sites":[{"x_um":-1,"y_um":1}]}"#).unwrap_err();
        assert_eq!(e.message, "sites[0].x_um = -1 is out of range; allowed: [0, 100] µm");
        let e = command(
            &st,
            &mut op,
            r#"{"type":"assemble","generator":"ring:n=3,radius_um=2","at_x_um":50,"at_y_um":1e300}"#,
        )
        .unwrap_err();
        assert_eq!(e.code, ErrorCode::OutOfRange);
        assert!(e.message.starts_with("at_y_um = "), "{}", e.message);
        assert!(!st.activity.assembling.load(Relaxed), "nothing started");
    }
}
