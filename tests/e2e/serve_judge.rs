//! A push in the server is `ok` only when the scan after it finds the particle
//! within the push's tolerance of the target, never by the controller's estimate; outside it a
//! correction is pushed from where the scan found it, and a move still outside after its
//! pushes is `missed`, with the distance. Checked against the true position the simulation
//! knows (the record's `truth`).

use serde_json::{Value, json};

use crate::util::{Ws, http_get, is, ok, operator, runtime, start, until};

/// Pushes particle 1 of the test scene `distance_um` along +x with `tolerance_nm`: every
/// `push_started` of the move, then its `run_done`.
async fn judged_push(op: &mut Ws, id: u32, distance_um: f64, tolerance_nm: f64) -> (Vec<Value>, Value) {
    ok(
        op,
        json!({"type": "push", "id": id, "particle": 1, "distance_um": distance_um,
               "direction_deg": 0.0, "tolerance_nm": tolerance_nm}),
    )
    .await;
    let mut started = Vec::new();
    loop {
        let m = until(op, 60.0, |m| is(m, "push_started") || is(m, "run_done")).await;
        if is(&m, "run_done") {
            return (started, m);
        }
        started.push(m);
    }
}

/// A record's JSON summary.
fn summary(addr: &str, name: &str) -> Value {
    let (status, body) = http_get(addr, &format!("/api/records/{name}"));
    assert_eq!(status, 200, "{name}");
    serde_json::from_slice(&body).unwrap()
}

fn xy(v: &Value) -> (f64, f64) {
    (v[0].as_f64().unwrap(), v[1].as_f64().unwrap())
}

fn dist(a: (f64, f64), b: (f64, f64)) -> f64 {
    (a.0 - b.0).hypot(a.1 - b.1)
}

/// The verdict agrees with the truth: an `ok` is truly within the tolerance (the scan's
/// localization is good to a fraction of a nanometre here), a `missed` truly outside it, and
/// the measured position is where the particle is.
fn check_against_truth(addr: &str, done: &Value, tolerance: f64) {
    let judged = &done["judged"];
    assert!(judged.is_object(), "a judged move: {done}");
    let record = summary(addr, done["record"].as_str().expect("a record"));
    assert_eq!(
        record["outcome"], done["outcome"],
        "the record says the verdict: {record}"
    );
    let truth = xy(&record["truth"]);
    let (measured, target) = (xy(&judged["measured"]), xy(&judged["target"]));
    assert!(dist(measured, truth) < 1e-9, "measured where it is: {done} {record}");
    assert!(
        (judged["tolerance_m"].as_f64().unwrap() - tolerance).abs() < 1e-15,
        "{done}"
    );
    let error = judged["error_m"].as_f64().unwrap();
    assert!((error - dist(measured, target)).abs() < 1e-12, "{done}");
    match done["outcome"].as_str().unwrap() {
        "ok" => assert!(
            dist(truth, target) <= tolerance + 1e-9,
            "an ok truly within: {done} {record}"
        ),
        "missed" => assert!(error > tolerance, "{done}"),
        other => panic!("a pushed move ends ok or missed, not {other}: {done}"),
    }
}

#[test]
fn a_push_is_ok_only_when_the_scan_after_it_finds_it_within_tolerance() {
    let srv = start("judge", &[]);
    runtime().block_on(async {
        let mut op = operator(&srv.addr, "tip").await;
        // The default tolerance, 25 nm: this push ends 2.5 nm off, and is `ok`.
        let (started, done) = judged_push(&mut op, 3, 1.0, 25.0).await;
        assert_eq!(started.len(), 1, "one push: {started:?}");
        assert_eq!(started[0]["attempt"], 1);
        // The plan's choice, said with the move's first push.
        let summary = started[0]["strategy"]["summary"].as_str().unwrap_or_default();
        assert!(summary.starts_with("β = ") && summary.contains(" side, xy control, "), "{}", started[0]);
        assert!(started[0]["strategy"]["tried"].is_array(), "{}", started[0]);
        assert_eq!(done["outcome"], "ok", "{done}");
        assert_eq!(done["judged"]["attempts"], 1);
        check_against_truth(&srv.addr, &done, 25.0 * 1e-9);
        // At 1 nm the same push is `missed`, with the distance: no push can correct the
        // 2.5 nm left (the planner's least leg is 10 nm).
        let (_, done) = judged_push(&mut op, 4, 1.0, 1.0).await;
        assert_eq!(done["outcome"], "missed", "{done}");
        let why = done["failure"].as_str().unwrap();
        assert!(why.contains("nm from the target, beyond the 1.0 nm tolerance"), "{why}");
        check_against_truth(&srv.addr, &done, 1e-9);
        // A tolerance out of range is refused, naming the field and the range.
        crate::util::send(
            &mut op,
            json!({"type": "push", "id": 5, "particle": 1, "distance_um": 1.0, "direction_deg": 0.0, "tolerance_nm": 0.5}),
        )
        .await;
        let r = crate::util::reply(&mut op, 5).await;
        assert_eq!(r["type"], "error", "{r}");
        assert!(
            r["message"]
                .as_str()
                .unwrap()
                .contains("tolerance_nm = 0.5 is out of range; allowed: [1, 100000] nm"),
            "{r}"
        );
    });
}
