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
        assert_eq!(i["offers"], json!([]));

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

        // Pushes, scans and assemblies are the command line's on a real controller.
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
        send(&mut op, json!({"type": "scan", "id": 6})).await;
        assert_eq!(reply(&mut op, 6).await["code"], "unavailable");

        // Stop withdraws the tip.
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
    assert_eq!(f.commands().last().map(String::as_str), Some("ZCtrl.Withdraw"));
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
