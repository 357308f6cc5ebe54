//! The Nanonis backend against the fake controller: scans, a held push through its phases, the
//! read-only mode, and every fault the fake commits ending in a named error and a withdrawn tip.

use std::sync::atomic::AtomicBool;
use std::time::Duration;

use nanopush_instrument::afm::{Microscope, MicroscopeError, ScanFrame};
use nanopush_instrument::control::{HeldError, HeldOutcome, HeldPhase, HeldPush, held_push};
use nanopush_nanonis::fake::faults::Fault;
use nanopush_nanonis::fake::{FakeController, FakeOptions};
use nanopush_nanonis::{NanonisMicroscope, NanonisOptions};

fn fake() -> FakeController {
    FakeController::start(FakeOptions::default()).expect("start the fake")
}

fn options(f: &FakeController, logger: bool) -> NanonisOptions {
    let mut o = NanonisOptions::new(f.addr());
    o.logger_port = logger.then(|| f.logger_port());
    o.timeout = Duration::from_secs(2);
    o
}

fn connect(f: &FakeController) -> NanonisMicroscope {
    NanonisMicroscope::connect(options(f, true)).expect("connect to the fake")
}

/// The scene's particle 1 and a target 1 µm along +x.
fn push_of(f: &FakeController) -> HeldPush {
    let s = f.world().surface.spheres[0];
    HeldPush {
        from: [s.x, s.y],
        to: [s.x + 1e-6, s.y],
        radius: s.r,
        tip_radius: nanopush_instrument::scene::Scene::default_scene().file.tip.radius_nm * 1e-9,
        approach_gap: 100e-9,
        travel_speed: 10e-6,
        push_speed: 5e-6,
        setpoint: 0.1,
        land_tolerance: 0.005,
        settle_samples: 5,
        lateral_contact: 0.1,
        normal_limit: 0.5,
        land_timeout: 10.0,
    }
}

#[test]
fn the_backend_reports_a_local_z_loop_and_the_loggers_rate() {
    let f = fake();
    let m = connect(&f);
    let c = m.capabilities();
    assert!(c.z_closed_locally && c.scan_engine && !c.read_only);
    assert!(
        c.feed_rate_hz > 300.0 && c.feed_rate_hz < 1500.0,
        "logger at 1 kHz: {} Hz",
        c.feed_rate_hz
    );
    assert!(c.backend.contains(&f.addr().to_string()));
}

#[test]
fn without_a_logger_the_feed_rate_is_the_polled_one() {
    let f = fake();
    let m = NanonisMicroscope::connect(options(&f, false)).unwrap();
    assert_eq!(m.capabilities().feed_rate_hz, 50.0);
    assert!(f.commands().contains(&"Util.AcqPeriodSet".to_string()));
}

#[test]
fn a_scan_of_the_controllers_frame_is_the_image_the_fake_records() {
    let f = fake();
    let mut m = connect(&f);
    // The scan engine refuses to start with the tip withdrawn: land it first.
    m.hold_force(0.1).unwrap();
    let img = m.scan(None).unwrap();
    let truth = f.world().image.clone().unwrap();
    assert_eq!((img.xres, img.yres), (truth.xres, truth.yres));
    assert!((img.x_offset - truth.x_offset).abs() < 1e-11 && (img.x_real - truth.x_real).abs() < 1e-11);
    let worst = img
        .data
        .iter()
        .zip(&truth.data)
        .map(|(a, b)| (a - b).abs() / b.abs().max(1e-9))
        .fold(0.0, f64::max);
    assert!(worst < 1e-6, "f32 on the wire: relative error {worst}");
    let sent = f.commands();
    for c in [
        "Scan.BufferSet",
        "Scan.Action",
        "Scan.WaitEndOfScan",
        "Scan.FrameDataGrab",
    ] {
        assert!(sent.contains(&c.to_string()), "{c} not in {sent:?}");
    }
}

#[test]
fn a_scan_of_a_given_frame_sets_it_first() {
    let f = fake();
    let mut m = connect(&f);
    m.hold_force(0.1).unwrap();
    let mut frame = m.current_frame().unwrap();
    frame.width /= 2.0;
    frame.height /= 2.0;
    frame.pixels = 32;
    frame.lines = 32;
    let img = m.scan(Some(&frame)).unwrap();
    assert_eq!((img.xres, img.yres), (32, 32));
    assert!((img.x_real - frame.width).abs() < 1e-12);
    assert!(f.commands().contains(&"Scan.FrameSet".to_string()));
}

#[test]
fn read_only_grabs_the_last_image_and_sends_nothing_that_moves() {
    let f = fake();
    let mut o = options(&f, true);
    o.read_only = true;
    o.logger_port = None;
    let mut m = NanonisMicroscope::connect(o).unwrap();
    let img = m.scan(None).unwrap();
    assert_eq!(img.data.len(), 64 * 64);
    assert!(matches!(
        m.start_move(1e-6, 1e-6, 1e-6),
        Err(MicroscopeError::ReadOnly { .. })
    ));
    assert!(matches!(m.hold_force(0.1), Err(MicroscopeError::ReadOnly { .. })));
    assert!(matches!(m.withdraw(), Err(MicroscopeError::ReadOnly { .. })));
    let frame = m.current_frame().unwrap();
    assert!(matches!(m.scan(Some(&frame)), Err(MicroscopeError::ReadOnly { .. })));
    let sent = f.commands();
    let moving = [
        "FolMe.",
        "ZCtrl.OnOff",
        "ZCtrl.Setpnt",
        "ZCtrl.Withdraw",
        "ZCtrl.ZPos",
        "Scan.Action",
        "Scan.FrameSet",
        "Scan.BufferSet",
        "Util.AcqPeriodSet",
        "TCPLog.",
    ];
    for c in &sent {
        assert!(!moving.iter().any(|m| c.starts_with(m)), "read-only sent {c}: {sent:?}");
    }
}

#[test]
fn a_move_outside_the_frame_is_refused_before_anything_is_sent() {
    let f = fake();
    let mut m = connect(&f);
    let before = f.commands().len();
    let e = m.start_move(1.0, 0.0, 1e-6).unwrap_err().to_string();
    assert!(e.contains("outside the limits") && e.contains("scan frame"), "{e}");
    let e = m.start_move(50e-6, 50e-6, 1.0).unwrap_err().to_string();
    assert!(e.contains("speed") && e.contains("µm/s"), "{e}");
    assert_eq!(f.commands().len(), before);
}

#[test]
fn a_held_push_runs_its_phases_moves_the_particle_and_withdraws() {
    let f = fake();
    let mut m = connect(&f);
    let p = push_of(&f);
    let r = held_push(&mut m, &p, &AtomicBool::new(false)).unwrap();
    let phases: Vec<HeldPhase> = r.phases.iter().map(|(p, _)| *p).collect();
    assert_eq!(
        phases,
        [
            HeldPhase::Withdraw,
            HeldPhase::Travel,
            HeldPhase::Land,
            HeldPhase::Push,
            HeldPhase::Retract
        ]
    );
    assert_eq!(r.outcome, HeldOutcome::Pushed);
    assert!(r.watched && r.contact_at.is_some());
    let w = f.world();
    let s = w.surface.spheres[0];
    let miss = (s.x - p.to[0]).hypot(s.y - p.to[1]);
    assert!(miss < 5e-9, "particle {:.1} nm from the target", miss * 1e9);
    assert!(w.withdrawn && !w.z_on, "the tip ends withdrawn");
    assert!(r.samples.len() > 50, "{} readings from the logger", r.samples.len());
}

/// Runs a push with `fault` and checks that it ends in an error naming `command`, with the tip
/// withdrawn.
fn push_with_fault(fault: &str, command: &str) -> String {
    let f = fake();
    let mut m = connect(&f);
    f.add_fault(fault.parse::<Fault>().unwrap());
    let e = held_push(&mut m, &push_of(&f), &AtomicBool::new(false)).unwrap_err();
    let text = e.to_string();
    assert!(text.contains(command), "{fault}: {text}");
    assert!(
        matches!(e, HeldError::Backend { .. } | HeldError::Safety { .. }),
        "{e:?}"
    );
    assert!(
        text.contains("withdrawn") && !text.contains("could not"),
        "{fault}: {text}"
    );
    let w = f.world();
    assert!(w.withdrawn && !w.z_on, "{fault}: the tip is withdrawn");
    text
}

#[test]
fn an_error_block_ends_the_push_with_the_controllers_words() {
    let t = push_with_fault("error:ZCtrl.OnOffSet", "ZCtrl.OnOffSet");
    assert!(t.contains("Fake fault: ZCtrl.OnOffSet failed"), "{t}");
}

#[test]
fn a_dropped_connection_is_reopened_and_withdraws_first() {
    let f = fake();
    let mut m = connect(&f);
    f.add_fault("drop:FolMe.XYPosSet".parse().unwrap());
    let e = held_push(&mut m, &push_of(&f), &AtomicBool::new(false))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("FolMe.XYPosSet") && e.contains("closed the connection"),
        "{e}"
    );
    let conns = f.commands_by_connection();
    let second = &conns[1];
    assert_eq!(
        second[0], "ZCtrl.Withdraw",
        "the new connection's first command: {second:?}"
    );
    assert!(f.world().withdrawn);
}

#[test]
fn a_slow_controller_is_a_named_time_out_not_a_hang() {
    let t = push_with_fault("slow:FolMe.SpeedSet:3000", "FolMe.SpeedSet");
    assert!(t.contains("no answer within 2.0 s"), "{t}");
}

#[test]
fn a_reply_under_another_name_is_refused() {
    let t = push_with_fault("wrong-name:ZCtrl.SetpntSet", "ZCtrl.SetpntSet");
    assert!(t.contains("answered \"Bias.Get\""), "{t}");
}

#[test]
fn a_body_shorter_than_announced_is_refused() {
    push_with_fault("short:FolMe.SpeedSet", "FolMe.SpeedSet");
}

#[test]
fn a_logger_stream_that_stops_ends_the_push() {
    let f = fake();
    f.add_fault("logger-drop:600".parse().unwrap());
    let mut m = connect(&f);
    let mut p = push_of(&f);
    p.travel_speed = 1e-6;
    let e = held_push(&mut m, &p, &AtomicBool::new(false)).unwrap_err().to_string();
    assert!(e.contains("TCP Logger stream"), "{e}");
    assert!(e.contains("withdrawn"), "{e}");
    assert!(f.world().withdrawn);
}

#[test]
fn a_scan_that_fails_stops_the_engine_and_withdraws() {
    let f = fake();
    let mut m = connect(&f);
    m.hold_force(0.1).unwrap();
    f.add_fault("error:Scan.FrameDataGrab".parse().unwrap());
    let e = m.scan(None).unwrap_err().to_string();
    assert!(e.contains("Scan.FrameDataGrab") && e.contains("withdrawn"), "{e}");
    assert!(f.world().withdrawn);
}

#[test]
fn a_stopped_push_withdraws() {
    let f = fake();
    let mut m = connect(&f);
    let r = held_push(&mut m, &push_of(&f), &AtomicBool::new(true)).unwrap();
    assert_eq!(r.outcome, HeldOutcome::Stopped);
    assert!(f.world().withdrawn);
}

#[test]
fn an_unknown_deflection_signal_names_the_ones_there_are() {
    let f = fake();
    let mut o = options(&f, false);
    o.deflection_signal = "Deflection".into();
    let e = NanonisMicroscope::connect(o).unwrap_err().to_string();
    assert!(
        e.contains("no signal named \"Deflection\"") && e.contains("Normal deflection (V)"),
        "{e}"
    );
}

#[test]
fn a_controller_that_is_not_there_is_a_link_error() {
    let f = fake();
    let addr = f.addr();
    drop(f);
    let e = NanonisMicroscope::connect(NanonisOptions::new(addr)).unwrap_err();
    assert!(matches!(e, MicroscopeError::Link { .. }), "{e}");
}

#[test]
fn a_frame_outside_the_controllers_is_refused() {
    let f = fake();
    let mut m = connect(&f);
    let frame = ScanFrame {
        centre_x: 1.0,
        centre_y: 1.0,
        width: 1e-6,
        height: 1e-6,
        pixels: 32,
        lines: 32,
    };
    let e = m.scan(Some(&frame)).unwrap_err().to_string();
    assert!(e.contains("frame corner"), "{e}");
}

#[test]
fn the_users_xy_limits_narrow_the_controllers_and_are_checked_before_sending() {
    let f = fake();
    let mut o = options(&f, true);
    o.xy_limits = Some([[45e-6, 55e-6], [45e-6, 55e-6]]);
    let mut m = NanonisMicroscope::connect(o).unwrap();
    let l = m.limits().unwrap();
    assert_eq!((l.x, l.y), ([45e-6, 55e-6], [45e-6, 55e-6]));
    let before = f.commands().len();
    let e = m.start_move(60e-6, 50e-6, 1e-6).unwrap_err().to_string();
    assert!(e.contains("--xy-limits-um") && e.contains("[45.0000, 55.0000]"), "{e}");
    assert_eq!(f.commands().len(), before, "nothing sent");
    let mut o = options(&f, false);
    o.xy_limits = Some([[90e-6, 95e-6], [0.0, 1e-6]]);
    let e = NanonisMicroscope::connect(o).unwrap_err().to_string();
    assert!(e.contains("overlapping the controller's scan frame"), "{e}");
}

#[test]
fn a_reply_trickled_a_byte_at_a_time_is_as_late_as_silence() {
    use std::io::{Read, Write};
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    std::thread::spawn(move || {
        let (mut s, _) = listener.accept().unwrap();
        let mut req = [0u8; 40];
        let _ = s.read_exact(&mut req);
        // A well-formed header, one byte every 300 ms.
        let reply = nanopush_proto::nanonis::encode_response("Signals.NamesGet", &[0; 16]).unwrap();
        for b in reply {
            if s.write_all(&[b]).is_err() {
                return;
            }
            std::thread::sleep(Duration::from_millis(300));
        }
    });
    let mut o = NanonisOptions::new(addr);
    o.timeout = Duration::from_secs(1);
    let asked = std::time::Instant::now();
    let e = NanonisMicroscope::connect(o).unwrap_err().to_string();
    assert!(e.contains("Signals.NamesGet: no answer within 1.0 s"), "{e}");
    assert!(asked.elapsed() < Duration::from_secs(3), "{:?}", asked.elapsed());
}

#[test]
fn a_frame_that_is_not_a_frame_is_refused_at_connect() {
    let f = fake();
    f.world().frame = [f64::NAN, 50e-6, 50e-6, 50e-6, 0.0];
    let e = NanonisMicroscope::connect(options(&f, false)).unwrap_err().to_string();
    assert!(
        e.starts_with("Scan.FrameGet: the scan frame") && e.contains("not a frame"),
        "{e}"
    );
    f.world().frame = [50e-6, 50e-6, -1e-6, 50e-6, 0.0];
    assert!(NanonisMicroscope::connect(options(&f, false)).is_err());
    f.world().frame = [50e-6, 50e-6, 50e-6, 50e-6, f64::NAN];
    assert!(NanonisMicroscope::connect(options(&f, false)).is_err(), "a NaN angle");
}

#[test]
fn an_image_that_is_not_the_buffers_is_refused() {
    let f = fake();
    let mut o = options(&f, false);
    o.read_only = true;
    let mut m = NanonisMicroscope::connect(o).unwrap();
    {
        let mut w = f.world();
        let img = w.image.as_mut().unwrap();
        img.xres = 1;
        img.yres = 1;
        img.data.truncate(1);
    }
    let e = m.scan(None).unwrap_err().to_string();
    assert!(
        e.contains("an image of 1 × 1 pixels; the scan buffer is 64 × 64"),
        "{e}"
    );
    {
        let mut w = f.world();
        let img = w.image.as_mut().unwrap();
        img.xres = 64;
        img.yres = 64;
        img.data = vec![1.0; 64 * 64];
    }
    let e = m.scan(None).unwrap_err().to_string();
    assert!(
        e.contains("4096 of 4096 pixels are not heights inside the Z range"),
        "{e}"
    );
}

#[test]
fn a_scan_of_a_given_frame_gives_the_operator_their_frame_back() {
    let f = fake();
    let mut m = connect(&f);
    let frame0 = f.world().frame;
    let buffer0 = f.world().buffer.clone();
    let frame = ScanFrame {
        centre_x: 50e-6,
        centre_y: 50e-6,
        width: 2e-6,
        height: 2e-6,
        pixels: 32,
        lines: 32,
    };
    let img = m.scan(Some(&frame)).unwrap();
    assert_eq!(img.xres, 32);
    assert_eq!(f.world().frame, frame0.map(|v| f64::from(v as f32)));
    assert_eq!(f.world().buffer, buffer0);
}

#[test]
fn read_only_starts_no_logger() {
    let f = fake();
    let mut o = options(&f, true);
    o.read_only = true;
    let m = NanonisMicroscope::connect(o).unwrap();
    assert!(
        !f.commands().iter().any(|c| c.starts_with("TCPLog.")),
        "{:?}",
        f.commands()
    );
    assert_eq!(m.capabilities().feed_rate_hz, 50.0, "polled");
}

#[test]
fn a_scan_cancelled_before_it_starts_never_lands_the_tip() {
    let f = fake();
    let mut m = connect(&f);
    let cancel = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(true));
    m.set_cancel(cancel);
    let before = f.commands().len();
    let e = m.scan(None).unwrap_err();
    assert!(matches!(e, MicroscopeError::Cancelled(_)), "{e}");
    assert_eq!(e.to_string(), "the scan; the tip was withdrawn: stopped");
    let sent = &f.commands()[before..];
    assert!(
        !sent.iter().any(|c| c == "ZCtrl.OnOffSet" || c == "Scan.Action"),
        "nothing lands or starts: {sent:?}"
    );
    assert!(f.world().withdrawn);
}

#[test]
fn a_failed_scan_withdraws_before_it_gives_the_frame_back() {
    let f = fake();
    let mut m = connect(&f);
    f.add_fault("error:Scan.FrameDataGrab".parse().unwrap());
    let mut frame = m.current_frame().unwrap();
    frame.width /= 2.0;
    frame.height /= 2.0;
    let before = f.commands().len();
    let e = m.scan(Some(&frame)).unwrap_err().to_string();
    assert!(e.contains("Scan.FrameDataGrab") && e.contains("withdrawn"), "{e}");
    let sent = f.commands()[before..].to_vec();
    let at = |c: &str| {
        sent.iter()
            .rposition(|s| s == c)
            .unwrap_or_else(|| panic!("{c} in {sent:?}"))
    };
    assert!(
        at("ZCtrl.Withdraw") < at("Scan.FrameSet"),
        "withdrawn first, the frame after: {sent:?}"
    );
    assert!(
        at("Scan.Action") < at("ZCtrl.Withdraw"),
        "the engine stopped first: {sent:?}"
    );
}

#[test]
fn a_rotated_frame_is_refused_at_connect_unless_the_user_gives_limits() {
    let f = fake();
    f.world().frame[4] = 30.0;
    let e = NanonisMicroscope::connect(options(&f, false)).unwrap_err().to_string();
    assert!(e.contains("rotated by 30.00°") && e.contains("--xy-limits-um"), "{e}");
    let mut o = options(&f, false);
    o.xy_limits = Some([[45e-6, 55e-6], [45e-6, 55e-6]]);
    assert!(NanonisMicroscope::connect(o).is_ok());
}
