use super::*;
use crate::afm::{Capabilities, Limits, ScanFrame};
use crate::scan::HeightImage;

/// A controller whose readings a test writes: the tip moves 1 µm per reading towards its
/// target; `normal` and `lateral` give each reading's deflections from its number.
struct Scripted {
    t: f64,
    tip: [f64; 2],
    target: Option<[f64; 2]>,
    held: bool,
    withdrawn: bool,
    sent: Vec<&'static str>,
    normal: fn(u64, bool) -> f64,
    tip_nan: bool,
    n: u64,
}

impl Scripted {
    fn new(normal: fn(u64, bool) -> f64) -> Scripted {
        Scripted {
            t: 0.0,
            tip: [10e-6, 10e-6],
            target: None,
            held: false,
            withdrawn: false,
            sent: Vec::new(),
            normal,
            tip_nan: false,
            n: 0,
        }
    }
}

impl Microscope for Scripted {
    fn capabilities(&self) -> Capabilities {
        Capabilities {
            backend: "scripted".into(),
            feed_rate_hz: 1000.0,
            z_closed_locally: true,
            scan_engine: false,
            read_only: false,
        }
    }
    fn limits(&mut self) -> Result<Limits, MicroscopeError> {
        Ok(Limits {
            x: [0.0, 50e-6],
            y: [0.0, 50e-6],
            z: [-1e-6, 1e-6],
            max_speed: 20e-6,
        })
    }
    fn start_move(&mut self, x: f64, y: f64, _speed: f64) -> Result<(), MicroscopeError> {
        self.sent.push("move");
        self.target = Some([x, y]);
        Ok(())
    }
    fn stop_move(&mut self) -> Result<(), MicroscopeError> {
        self.sent.push("stop");
        self.target = None;
        Ok(())
    }
    fn poll(&mut self) -> Result<(Sample, bool), MicroscopeError> {
        self.t += 1e-3;
        self.n += 1;
        let arrived = match self.target {
            Some([x, y]) => {
                let (dx, dy) = (x - self.tip[0], y - self.tip[1]);
                let d = dx.hypot(dy);
                if d <= 1e-6 {
                    self.tip = [x, y];
                    self.target = None;
                    true
                } else {
                    self.tip = [self.tip[0] + dx / d * 1e-6, self.tip[1] + dy / d * 1e-6];
                    false
                }
            }
            None => true,
        };
        let x = if self.tip_nan { f64::NAN } else { self.tip[0] };
        let s = Sample {
            t: self.t,
            tip: [x, self.tip[1], 0.0],
            normal: (self.normal)(self.n, self.held),
            lateral: Some(0.0),
        };
        Ok((s, arrived))
    }
    fn hold_force(&mut self, _setpoint: f64) -> Result<(), MicroscopeError> {
        self.sent.push("hold");
        self.held = true;
        self.withdrawn = false;
        Ok(())
    }
    fn scan(&mut self, _: Option<&ScanFrame>) -> Result<HeightImage, MicroscopeError> {
        unreachable!("a held push does not scan")
    }
    fn current_frame(&mut self) -> Result<ScanFrame, MicroscopeError> {
        unreachable!("a held push does not scan")
    }
    fn withdraw(&mut self) -> Result<(), MicroscopeError> {
        self.sent.push("withdraw");
        self.held = false;
        self.withdrawn = true;
        Ok(())
    }
}

fn push() -> HeldPush {
    HeldPush {
        from: [20e-6, 20e-6],
        to: [25e-6, 20e-6],
        radius: 0.5e-6,
        tip_radius: 20e-9,
        approach_gap: 0.1e-6,
        travel_speed: 10e-6,
        push_speed: 1e-6,
        setpoint: 0.1,
        land_tolerance: 0.005,
        settle_samples: 5,
        lateral_contact: 0.1,
        normal_limit: 0.5,
        land_timeout: 2.0,
    }
}

fn held(n: u64, on: bool) -> f64 {
    let _ = n;
    if on { 0.1 } else { 0.0 }
}

#[test]
fn a_push_on_a_well_behaved_controller_runs_every_phase_and_withdraws() {
    let mut m = Scripted::new(held);
    let r = held_push(&mut m, &push(), &AtomicBool::new(false)).unwrap();
    assert_eq!(r.phases.len(), 5);
    assert_eq!(
        r.outcome,
        HeldOutcome::NoContact,
        "the script never reads a lateral contact"
    );
    assert!(m.withdrawn);
}

#[test]
fn a_reading_that_is_not_a_number_ends_the_push_and_withdraws() {
    let mut m = Scripted::new(held);
    m.tip_nan = true;
    let e = held_push(&mut m, &push(), &AtomicBool::new(false))
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("travel: a reading that is not a number"), "{e}");
    assert!(e.ends_with("; the tip was withdrawn"), "{e}");
    assert!(m.withdrawn);
    assert_eq!(
        m.sent[m.sent.len() - 2..],
        ["withdraw", "stop"],
        "the motion cut short is stopped after the withdraw"
    );
    let mut m = Scripted::new(|n, on| if on && n > 23 { f64::NAN } else { held(n, on) });
    let e = held_push(&mut m, &push(), &AtomicBool::new(false))
        .unwrap_err()
        .to_string();
    assert!(e.contains("not a number") && e.contains("normal NaN"), "{e}");
    assert!(m.withdrawn);
}

#[test]
fn a_landing_that_never_settles_ends_at_its_time_out() {
    let mut m = Scripted::new(|_, _| 0.0);
    let e = held_push(&mut m, &push(), &AtomicBool::new(false))
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("land: the normal deflection did not settle") && e.contains("in 2 s"),
        "{e}"
    );
    assert!(m.t < 2.1, "ended at {} s of the controller's clock", m.t);
    assert!(m.withdrawn);
}

#[test]
fn a_motion_that_never_arrives_ends_at_twice_its_time_and_the_slack() {
    let mut m = Scripted::new(held);
    // The tip crawls: a reading every ms, but a travel of 10 µm at 10 µm/s "takes" 1 s and
    // the script never gets there once stuck.
    m.tip = [10e-6, 10e-6];
    struct Stuck(Scripted);
    impl Microscope for Stuck {
        fn capabilities(&self) -> Capabilities {
            self.0.capabilities()
        }
        fn limits(&mut self) -> Result<Limits, MicroscopeError> {
            self.0.limits()
        }
        fn start_move(&mut self, x: f64, y: f64, v: f64) -> Result<(), MicroscopeError> {
            self.0.start_move(x, y, v)
        }
        fn stop_move(&mut self) -> Result<(), MicroscopeError> {
            self.0.stop_move()
        }
        fn poll(&mut self) -> Result<(Sample, bool), MicroscopeError> {
            let target = self.0.target;
            let r = self.0.poll();
            self.0.tip = [10e-6, 10e-6];
            self.0.target = target;
            r.map(|(s, _)| (s, false))
        }
        fn hold_force(&mut self, v: f64) -> Result<(), MicroscopeError> {
            self.0.hold_force(v)
        }
        fn scan(&mut self, f: Option<&ScanFrame>) -> Result<HeightImage, MicroscopeError> {
            self.0.scan(f)
        }
        fn current_frame(&mut self) -> Result<ScanFrame, MicroscopeError> {
            self.0.current_frame()
        }
        fn withdraw(&mut self) -> Result<(), MicroscopeError> {
            self.0.withdraw()
        }
    }
    let mut stuck = Stuck(m);
    let e = held_push(&mut stuck, &push(), &AtomicBool::new(false))
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("travel: the motion did not arrive within"), "{e}");
    assert!(stuck.0.t < 15.0, "ended at {} s", stuck.0.t);
    assert!(stuck.0.withdrawn);
}

#[test]
fn a_push_that_would_leave_the_limits_sends_nothing() {
    let mut m = Scripted::new(held);
    let p = HeldPush {
        to: [60e-6, 20e-6],
        ..push()
    };
    let e = held_push(&mut m, &p, &AtomicBool::new(false)).unwrap_err().to_string();
    assert!(
        e.contains("outside the limits") && e.contains("nothing was sent"),
        "{e}"
    );
    assert!(m.sent.is_empty(), "{:?}", m.sent);
    let p = HeldPush {
        push_speed: 30e-6,
        ..push()
    };
    let e = held_push(&mut m, &p, &AtomicBool::new(false)).unwrap_err().to_string();
    assert!(
        e.contains("push speed 30.000 µm/s is over the fastest allowed, 20.000 µm/s"),
        "{e}"
    );
    assert!(m.sent.is_empty());
}
