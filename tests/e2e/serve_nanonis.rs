//! `nanopush serve --instrument nanonis:…` against a fake controller started by the test: the
//! page is told the backend and its rate, telemetry carries the controller's readings at the
//! logger's rate, what the server does not offer there is refused with the command to use, and
//! Stop and shutdown withdraw the tip.

use std::time::{Duration, Instant};

use nanopush_e2e::{run, text};
use nanopush_instrument::afm::Microscope;
use nanopush_nanonis::fake::{FakeController, FakeOptions};
use nanopush_nanonis::{NanonisMicroscope, NanonisOptions};
use serde_json::json;

use crate::util::{TOKEN, is, ok, operator, reply, runtime, send, start, status, until, welcomed};

fn fake() -> FakeController {
    FakeController::start(FakeOptions::default()).expect("start the fake controller")
}

fn spec(f: &FakeController) -> String {
    format!("nanonis:{},{}", f.addr(), f.logger_port())
}

#[test]
fn the_page_is_told_the_backend_and_telemetry_follows_the_controller() {
    let f = fake();
    let s = start("nanonis", &["--instrument", &spec(&f)]);
    runtime().block_on(async {
        let (_ws, welcome) = welcomed(&s.addr, Some(TOKEN)).await;
        let i = &welcome["instrument"];
        assert_eq!(i["backend"], format!("Nanonis {}", f.addr()), "{welcome}");
        let rate = i["feed_rate_hz"].as_f64().unwrap();
        assert!(
            (300.0..3000.0).contains(&rate),
            "the fake's logger runs at 1 kHz: {rate} Hz"
        );
        assert_eq!(i["z_closed_locally"], true);
        assert_eq!(i["offers"], json!(["scan"]));

        // The controller's deflection, changed by another client, reaches the page.
        let mut op = operator(&s.addr, "tip").await;
        let first = until(&mut op, 5.0, |m| is(m, "telemetry")).await;
        let stage = first["stage"].as_array().unwrap();
        assert!((stage[0].as_f64().unwrap() - 50e-6).abs() < 1e-9, "{first}");
        let mut other = NanonisMicroscope::connect(NanonisOptions::new(f.addr())).unwrap();
        other.hold_force(0.2).unwrap();
        let landed = until(&mut op, 5.0, |m| {
            is(m, "telemetry") && m["volts"].as_f64().unwrap() > 0.19
        })
        .await;
        assert!(landed["volts"].as_f64().unwrap() <= 0.2 + 1e-6, "{landed}");

        // The readings come at the logger's rate.
        let ticks = |v: &serde_json::Value| v["loop"]["ticks"].as_u64().unwrap();
        let (a, t0) = (ticks(&status(&s.addr)), Instant::now());
        tokio::time::sleep(Duration::from_millis(1000)).await;
        let per_s = (ticks(&status(&s.addr)) - a) as f64 / t0.elapsed().as_secs_f64();
        assert!(per_s > 300.0, "{per_s:.0} readings per second from a 1 kHz logger");

        // Pushes and assemblies are the command line's on a real controller.
        send(
            &mut op,
            json!({"type": "push", "id": 5, "particle": 1, "distance_um": 1.0, "direction_deg": 0.0}),
        )
        .await;
        let r = reply(&mut op, 5).await;
        assert_eq!(r["code"], "unavailable", "{r}");
        assert!(
            r["message"].as_str().unwrap().contains("nanopush push --instrument"),
            "{r}"
        );
        // A part of a square is refused; none of it scans the controller's own frame.
        send(&mut op, json!({"type": "scan", "id": 6, "size_um": 5.0})).await;
        assert_eq!(reply(&mut op, 6).await["code"], "invalid");
        assert!(!f.world().withdrawn, "landed by the other client");
        drop(other);
        send(
            &mut op,
            json!({"type": "subscribe", "id": 8, "streams": ["tip", "scan"]}),
        )
        .await;
        ok(&mut op, json!({"type": "scan", "id": 9})).await;
        let done = until(&mut op, 20.0, |m| is(m, "scan_done")).await;
        let record = done["record"].as_str().unwrap_or_else(|| panic!("{done}")).to_string();
        let gsf = s.dir.join("records").join(&record);
        let bytes = std::fs::read(&gsf).unwrap_or_else(|e| panic!("{}: {e}", gsf.display()));
        assert!(bytes.starts_with(b"Gwyddion Simple Field 1.0\n"));
        let truth = f.world().image.clone().unwrap();
        let nul = bytes.iter().position(|&c| c == 0).unwrap();
        let data: Vec<f64> = bytes[nul + (4 - nul % 4)..]
            .chunks_exact(4)
            .map(|c| f64::from(f32::from_le_bytes([c[0], c[1], c[2], c[3]])))
            .collect();
        assert_eq!(data.len(), truth.data.len());
        let worst = data
            .iter()
            .zip(&truth.data)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(
            worst < 1e-12,
            "the record holds the controller's image: worst pixel off by {worst} m"
        );

        // Stop withdraws the tip.
        NanonisMicroscope::connect(NanonisOptions::new(f.addr()))
            .unwrap()
            .hold_force(0.1)
            .unwrap();
        assert!(!f.world().withdrawn);
        ok(&mut op, json!({"type": "stop", "id": 7})).await;
        let deadline = Instant::now() + Duration::from_secs(5);
        while !f.world().withdrawn {
            assert!(Instant::now() < deadline, "Stop did not withdraw the tip");
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    });
}

#[test]
fn shutdown_withdraws_the_tip_and_the_state_names_no_scene_particles() {
    let f = fake();
    let mut s = start("nanonis-stop", &["--instrument", &spec(&f)]);
    let st = status(&s.addr);
    assert_eq!(st["instrument"]["backend"], format!("Nanonis {}", f.addr()));
    assert_eq!(
        st["particles"],
        json!([]),
        "the scene's particles are not the controller's sample"
    );
    let mut other = NanonisMicroscope::connect(NanonisOptions::new(f.addr())).unwrap();
    other.hold_force(0.1).unwrap();
    assert!(!f.world().withdrawn);
    nanopush_e2e::stop(&mut s.child);
    assert!(f.world().withdrawn, "the server withdrew the tip as it shut down");
    let sent = f.commands();
    let last = |c: &str| sent.iter().rposition(|s| s == c);
    assert!(
        last("ZCtrl.Withdraw") > last("ZCtrl.OnOffSet"),
        "withdrawn after the landing: {sent:?}"
    );
}

#[test]
fn a_haptic_link_or_a_frame_with_a_real_controller_is_refused_at_start() {
    let f = fake();
    let spec = spec(&f);
    for (extra, says) in [
        (vec!["--haptic", "sim"], "--haptic sim with --instrument"),
        (
            vec!["--frame-um", "50,50,5"],
            "--frame-um is for nanopush scan and push",
        ),
    ] {
        let mut args = vec!["serve", "--port", "0", "--instrument", &spec];
        args.extend(extra);
        let o = run("nanopush", &args, None);
        let (_, err) = text(&o);
        assert!(!o.status.success(), "{err}");
        assert!(err.contains(says), "{says}: {err}");
    }
}

#[test]
fn stop_ends_a_controllers_scan_and_withdraws() {
    let f = FakeController::start(FakeOptions {
        line_rate: 8.0,
        ..FakeOptions::default()
    })
    .unwrap();
    let s = start("nanonis-scan-stop", &["--instrument", &spec(&f)]);
    runtime().block_on(async {
        let mut op = operator(&s.addr, "scan").await;
        ok(&mut op, json!({"type": "scan", "id": 5})).await;
        // 64 lines at 8 lines/s: eight seconds of scanning, stopped after one.
        tokio::time::sleep(Duration::from_millis(1000)).await;
        assert!(f.world().scanning(), "the controller scans");
        let asked = Instant::now();
        ok(&mut op, json!({"type": "stop", "id": 6})).await;
        let done = until(&mut op, 5.0, |m| is(m, "scan_done")).await;
        assert!(
            asked.elapsed() < Duration::from_secs(3),
            "the stop was heard within a slice of the wait"
        );
        assert_eq!(done["record"], serde_json::Value::Null, "{done}");
        assert_eq!(
            done["record_error"],
            serde_json::Value::Null,
            "a stopped scan is no failure: {done}"
        );
        assert!(!f.world().scanning(), "the scan engine was stopped");
        assert!(f.world().withdrawn, "and the tip withdrawn");
    });
}

#[test]
fn a_controller_that_vanishes_leaves_the_server_up_and_its_shutdown_bounded() {
    let f = fake();
    let addr = f.addr();
    let mut s = start("nanonis-vanish", &["--instrument", &spec(&f)]);
    let ticks = |v: &serde_json::Value| v["loop"]["ticks"].as_u64().unwrap();
    assert!(ticks(&status(&s.addr)) > 0);
    drop(f);
    std::thread::sleep(Duration::from_millis(500));
    let a = ticks(&status(&s.addr));
    std::thread::sleep(Duration::from_millis(500));
    assert_eq!(ticks(&status(&s.addr)), a, "no readings from a controller that is gone");
    let asked = Instant::now();
    nanopush_e2e::stop(&mut s.child);
    assert!(
        asked.elapsed() < Duration::from_secs(15),
        "shut down in {:?}",
        asked.elapsed()
    );
    let log = std::fs::read_to_string(s.dir.join("server.log")).unwrap();
    assert!(
        log.contains("the tip could NOT be withdrawn") && log.contains(&addr.to_string()),
        "the log says the tip may still be down:\n{log}"
    );
}

#[test]
fn a_stop_sent_right_after_a_scan_ends_it_and_a_storm_of_stops_is_one_withdraw() {
    let f = FakeController::start(FakeOptions {
        line_rate: 20.0,
        ..FakeOptions::default()
    })
    .unwrap();
    let s = start("nanonis-race", &["--instrument", &spec(&f), "--max-rate", "200"]);
    runtime().block_on(async {
        let mut op = operator(&s.addr, "scan").await;
        for round in 0..5u32 {
            let id = 10 + 2 * round;
            send(&mut op, json!({"type": "scan", "id": id})).await;
            send(&mut op, json!({"type": "stop", "id": id + 1})).await;
            let done = until(&mut op, 10.0, |m| is(m, "scan_done")).await;
            assert_eq!(
                done["record"],
                serde_json::Value::Null,
                "round {round}: the stop ended the scan: {done}"
            );
            // The next scan waits until this one is over.
            tokio::time::sleep(Duration::from_millis(300)).await;
        }
        let withdraws = || f.commands().iter().filter(|c| *c == "ZCtrl.Withdraw").count();
        let before = withdraws();
        for id in 100..120 {
            send(&mut op, json!({"type": "stop", "id": id})).await;
        }
        reply(&mut op, 119).await;
        tokio::time::sleep(Duration::from_millis(500)).await;
        let sent = withdraws() - before;
        assert!((1..=4).contains(&sent), "20 stops in a burst: {sent} withdraws");
    });
}

#[test]
fn the_logger_comes_back_after_the_controller_restarts_and_a_lost_withdraw_is_told() {
    let f = fake();
    let (port, logger_port) = (f.addr().port(), f.logger_port());
    let s = start(
        "nanonis-restart",
        &["--instrument", &spec(&f), "--instrument-timeout-s", "1"],
    );
    let ticks = |v: &serde_json::Value| v["loop"]["ticks"].as_u64().unwrap();
    runtime().block_on(async {
        let mut op = operator(&s.addr, "tip").await;
        drop(f);
        tokio::time::sleep(Duration::from_millis(1500)).await;
        let st = status(&s.addr);
        assert!(st["instrument_reading_age_s"].as_f64().unwrap() > 1.0, "{st}");
        // A stop with the controller gone: the withdraw fails, and everyone is told.
        ok(&mut op, json!({"type": "stop", "id": 5})).await;
        let told = until(&mut op, 10.0, |m| is(m, "error") && m["id"].is_null()).await;
        assert!(
            told["message"].as_str().unwrap().contains("could NOT be withdrawn"),
            "{told}"
        );
        let again = FakeController::start(FakeOptions {
            port,
            logger_port,
            ..FakeOptions::default()
        })
        .unwrap();
        let a = ticks(&status(&s.addr));
        let deadline = Instant::now() + Duration::from_secs(15);
        while ticks(&status(&s.addr)) < a + 500 {
            assert!(Instant::now() < deadline, "readings never came back");
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
        assert!(
            again.commands().contains(&"TCPLog.Start".to_string()),
            "the logger was started again"
        );
        send(
            &mut op,
            json!({"type": "scan", "id": 6, "centre_x_um": 74.0, "centre_y_um": 50.0, "size_um": 5.0}),
        )
        .await;
        let r = reply(&mut op, 6).await;
        assert_eq!(r["code"], "out_of_range", "{r}");
        assert!(r["message"].as_str().unwrap().contains("controller's frame"), "{r}");
    });
}
