use super::*;
use crate::operator::Script;
use crate::sim::SimDevice;

/// A link in memory: what the bridge published, and a queue of force samples to hand it.
#[derive(Default)]
struct Loop {
    published: Vec<HapticState>,
    next: Option<ForceFeedback>,
}

impl Link for Loop {
    fn publish(&mut self, s: &HapticState) {
        self.published.push(*s);
    }
    fn newest(&mut self) -> Option<ForceFeedback> {
        self.next.take()
    }
}

fn live(force: f64, now_ns: u64) -> ForceFeedback {
    ForceFeedback {
        time_ns: now_ns,
        force,
        active: 1,
        half_range: 1.0,
        state_seq: u64::MAX,
        ..Default::default()
    }
}

/// docs/haptics.md, "Passivity": the damping is "capped at 80 % of the damping the device renders
/// (`m/T`)" and never applied "at `|v| < 0.1 mm/s`": the bridge's controller for the
/// simulated handle at 1, 2 and 4 kHz.
#[test]
fn the_bridges_passivity_cap_and_speed_guard_are_as_documented() {
    for rate in [1000.0, 2000.0, 4000.0] {
        let period = 1.0 / rate;
        let cfg = BridgeConfig {
            rate_hz: rate,
            ..BridgeConfig::default()
        };
        let b = Bridge::new(SimDevice::new(Script::Hold, period), cfg, 0);
        let m_over_t = crate::sim::Handle::default().mass / period;
        assert!((b.spec.max_damping - m_over_t).abs() <= 1e-12 * m_over_t);
        assert!((b.pc.alpha_max - 0.8 * m_over_t).abs() <= 1e-12 * m_over_t);
        assert_eq!(b.pc.v_min, 1e-4);
        assert!(b.pc.enabled);
    }
}

/// A device whose answers take as long as its test says, and whose watchdog trips on demand.
struct Slow {
    sim: SimDevice,
    trips: u64,
}

impl Device for Slow {
    fn spec(&self) -> DeviceSpec {
        self.sim.spec()
    }
    fn read(&mut self, dt: f64) -> Result<DeviceSample, DeviceError> {
        self.sim.read(dt)
    }
    fn write_force(&mut self, force: f64) -> Result<(), DeviceError> {
        self.sim.write_force(force)
    }
    fn faults(&self) -> DeviceFaults {
        DeviceFaults {
            watchdog_trips: self.trips,
            ..DeviceFaults::default()
        }
    }
}

/// A read that waits 2 ms for a late answer does not make the server's newest sample,
/// published meanwhile, look stamped in the future (which would zero the force and blame the
/// server): the server is judged after the read.
#[test]
fn a_late_answer_neither_zeroes_the_force_nor_blames_the_server() {
    let sim = SimDevice::new(Script::Hold, 1e-3);
    let mut b = Bridge::new(Slow { sim, trips: 0 }, BridgeConfig::default(), 0);
    let mut link = Loop::default();
    let ms = 1_000_000;
    link.next = Some(live(0.5, ms));
    assert_eq!(b.cycle(ms, &mut link).force, 0.5);
    // The next cycle starts at 2 ms; its read returns at 4.2 ms; the server's sample of 4 ms
    // arrived during the read.
    link.next = Some(live(0.5, 4 * ms));
    let row = b.cycle_timed(2 * ms, || 4 * ms + 200_000, &mut link);
    assert!(row.link, "the server is heard");
    assert_eq!(row.force, 0.5, "no zero, no ramp: a late answer is not a pause");
    // At 2 kHz a late answer is a 3.2 ms gap between writes: still not a pause.
    let mut b = Bridge::new(
        SimDevice::new(Script::Hold, 5e-4),
        BridgeConfig {
            rate_hz: 2000.0,
            ..BridgeConfig::default()
        },
        0,
    );
    link.next = Some(live(0.5, ms));
    b.cycle(ms, &mut link);
    link.next = Some(live(0.5, 4 * ms));
    assert_eq!(b.cycle_timed(ms + 500_000, || 4 * ms + 200_000, &mut link).force, 0.5);
}

/// After the device's watchdog zeroed its force (it heard nothing valid for 10 ms while the
/// bridge ran on), the force ramps in again rather than coming back as a step.
#[test]
fn after_the_devices_watchdog_tripped_the_force_ramps_in() {
    let sim = SimDevice::new(Script::Hold, 1e-3);
    let mut b = Bridge::new(Slow { sim, trips: 0 }, BridgeConfig::default(), 0);
    let mut link = Loop::default();
    let ms = 1_000_000;
    let mut t = ms;
    link.next = Some(live(0.5, t));
    assert_eq!(b.cycle(t, &mut link).force, 0.5);
    b.device.trips = 1;
    t += ms;
    link.next = Some(live(0.5, t));
    assert_eq!(b.cycle(t, &mut link).force, 0.0, "from zero after the trip");
    t += ms;
    link.next = Some(live(0.5, t));
    let f = b.cycle(t, &mut link).force;
    assert!(f > 0.0 && f < 0.05, "ramping: {f}");
}

/// After the bridge was stopped for 50 ms, its first packet does not carry the force from before
/// (a kick in the hand): a pause of more than 3 periods and 10 ms ramps the force in from zero
/// over 20 ms, on a device that may have dropped its force meanwhile (a watchdog: `Slow` stands
/// for one).
#[test]
fn after_a_pause_the_force_ramps_in_from_zero_not_at_the_old_force() {
    let sim = SimDevice::new(Script::Hold, 1e-3);
    let mut b = Bridge::new(Slow { sim, trips: 0 }, BridgeConfig::default(), 0);
    let mut link = Loop::default();
    let ms = 1_000_000;
    let mut t = 0;
    for _ in 0..5 {
        t += ms;
        link.next = Some(live(0.5, t));
        assert_eq!(b.cycle(t, &mut link).force, 0.5, "steady before the pause");
    }
    // The bridge is stopped 50 ms; the server's newest force is fresh when it resumes.
    t += 50 * ms;
    let mut forces = Vec::new();
    for _ in 0..25 {
        link.next = Some(live(0.5, t));
        forces.push(b.cycle(t, &mut link).force);
        t += ms;
    }
    assert!(
        forces[0] <= 0.5 * 0.05 + 1e-12,
        "first force after the pause: {}",
        forces[0]
    );
    assert!(forces.windows(2).all(|w| w[1] >= w[0]), "it only grows: {forces:?}");
    assert_eq!(forces[20], 0.5, "ramped in over 20 ms: {forces:?}");
    // A pause of 3 periods or less is a late cycle, not a pause: no ramp.
    t += 2 * ms;
    link.next = Some(live(0.5, t));
    assert_eq!(b.cycle(t, &mut link).force, 0.5);
    // Nor is a stall shorter than a serial device's 10 ms watchdog (the device still
    // holds its force: dropping it would be an active dip); one of 10 ms and more is.
    t += 9_900_000;
    link.next = Some(live(0.5, t));
    assert_eq!(b.cycle(t, &mut link).force, 0.5, "a 9.9 ms stall");
    t += 10_100_000;
    link.next = Some(live(0.5, t));
    assert!(b.cycle(t, &mut link).force < 0.05, "a 10.1 ms stall");
}

/// The simulated device holds its force through any pause (its motor holds it, its handle
/// stands still): after 50 ms the bridge resumes at the force of the moment, without a dip and
/// ramp, which would push a loose hand's handle back (−0.36 mJ and a 44 % tip swing after a
/// 12.7 ms stall in the grid's loose grip at 10 nm/mm and 10 N).
#[test]
fn a_device_that_holds_its_force_resumes_without_a_ramp() {
    let mut b = Bridge::new(SimDevice::new(Script::Hold, 1e-3), BridgeConfig::default(), 0);
    let mut link = Loop::default();
    let ms = 1_000_000;
    link.next = Some(live(0.5, ms));
    assert_eq!(b.cycle(ms, &mut link).force, 0.5);
    link.next = Some(live(0.5, 51 * ms));
    assert_eq!(b.cycle(51 * ms, &mut link).force, 0.5);
}

/// A reopened device starts with the force ramped in, its limits taken anew, and
/// the lost device's counters kept (one reopen counted).
#[test]
fn a_replaced_device_ramps_in_and_the_counters_carry_over() {
    let mut b = Bridge::new(SimDevice::new(Script::Hold, 1e-3), BridgeConfig::default(), 0);
    let mut link = Loop::default();
    let ms = 1_000_000;
    b.count_overrun();
    b.faults.losses += 1;
    b.replace_device(SimDevice::new(Script::Hold, 1e-3));
    let f = b.faults();
    assert_eq!((f.overruns, f.losses, f.reopens), (1, 1, 1));
    assert!(b.lost().is_none());
    link.next = Some(live(1.0, ms));
    let first = b.cycle(ms, &mut link).force;
    assert!(first > 0.0 && first <= 0.05 + 1e-12, "{first}");
    assert_eq!(link.published.last().unwrap().faults, f, "published with every state");
    assert_eq!(link.published.last().unwrap().rate_hz, 1000.0);
}

#[test]
fn the_bridge_clamps_whatever_the_server_sends_and_zeroes_a_silent_server() {
    let mut b = Bridge::new(SimDevice::new(Script::Hold, 1e-3), BridgeConfig::default(), 0);
    let mut link = Loop::default();
    let ms = 1_000_000;
    link.next = Some(live(100.0, ms));
    let row = b.cycle(ms, &mut link);
    assert_eq!(row.force, 2.5, "clamped to the device's limit");
    assert!(row.link);
    // The server falls silent: the same sample ages; zero force once it is 5 ms old.
    let mut t = ms;
    let mut silent_at = None;
    for _ in 0..10 {
        t += ms;
        let row = b.cycle(t, &mut link);
        if row.force == 0.0 && silent_at.is_none() {
            silent_at = Some(t - ms);
            assert!(!row.link);
            assert_eq!(
                link.published.last().unwrap().flags & STATE_SERVER_SILENT,
                STATE_SERVER_SILENT
            );
        }
    }
    // Zero force within 5 ms of the last sample (cycles at 1 kHz).
    assert!(silent_at.unwrap() <= 5 * ms, "{silent_at:?}");
    // It comes back: the force is live again.
    link.next = Some(live(0.5, t + ms));
    let row = b.cycle(t + ms, &mut link);
    assert!(row.link && (row.force - 0.5).abs() < 0.1, "{row:?}");
    // Non-finite forces render nothing.
    link.next = Some(live(f64::NAN, t + 2 * ms));
    assert_eq!(b.cycle(t + 2 * ms, &mut link).force, 0.0);
}

/// A device that reports garbage every other cycle.
struct Glitchy(u32);

impl Device for Glitchy {
    fn spec(&self) -> DeviceSpec {
        SimDevice::new(Script::Hold, 1e-3).spec()
    }
    fn read(&mut self, _dt: f64) -> Result<DeviceSample, crate::device::DeviceError> {
        self.0 += 1;
        Ok(DeviceSample {
            position: match self.0 % 3 {
                0 => f64::NAN,
                1 => 1.0, // a metre: outside the travel
                _ => 0.001,
            },
            velocity: 0.0,
            buttons: 0,
        })
    }
    fn write_force(&mut self, _f: f64) -> Result<(), crate::device::DeviceError> {
        Ok(())
    }
}

#[test]
fn samples_outside_the_travel_or_not_finite_are_dropped_and_counted() {
    let mut b = Bridge::new(Glitchy(0), BridgeConfig::default(), 0);
    let mut link = Loop::default();
    for k in 0..30u64 {
        b.cycle(k * 1_000_000, &mut link);
    }
    assert_eq!(b.dropped(), 20);
    assert_eq!(link.published.len(), 10);
    assert!(link.published.iter().all(|s| s.position == 0.001));
    // The last published sample went out before the last cycle's drop.
    assert_eq!(link.published.last().unwrap().dropped, 19);
    // Sequence numbers count published samples, without gaps.
    assert!(link.published.windows(2).all(|w| w[1].seq == w[0].seq + 1));
}

#[test]
fn latency_is_the_time_from_a_sample_to_the_force_computed_from_it() {
    let mut b = Bridge::new(SimDevice::new(Script::Hold, 1e-3), BridgeConfig::default(), 0);
    let mut link = Loop::default();
    b.cycle(1_000_000, &mut link);
    let seq = link.published[0].seq;
    link.next = Some(ForceFeedback {
        state_seq: seq,
        ..live(0.0, 1_500_000)
    });
    let row = b.cycle(2_000_000, &mut link);
    assert_eq!(row.latency_ns, 1_000_000);
}

/// A stiff wall at `x_w` computed by a "server" from the newest published sample (one cycle
/// late, as the real loop is), sent with its stiffness; the bridge renders it as a held force.
/// Returns the peak-to-peak handle motion over the last second and the lowest observed energy.
fn wall(k: f64, passivity: bool, local_model: bool) -> (f64, f64) {
    let dt = 1e-3;
    let script = Script::from_csv("press", "0,0\n2,-0.004\n4,-0.004\n").unwrap();
    let cfg = BridgeConfig {
        passivity,
        local_model,
        ..BridgeConfig::default()
    };
    let mut b = Bridge::new(SimDevice::new(script, dt), cfg, 0);
    b.device.operator.damping = 1.0; // a light grip
    let mut link = Loop::default();
    let x_w = -0.002;
    let (mut lo, mut hi, mut e_min) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY);
    for n in 1..4000u64 {
        let now = n * 1_000_000;
        if let Some(st) = link.published.last() {
            let pen = x_w - st.position;
            link.next = Some(ForceFeedback {
                seq: n,
                time_ns: now,
                state_seq: st.seq,
                force: if pen > 0.0 { k * pen } else { 0.0 },
                stiffness: if pen > 0.0 { -k } else { 0.0 },
                anchor: st.position,
                half_range: 0.01,
                gain: 1.0,
                active: 1,
                flags: FORCE_ENGAGED,
                ..Default::default()
            });
        }
        let row = b.cycle(now, &mut link);
        if n > 3000 {
            lo = lo.min(row.handle);
            hi = hi.max(row.handle);
        }
        if n > 10 {
            e_min = e_min.min(row.port_energy);
        }
    }
    (hi - lo, e_min)
}

/// The sampled loop makes a stiff wall rendered as a held force buzz: the hand, pressing
/// slowly, comes to rest against it only with the passivity controller, which keeps the
/// observed energy above −1 µJ; without it the handle bounces (a limit cycle bounded by the
/// motor's saturation) and the energy runs away negative.
#[test]
fn a_stiff_held_wall_buzzes_unless_the_passivity_controller_acts() {
    // 20 kN/m against a light grip (1 N·s/m): ten times the sampled loop's limit
    // `K < 2b/T` ≈ 2 kN/m; the controller holds it up to ~40 kN/m (its damping cap, 40
    // N·s/m, is then reached).
    let k = 20_000.0;
    let (p2p_off, e_off) = wall(k, false, false);
    let (p2p_on, e_on) = wall(k, true, false);
    eprintln!("held wall {k} N/m: without PC p2p {p2p_off:e} m, E_min {e_off:e} J; with {p2p_on:e} m, {e_on:e} J");
    assert!(p2p_off > 2e-4, "without the controller the wall should buzz: {p2p_off}");
    assert!(
        p2p_on < 2e-5,
        "with the controller the hand should rest on the wall: {p2p_on}"
    );
    assert!(e_on > -1e-6, "{e_on}");
    assert!(e_off < -1e-4, "{e_off}");
}
