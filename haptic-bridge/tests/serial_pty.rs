//! The serial backend end to end over a pseudo-terminal: `SerialDevice` on the slave side, driven
//! through the `Device` trait; on the master side a fake 1-DOF device in a thread, which speaks the
//! protocol as the README documents it (its own parser and encoder, not the library's): it answers
//! each force packet with a state packet, its handle moves under the force, and it zeroes the force
//! after 10 ms without a valid force packet, like the firmware. Every wait is on a condition with a
//! time-out, so the tests hold on a loaded machine.

#[path = "serial_pty/fake.rs"]
mod fake;

use std::os::fd::OwnedFd;
use std::time::{Duration, Instant};

use nanopush_haptic::device::{BUTTON_CLUTCH, BUTTON_ENGAGE, Device, DeviceError};
use nanopush_haptic::serial::{
    HOLD_CYCLES, SerialDevice, SerialOptions, conformance, exchange_wire_time, negotiate_rate,
};

use fake::*;

#[test]
fn the_device_reports_its_limits_and_its_handle_in_si() {
    let (mut dev, fake, _slave) = setup(World::default(), patient());
    let spec = dev.spec();
    assert_eq!(spec.name, "serial");
    assert_eq!(spec.max_force, 2.0);
    assert_eq!(spec.travel, [-0.03, 0.03]);
    assert_eq!(spec.max_stiffness, 300.0);
    assert_eq!(spec.max_damping, 1.2);
    assert_eq!(dev.rate_hz(), 1000);
    assert!(dev.device().starts_with("serial:/dev/"));

    {
        let mut w = fake.world();
        w.pose = Some((12_345, -67_890));
        w.buttons = 0x03;
    }
    let s = cycle_until(&mut dev, 0.0, "the posed handle", |s| s.buttons != 0);
    assert!((s.position - 0.012_345).abs() < 1e-12, "{s:?}");
    assert!((s.velocity + 0.067_89).abs() < 1e-12, "{s:?}");
    assert_eq!(s.buttons, BUTTON_ENGAGE | BUTTON_CLUTCH);

    {
        let mut w = fake.world();
        w.pose = Some((-29_000, 1_500_000));
        w.buttons = 0x01;
    }
    let s = cycle_until(&mut dev, 0.0, "the engage button alone", |s| s.buttons == BUTTON_ENGAGE);
    assert!(
        (s.position + 0.029).abs() < 1e-12 && (s.velocity - 1.5).abs() < 1e-12,
        "{s:?}"
    );
    assert_eq!(dev.bad_packets(), 0);
}

#[test]
fn a_force_written_arrives_and_moves_the_handle() {
    let (mut dev, fake, _slave) = setup(World::default(), patient());
    let start = dev.read(1e-3).unwrap().position;
    let up = cycle_until(&mut dev, 1.0, "the handle pushed up by 2 mm", |s| {
        s.position > start + 0.002
    });
    assert!(up.velocity > 0.0, "{up:?}");
    assert_eq!(dev.applied_force(), 1.0);
    assert_eq!(
        fake.world().received.last().map(|r| (r.1, r.2)),
        Some((0x01, 1_000_000))
    );

    let down = cycle_until(&mut dev, -1.5, "the handle pushed down past its start", |s| {
        s.position < start
    });
    assert!(down.velocity < 0.0, "{down:?}");
    assert_eq!(dev.applied_force(), -1.5);
    assert_eq!(
        fake.world().received.last().map(|r| (r.1, r.2)),
        Some((0x01, -1_500_000))
    );
}

#[test]
fn forces_are_clamped_to_the_devices_limit_before_the_wire() {
    let (mut dev, fake, _slave) = setup(World::default(), patient());
    let before = fake.world().received.len();
    let forces = [
        10.0,
        -1e12,
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        0.5,
        -1.999_999_7,
    ];
    for f in forces {
        cycle(&mut dev, f);
    }
    fake.wait_until("all the force packets", |w| w.received.len() >= before + forces.len());
    let w = fake.world();
    let got: Vec<(u8, i32)> = w.received[before..].iter().map(|r| (r.1, r.2)).collect();
    let want = [2_000_000, -2_000_000, 0, 2_000_000, -2_000_000, 500_000, -2_000_000].map(|f| (0x01, f));
    assert_eq!(got, want);
    let seqs: Vec<u16> = w.received[before..].iter().map(|r| r.0).collect();
    assert!(seqs.windows(2).all(|p| p[1] == p[0].wrapping_add(1)), "{seqs:?}");
}

#[test]
fn a_corrupted_state_packet_is_skipped_and_counted() {
    let (mut dev, fake, _slave) = setup(World::default(), patient());
    cycle(&mut dev, 0.2);
    // Answered (under load perhaps after the read gave up): the next answer is the one to corrupt,
    // and the read that waits for it must time out.
    fake.wait_until("the first force", |w| w.received.last().map(|r| r.2) == Some(200_000));
    assert_eq!(dev.bad_packets(), 0);
    let timeouts = dev.timeouts();

    fake.world().corrupt = 1;
    let start = Instant::now();
    while dev.bad_packets() == 0 {
        // Read as valid, the corrupted position would be a protocol error: every read is Ok.
        let s = cycle(&mut dev, 0.2);
        assert!(s.position.abs() < 0.04, "{s:?}");
        assert!(start.elapsed() < PATIENCE, "the corrupted packet was never counted");
    }
    assert_eq!(fake.world().corrupt, 0);
    assert!(
        dev.timeouts() > timeouts,
        "the read waiting for the corrupted answer timed out"
    );
    let bad = dev.bad_packets();

    // Bytes without a sync byte before an answer are skipped, not counted as packets.
    fake.world().garbage = vec![0x00, 0x13, 0x37, 0x53, 0x49, 0xFF];
    cycle_until(&mut dev, 0.2, "the answer after the garbage", |_| {
        fake.world().garbage.is_empty()
    });
    cycle(&mut dev, 0.2);
    assert_eq!(dev.bad_packets(), bad);
}

/// A device that stops answering: the previous state holds for `HOLD_CYCLES` late answers in a
/// row (so one lost or late packet does not zero the force), then the read fails as silent.
#[test]
fn a_silent_device_holds_the_last_state_briefly_then_is_silent() {
    let options = SerialOptions {
        open_timeout: PATIENCE,
        ..SerialOptions::default()
    };
    let (mut dev, fake, _slave) = setup(World::default(), options);
    let mut prev = cycle(&mut dev, 0.3);
    fake.world().mute = true;
    // A late answer already in flight may still arrive: wait until the answers stop.
    let muted = Instant::now();
    let mut held = 0;
    let err = loop {
        dev.write_force(0.3).unwrap();
        let timeouts = dev.timeouts();
        match dev.read(1e-3) {
            Ok(s) if dev.timeouts() > timeouts => {
                held += 1;
                assert!(held <= HOLD_CYCLES, "held {held} cycles");
                assert_eq!(s, prev, "the previous state holds");
            }
            Ok(s) => {
                assert!(muted.elapsed() < PATIENCE, "the device never went silent");
                prev = s;
            }
            Err(e) => break e,
        }
    };
    assert_eq!((held, HOLD_CYCLES), (3, 3), "the README's 3 cycles");
    assert!(matches!(err, DeviceError::Silent { .. }), "expected Silent, got {err}");
    assert!(dev.timeouts() > u64::from(HOLD_CYCLES));
}

#[test]
fn the_device_zeroes_the_force_when_the_host_falls_silent() {
    let (mut dev, fake, _slave) = setup(World::default(), patient());
    cycle(&mut dev, 1.0);
    fake.wait_until("the watchdog zeroing the force", |w| w.watchdog_trips >= 1);
    assert!(!fake.world().active && fake.world().applied_un == 0);
    assert_eq!(dev.watchdog_trips(), 0);
    // The next state packet says the force was zeroed; the host counts it.
    let start = Instant::now();
    while dev.watchdog_trips() == 0 {
        cycle(&mut dev, 1.0);
        assert!(start.elapsed() < PATIENCE, "the host never heard of the zeroed force");
    }
}

#[test]
fn close_sends_zero_force_and_the_device_confirms_it() {
    let (mut dev, fake, _slave) = setup(World::default(), patient());
    cycle_until(&mut dev, 1.5, "the force rendered", |_| {
        fake.world().applied_un == 1_500_000
    });
    dev.close().expect("close");
    assert_eq!(dev.applied_force(), 0.0);
    let w = fake.world();
    assert_eq!(w.received.last().map(|r| (r.1, r.2)), Some((0x00, 0)));
    assert!(!w.active && w.applied_un == 0);
}

#[test]
fn dropping_a_live_device_sends_zero_force() {
    let (mut dev, fake, _slave) = setup(World::default(), patient());
    cycle(&mut dev, -1.5);
    fake.wait_until("the force", |w| {
        w.received.last().map(|r| (r.1, r.2)) == Some((0x01, -1_500_000))
    });
    drop(dev);
    fake.wait_until("a zero-force packet after the drop", |w| {
        w.received.last().map(|r| (r.1, r.2)) == Some((0x00, 0))
    });
    assert!(!fake.world().active);
}

#[test]
fn a_state_out_of_the_devices_range_is_a_protocol_error() {
    let (mut dev, fake, _slave) = setup(World::default(), patient());
    // 30 mm of travel each way and 6 mm of give: 40 mm cannot be.
    fake.world().pose = Some((40_000, 0));
    let start = Instant::now();
    let err = loop {
        dev.write_force(0.0).unwrap();
        match dev.read(1e-3) {
            Ok(s) => assert!(s.position.abs() < 0.036 && start.elapsed() < PATIENCE, "{s:?}"),
            Err(e) => break e,
        }
    };
    assert!(matches!(err, DeviceError::Protocol { .. }), "{err}");
    assert!(err.to_string().contains("40.000 mm is outside the travel"), "{err}");
}

/// An unplugged cable is a fault, not a silence: the hang-up is [`DeviceError::Lost`],
/// which the bridge answers by reopening the device.
#[test]
fn an_unplugged_device_is_lost() {
    let (mut dev, fake, _slave) = setup(World::default(), patient());
    cycle(&mut dev, 0.5);
    // The fake's thread owns the master side: stopping it closes it, which hangs the slave up.
    drop(fake);
    let start = Instant::now();
    let err = loop {
        match dev.write_force(0.5).and_then(|()| dev.read(1e-3)) {
            Ok(_) => assert!(start.elapsed() < PATIENCE, "the hang-up never showed"),
            Err(e) => break e,
        }
    };
    assert!(matches!(err, DeviceError::Lost { .. }), "{err}");
    assert!(err.to_string().contains("lost"), "{err}");
}

#[test]
fn a_device_of_another_protocol_version_is_named() {
    let (master, _slave, path) = open_pty();
    let _fake = Fake::start(
        master,
        World {
            version: 2,
            ..World::default()
        },
    );
    let err = SerialDevice::open_with(&path, patient()).err().expect("open must fail");
    assert!(matches!(err, DeviceError::Protocol { .. }), "{err}");
    assert!(err.to_string().contains("protocol version 2"), "{err}");
}

#[test]
fn opening_what_does_not_answer_fails_with_a_typed_error() {
    let (_master, _slave, path) = open_pty();
    let options = SerialOptions {
        open_timeout: Duration::from_millis(300),
        ..SerialOptions::default()
    };
    let start = Instant::now();
    match SerialDevice::open_with(&path, options) {
        Err(DeviceError::Silent { ms, .. }) => assert_eq!(ms, 300),
        Err(e) => panic!("expected Silent, got {e}"),
        Ok(_) => panic!("nothing answers on {path}"),
    }
    assert!(start.elapsed() >= Duration::from_millis(300));

    match SerialDevice::open("/dev/null") {
        Err(e @ DeviceError::Io { .. }) => assert!(e.to_string().contains("not a terminal"), "{e}"),
        other => panic!("expected an I/O error, got {:?}", other.err()),
    }
    match SerialDevice::open("/nonexistent/ttyACM9") {
        Err(DeviceError::Io { source, .. }) => assert_eq!(source.kind(), std::io::ErrorKind::NotFound),
        other => panic!("expected an I/O error, got {:?}", other.err()),
    }
    assert!(matches!(
        SerialDevice::open("/dev/ttyACM0@1234"),
        Err(DeviceError::BadSpec { .. })
    ));
}

/// The answer deadline the conformance runs on a fake device use (see the next test).
const LOOSE: conformance::Deadline = conformance::Deadline {
    answer: Duration::from_millis(100),
};

/// The conformance test a maker runs against their board passes on a fake that follows the
/// specification, paced like a UART at 1 Mbaud. The answers are timed on the host, and this fake
/// shares a loaded test machine with the other tests, so its deadline here is 100 ms instead of
/// the specification's 2 (a loaded CI machine has taken 3.3 ms for one answer); the rule itself
/// is held to by a device that is late by construction, below.
#[test]
fn the_conformance_test_passes_on_a_device_that_follows_the_specification() {
    let (master, _slave, path) = open_pty();
    let _fake = Fake::start(
        master,
        World {
            baud: Some(1_000_000),
            ..World::default()
        },
    );
    let checks = conformance::run_with(&path, LOOSE).expect("the board is there");
    let failed: Vec<String> = checks.iter().filter(|c| !c.pass).map(|c| c.to_string()).collect();
    assert!(failed.is_empty(), "{failed:#?}");
    assert_eq!(checks.len(), 12, "{checks:#?}");
}

/// A firmware that answers each force packet 5 ms after reading it fails the specification's
/// 2 ms deadline on every one of the 200 exchanges, whatever the host's load (load only makes it
/// later), and the checks of framing and sequence still pass.
#[test]
fn the_conformance_test_names_a_device_that_answers_late() {
    let (master, _slave, path) = open_pty();
    let _fake = Fake::start(
        master,
        World {
            answer_delay: Duration::from_millis(5),
            ..World::default()
        },
    );
    let checks = conformance::run(&path).expect("the board is there");
    let timing = checks
        .iter()
        .find(|c| c.name.contains("answered in time"))
        .expect("a timing check");
    assert!(!timing.pass, "{timing}");
    assert!(
        timing.detail.starts_with("200 exchanges: 200 not answered within 2 ms"),
        "{timing}"
    );
    for name in ["sequence number", "framed and checksummed"] {
        let c = checks.iter().find(|c| c.name.contains(name)).expect(name);
        assert!(c.pass, "{c}");
    }
}

/// A board without a watchdog fails the conformance test, on that rule and no other.
#[test]
fn the_conformance_test_names_a_device_without_a_watchdog() {
    let (master, _slave, path) = open_pty();
    let _fake = Fake::start(
        master,
        World {
            watchdog: false,
            ..World::default()
        },
    );
    let checks = conformance::run_with(&path, LOOSE).expect("the board is there");
    let failed: Vec<&conformance::Check> = checks.iter().filter(|c| !c.pass).collect();
    assert_eq!(failed.len(), 1, "{checks:#?}");
    assert!(failed[0].name.contains("watchdog"), "{}", failed[0]);
    assert!(failed[0].to_string().starts_with("FAIL "), "{}", failed[0]);
}

/// The rate is the lesser of `--rate-hz`, the device's
/// declared rate and 80 % of what the baud carries, never below 500 Hz; a device that declares
/// 100 Hz, or a link at 115 200 baud (256 Hz), is refused with the numbers.
#[test]
fn the_rate_fits_the_device_and_its_baud_or_is_refused_with_the_numbers() {
    let open = |rate_hz: u16, baud: u32| {
        let (master, slave, path) = open_pty();
        let fake = Fake::start(
            master,
            World {
                rate_hz,
                ..World::default()
            },
        );
        let options = SerialOptions { baud, ..patient() };
        let dev = SerialDevice::open_with(&path, options).expect("open");
        (dev, fake, slave, path)
    };
    let (dev, _f1, _s1, path) = open(1000, 1_000_000);
    assert_eq!(negotiate_rate(&dev, Some(&path), 1000.0).unwrap(), (1000.0, None));
    let (dev, _f0, _s0, path) = open(1000, 115_200);
    let slow = negotiate_rate(&dev, Some(&format!("{path}@115200")), 1000.0).unwrap_err();
    assert!(
        slow.contains("115200 baud") && slow.contains("3.12 ms") && slow.contains("at most 256 Hz"),
        "{slow}"
    );
    assert!(
        slow.contains("the floor is 500 Hz") && slow.contains("@1000000"),
        "{slow}"
    );
    let (dev, _f2, _s2, path) = open(800, 1_000_000);
    let (rate, why) = negotiate_rate(&dev, Some(&path), 1000.0).unwrap();
    assert_eq!(rate, 800.0);
    assert!(why.unwrap().contains("the device declares 800 Hz"));
    let (dev, _f3, _s3, path) = open(100, 1_000_000);
    let refused = negotiate_rate(&dev, Some(&path), 1000.0).unwrap_err();
    assert!(
        refused.contains("declares 100 Hz") && refused.contains("floor is 500 Hz"),
        "{refused}"
    );
}

/// At 115 200 baud (3.1 ms an exchange on the wire) the answers to 200 cycles at 1 kHz are late
/// (load only makes them later), which is why the bridge refuses that baud; at 1 Mbaud the wire
/// takes 0.3 ms of the cycle ([`exchange_wire_time`]). That 1 Mbaud keeps up in real time is a
/// timing claim about this machine, so it is not asserted here: only that every answer comes.
#[test]
fn a_fast_uart_answers_every_cycle_and_a_slow_one_cannot() {
    assert!(exchange_wire_time(1_000_000) < Duration::from_micros(400));
    assert!(exchange_wire_time(115_200) > Duration::from_millis(3));
    // (baud, how long a read waits): the slow link within the 1 ms cycle, the fast one patiently.
    for (baud, wait_s) in [(1_000_000, 500e-3), (115_200, 1e-3)] {
        let world = World {
            baud: Some(baud),
            ..World::default()
        };
        let (mut dev, _fake, _slave) = setup(world, patient());
        let before = dev.timeouts();
        for _ in 0..200 {
            let start = Instant::now();
            dev.write_force(0.0).unwrap();
            let _ = dev.read(wait_s);
            if let Some(rest) = Duration::from_millis(1).checked_sub(start.elapsed()) {
                std::thread::sleep(rest);
            }
        }
        let late = dev.timeouts() - before;
        if baud == 115_200 {
            assert!(late >= 150, "{baud} baud: only {late} of 200 late");
        } else {
            // A handful may go unanswered (CI has seen 1 of 200 even at 500 ms: not a matter of
            // timing, and its cause is not known).
            assert!(late <= 5, "{baud} baud: {late} of 200 unanswered in 500 ms");
        }
    }
}

/// Each kind of device fault is counted apart, and one
/// bad packet, one lost answer or one state out of range does not fail the read (the previous
/// state holds, so the force does not drop to zero).
#[test]
fn each_device_fault_is_counted_apart_and_one_does_not_zero_the_force() {
    let (mut dev, fake, _slave) = setup(World::default(), patient());
    cycle(&mut dev, 0.1);
    let zero = dev.faults();
    fake.world().corrupt = 1;
    cycle(&mut dev, 0.1);
    fake.world().skip_seq = 3;
    cycle(&mut dev, 0.1);
    cycle(&mut dev, 0.1);
    fake.world().pose = Some((40_000, 0));
    cycle(&mut dev, 0.1);
    fake.world().pose = None;
    cycle_until(&mut dev, 0.1, "a good state again", |s| s.position.abs() < 0.03);
    let f = dev.faults();
    assert_eq!(f.bad_packets - zero.bad_packets, 1, "{f:?}");
    assert_eq!(f.seq_gaps - zero.seq_gaps, 1, "{f:?}");
    assert_eq!(f.out_of_range - zero.out_of_range, 1, "{f:?}");
    assert_eq!(f.losses + f.reopens, 0, "the device side only: {f:?}");
}

/// The bridge process on a fake device behind a symlink (as a udev `/dev/serial/by-id/` link
/// is): its stderr lines and its `--json` summary.
struct BridgeRun {
    child: std::process::Child,
    link: std::path::PathBuf,
}

impl BridgeRun {
    fn start(link: &std::path::Path, extra: &[&str]) -> BridgeRun {
        let child = std::process::Command::new(env!("CARGO_BIN_EXE_nanopush-haptic"))
            .args([
                "--device",
                &format!("serial:{}", link.display()),
                "--no-realtime",
                "--json",
            ])
            .args(extra)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .expect("start nanopush-haptic");
        BridgeRun {
            child,
            link: link.to_path_buf(),
        }
    }

    /// Waits for the process to end; its exit code, stdout and stderr.
    fn finish(mut self) -> (i32, String, String) {
        let start = Instant::now();
        loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                let out = std::io::read_to_string(self.child.stdout.take().unwrap()).unwrap();
                let err = std::io::read_to_string(self.child.stderr.take().unwrap()).unwrap();
                return (status.code().unwrap_or(-1), out, err);
            }
            assert!(start.elapsed() < PATIENCE, "the bridge did not end");
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

/// Points `link` at a new pseudo-terminal with a fake device on it (a plug-in).
fn plug_in(link: &std::path::Path) -> (Fake, OwnedFd) {
    let (master, slave, path) = open_pty();
    let fake = Fake::start(master, World::default());
    let _ = std::fs::remove_file(link);
    std::os::unix::fs::symlink(&path, link).unwrap();
    (fake, slave)
}

/// A cable is a fault, not a silence: unplugged in the middle of a run, the bridge
/// says so (naming the device and the side), zeroes the force, reopens the device by its path
/// when it is plugged in again, and counts the loss and the reopen; `--exit-on-device-loss`
/// ends the run with code 3 instead, and a device still lost at the end is exit code 3 too.
#[test]
fn an_unplugged_cable_is_reported_reopened_by_its_path_and_counted() {
    let dir = std::env::temp_dir().join(format!("nanopush-cable-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let link = dir.join("by-id-hapkit");

    // Unplugged for a second, then plugged in again: the run goes on.
    let (fake, slave) = plug_in(&link);
    let run = BridgeRun::start(&link, &["--duration", "3"]);
    fake.wait_until("the bridge's active packets", |w| w.received.len() > 200);
    drop(fake);
    drop(slave);
    std::fs::remove_file(&run.link).unwrap();
    std::thread::sleep(Duration::from_millis(1000));
    let (fake, _slave) = plug_in(&link);
    let (code, out, err) = run.finish();
    assert!(
        fake.world().received.len() > 200,
        "the bridge came back on the re-plugged device: {err}"
    );
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains(&format!("cable: serial:{} was lost", link.display())),
        "{err}"
    );
    assert!(err.contains("reopening it by its path"), "{err}");
    assert!(
        err.contains(&format!("cable: serial:{} is back after", link.display())),
        "{err}"
    );
    let summary: serde_json::Value = serde_json::from_str(&out).expect(&out);
    assert_eq!(summary["device_faults"]["losses"], 1, "{summary}");
    assert_eq!(summary["device_faults"]["reopens"], 1, "{summary}");
    assert!(summary["device_lost"].is_null(), "{summary}");
    drop(fake);

    // --exit-on-device-loss: code 3 at the loss.
    let (fake, slave) = plug_in(&link);
    let run = BridgeRun::start(&link, &["--duration", "30", "--exit-on-device-loss"]);
    fake.wait_until("the bridge's packets", |w| w.received.len() > 100);
    drop(fake);
    drop(slave);
    let (code, out, err) = run.finish();
    assert_eq!(code, 3, "{err}");
    assert!(err.contains("was lost"), "{err}");
    let summary: serde_json::Value = serde_json::from_str(&out).expect(&out);
    assert_eq!(summary["device_faults"]["losses"], 1, "{summary}");
    assert!(summary["device_lost"].is_string(), "{summary}");
    let _ = std::fs::remove_dir_all(&dir);
}
