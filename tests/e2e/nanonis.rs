//! `nanopush scan` and `nanopush push` against a fake Nanonis controller started by the test:
//! the surface it serves lands in the GSF, a push runs its phases and ends withdrawn, read-only
//! sends nothing that moves, and every fault ends in a named error with the tip withdrawn.

use nanopush_e2e::{run, text};
use nanopush_nanonis::fake::faults::Fault;
use nanopush_nanonis::fake::{FakeController, FakeOptions};

use crate::util::tmp;

fn fake() -> FakeController {
    FakeController::start(FakeOptions::default()).expect("start the fake controller")
}

fn spec(f: &FakeController) -> String {
    format!("nanonis:{},{}", f.addr(), f.logger_port())
}

/// The heights of a GSF file (m), row by row.
fn gsf_data(path: &std::path::Path) -> (usize, usize, Vec<f64>) {
    let b = std::fs::read(path).unwrap();
    let nul = b.iter().position(|&c| c == 0).unwrap();
    let header = std::str::from_utf8(&b[..nul]).unwrap();
    let key = |k: &str| -> usize {
        header
            .lines()
            .find_map(|l| l.strip_prefix(&format!("{k} = ")))
            .unwrap_or_else(|| panic!("{k} in {header}"))
            .trim()
            .parse()
            .unwrap()
    };
    let (xres, yres) = (key("XRes"), key("YRes"));
    let start = nul + (4 - nul % 4);
    let data = b[start..]
        .chunks_exact(4)
        .map(|c| f64::from(f32::from_le_bytes([c[0], c[1], c[2], c[3]])))
        .collect();
    (xres, yres, data)
}

#[test]
fn a_scan_writes_the_surface_the_controller_serves_and_leaves_the_tip_withdrawn() {
    let f = fake();
    let dir = tmp("nanonis-scan");
    let gsf = dir.join("s.gsf");
    let o = run(
        "nanopush",
        &[
            "scan",
            "--instrument",
            &spec(&f),
            "--size",
            "128",
            "--out",
            gsf.to_str().unwrap(),
        ],
        None,
    );
    let (out, err) = text(&o);
    assert!(o.status.success(), "{err}");
    assert!(
        out.contains("128 × 128 pixels") && out.contains("particles found in the image: 1"),
        "{out}"
    );
    let (xres, yres, data) = gsf_data(&gsf);
    assert_eq!((xres, yres), (128, 128));
    let truth = f.world().image.clone().unwrap();
    assert_eq!(truth.data.len(), data.len());
    let worst = data
        .iter()
        .zip(&truth.data)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(worst < 1e-12, "worst pixel differs by {worst} m");
    assert!(gsf.with_extension("png").exists());
    assert!(f.world().withdrawn, "the scan landed the tip and withdrew it after");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_read_only_scan_shows_the_last_image_and_moves_nothing() {
    let f = fake();
    let dir = tmp("nanonis-ro");
    let gsf = dir.join("s.gsf");
    let o = run(
        "nanopush",
        &[
            "scan",
            "--instrument",
            &format!("nanonis:{}", f.addr()),
            "--instrument-read-only",
            "--out",
            gsf.to_str().unwrap(),
        ],
        None,
    );
    let (out, err) = text(&o);
    assert!(o.status.success(), "{err}");
    assert!(out.contains("read-only"), "{out}");
    let moving = [
        "FolMe.",
        "ZCtrl.OnOff",
        "ZCtrl.Setpnt",
        "ZCtrl.Withdraw",
        "Scan.Action",
        "Scan.FrameSet",
        "Scan.BufferSet",
        "Util.AcqPeriodSet",
        "TCPLog.",
    ];
    for c in f.commands() {
        assert!(!moving.iter().any(|m| c.starts_with(m)), "read-only sent {c}");
    }
    let o = run(
        "nanopush",
        &[
            "push",
            "--instrument",
            &spec(&f),
            "--instrument-read-only",
            "--at-um",
            "50,50",
            "--to-um",
            "52,50",
        ],
        None,
    );
    assert!(!o.status.success());
    assert!(
        text(&o).1.contains("--instrument-read-only: a push moves the tip"),
        "{}",
        text(&o).1
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_push_runs_its_phases_moves_the_particle_and_ends_withdrawn() {
    let f = fake();
    let dir = tmp("nanonis-push");
    let o = run(
        "nanopush",
        &[
            "push",
            "--instrument",
            &spec(&f),
            "--at-um",
            "50.2,49.9",
            "--to-um",
            "52,50",
            "--out",
            dir.to_str().unwrap(),
        ],
        None,
    );
    let (out, err) = text(&o);
    assert!(o.status.success(), "{out}{err}");
    assert!(
        out.contains("withdraw → travel → land → push → retract; push pushed"),
        "{out}"
    );
    assert!(
        out.contains("signals at") && out.contains("the tip is withdrawn"),
        "{out}"
    );
    assert!(out.contains("from the target: ok (tolerance 25.0000 nm)"), "{out}");
    let w = f.world();
    let s = w.surface.spheres[0];
    let miss = (s.x - 52e-6).hypot(s.y - 50e-6);
    assert!(miss < 20e-9, "the particle ended {:.1} nm from the target", miss * 1e9);
    assert!(w.withdrawn && !w.z_on);
    assert!(dir.join("scan-after.gsf").exists() && dir.join("scan-before.png").exists());
    drop(w);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn every_fault_of_the_controller_ends_in_a_named_error_and_a_withdrawn_tip() {
    for (fault, named) in [
        (
            "error:ZCtrl.OnOffSet*2",
            "the controller reports error 1: Fake fault: ZCtrl.OnOffSet failed",
        ),
        (
            "drop:FolMe.XYPosSet",
            "FolMe.XYPosSet: the controller closed the connection",
        ),
        ("slow:FolMe.SpeedSet:4000", "FolMe.SpeedSet: no answer within 1.0 s"),
        (
            "wrong-name:ZCtrl.SetpntSet",
            "the controller answered \"Bias.Get\" instead",
        ),
        ("short:Scan.FrameDataGrab", "Scan.FrameDataGrab"),
        ("error:Scan.Action", "Scan.Action: the controller reports error 1"),
        ("logger-drop:700", "TCP Logger stream"),
    ] {
        let f = fake();
        f.add_fault(fault.parse::<Fault>().unwrap());
        let o = run(
            "nanopush",
            &[
                "push",
                "--instrument",
                &spec(&f),
                "--instrument-timeout-s",
                "1",
                "--travel-speed-um-per-s",
                "1",
                "--at-um",
                "50,50",
                "--to-um",
                "52,50",
            ],
            None,
        );
        let (out, err) = text(&o);
        assert!(!o.status.success(), "{fault}: it succeeded:\n{out}");
        assert!(err.contains(named), "{fault}: expected {named:?} in:\n{err}");
        assert!(
            err.contains("withdrawn") && !err.contains("could NOT"),
            "{fault}: {err}"
        );
        assert!(!err.contains("panicked"), "{fault}: {err}");
        let w = f.world();
        assert!(w.withdrawn && !w.z_on, "{fault}: the tip is left withdrawn");
    }
}

#[test]
fn a_bad_instrument_is_named_with_what_is_expected() {
    let dir = tmp("nanonis-bad");
    let gsf = dir.join("s.gsf");
    let out = gsf.to_str().unwrap();
    for (spec, says) in [
        ("afm:1.2.3.4:5", "unknown backend; expected nanonis:HOST:PORT[,LOGPORT]"),
        ("nanonis:127.0.0.1", "no port"),
        ("nanonis:127.0.0.1:0", "port \"0\" is not a port in [1, 65535]"),
        ("nanonis:127.0.0.1:6501,x", "logger port \"x\""),
    ] {
        let o = run("nanopush", &["scan", "--instrument", spec, "--out", out], None);
        assert!(!o.status.success());
        assert!(text(&o).1.contains(says), "{spec}: {}", text(&o).1);
    }
    // Nothing listening: a link error naming the address, at once.
    let f = fake();
    let addr = f.addr();
    drop(f);
    let o = run(
        "nanopush",
        &["scan", "--instrument", &format!("nanonis:{addr}"), "--out", out],
        None,
    );
    let err = text(&o).1;
    assert!(!o.status.success() && err.contains(&addr.to_string()), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn an_interrupt_during_a_push_withdraws_the_tip_before_exiting() {
    use std::process::{Command, Stdio};
    let f = fake();
    let child = Command::new(nanopush_e2e::bin("nanopush"))
        .args([
            "push",
            "--instrument",
            &spec(&f),
            "--at-um",
            "50,50",
            "--to-um",
            "52,50",
            "--push-speed-um-per-s",
            "0.2",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Landed and pushing: the Z feedback on and the tip moving.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(30);
    while !(f.world().z_on && f.commands().iter().filter(|c| *c == "FolMe.XYPosSet").count() >= 2) {
        assert!(
            std::time::Instant::now() < deadline,
            "the push never started: {:?}",
            f.commands()
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    // SAFETY: a signal to our own child.
    unsafe { libc::kill(child.id() as i32, libc::SIGINT) };
    let asked = std::time::Instant::now();
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        asked.elapsed() < std::time::Duration::from_secs(5),
        "{:?}",
        asked.elapsed()
    );
    assert!(!o.status.success());
    assert!(
        err.contains("interrupted during the push (push): the tip was withdrawn"),
        "{err}"
    );
    let w = f.world();
    assert!(w.withdrawn && !w.z_on, "the tip is withdrawn");
}

#[test]
fn a_target_outside_the_frame_or_too_few_pixels_are_refused_before_anything_moves() {
    let f = fake();
    let dir = tmp("nanonis-refused");
    let o = run(
        "nanopush",
        &[
            "push",
            "--instrument",
            &spec(&f),
            "--at-um",
            "50,50",
            "--to-um",
            "80,50",
        ],
        None,
    );
    let err = text(&o).1;
    assert!(
        err.contains("the target (80.0000, 50.0000) µm is outside the limits") && err.contains("nothing was sent"),
        "{err}"
    );
    let gsf = dir.join("s.gsf");
    let o = run(
        "nanopush",
        &[
            "scan",
            "--instrument",
            &spec(&f),
            "--size",
            "8",
            "--out",
            gsf.to_str().unwrap(),
        ],
        None,
    );
    let err = text(&o).1;
    assert!(
        err.contains("--size 8 pixels is out of range for a controller's scan buffer; allowed: [16, 4096]"),
        "{err}"
    );
    let moving = [
        "FolMe.",
        "ZCtrl.OnOff",
        "ZCtrl.Setpnt",
        "ZCtrl.Withdraw",
        "Scan.Action",
        "Scan.FrameSet",
        "Scan.BufferSet",
    ];
    for c in f.commands() {
        assert!(!moving.iter().any(|m| c.starts_with(m)), "sent {c}");
    }
    std::fs::remove_dir_all(&dir).ok();
}
