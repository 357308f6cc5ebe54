//! `nanopush serve` survives a push in the campaign's hardest valid scenes: a stage at 1 pm/s,
//! whose prediction would size a 41.6 GB trace, and a 0.01 N/m lever, which would throw the
//! particle 4 cm. Each push ends with a `run_done` and a reason, and the server still answers:
//! `/api/status`, telemetry, and another command.

use serde_json::json;

use crate::util::{is, ok, operator, runtime, start_scene, status, until};

fn push_and_still_answer(tag: &str, edits: &[(&str, &str)], expect: &[&str]) {
    let srv = start_scene(tag, edits);
    runtime().block_on(async {
        let mut op = operator(&srv.addr, "tip").await;
        ok(
            &mut op,
            json!({"type": "push", "id": 3, "particle": 1, "distance_um": 1.0, "direction_deg": 0.0}),
        )
        .await;
        let done = until(&mut op, 60.0, |m| is(m, "run_done")).await;
        let outcome = done["outcome"].as_str().unwrap().to_string();
        assert!(expect.contains(&outcome.as_str()), "{tag}: {done}");
        assert!(
            done["failure"].as_str().is_some_and(|f| !f.is_empty()),
            "{tag}: a reason: {done}"
        );
        // The server lives on: status, telemetry, and a reply to the next command.
        status(&srv.addr);
        until(&mut op, 5.0, |m| is(m, "telemetry")).await;
        ok(&mut op, json!({"type": "release_lease", "id": 4})).await;
    });
}

#[test]
fn a_push_too_slow_to_end_fails_with_a_reason_and_the_server_lives() {
    // The contact search at 1 pm/s cannot finish: it times out (phase time-out made 3 s here).
    push_and_still_answer(
        "slow-stage",
        &[
            ("speed_um_per_s = 2.0", "speed_um_per_s = 1e-6"),
            ("phase_timeout_s = 120.0", "phase_timeout_s = 3.0"),
        ],
        &["timeout", "error"],
    );
}

#[test]
fn a_push_with_a_too_soft_lever_fails_with_a_reason_and_the_server_lives() {
    push_and_still_answer(
        "soft-lever",
        &[("stiffness_n_per_m = 8.0", "stiffness_n_per_m = 0.01")],
        // The plan refuses it before any push (the lever bends past the readout before the
        // particle shears loose).
        &[
            "refused",
            "deflection_limit",
            "no_contact",
            "particle_lost",
            "unphysical",
        ],
    );
}
