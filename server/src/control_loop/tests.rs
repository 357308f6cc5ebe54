//! A tick without a thread: the loop is started, ticked and ended by hand.

use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;
use std::time::Instant;

use super::*;
use nanopush_instrument::scene::Scene;

const CFG: LoopConfig = LoopConfig {
    rate_hz: 1000.0,
    realtime: false,
    cpu: None,
    no_halt: false,
    haptic: false,
    haptic_timeout: std::time::Duration::from_millis(5),
};

fn default_loop() -> (ControlLoop, Arc<Shared>) {
    let scene = Scene::default_scene();
    let tick = 1.0 / CFG.rate_hz;
    let base = nanopush_instrument::scan::ScanParams::from_scene(&scene);
    let afm = Afm::from_scene(&scene, base.centre_x, base.centre_y, tick);
    let shared = Arc::new(Shared::new(&afm));
    let lp = ControlLoop::new(afm, scene.bilateral_params(tick));
    (lp, shared)
}

#[test]
fn ticks_advance_the_clock_count_and_publish_the_snapshot() {
    let (mut lp, shared) = default_loop();
    let mut running = lp.start(&shared, &CFG);
    for _ in 0..3 {
        assert!(lp.tick(&shared, &mut running, Instant::now()));
    }
    assert_eq!(shared.metrics.ticks.load(Relaxed), 3);
    assert_eq!(shared.metrics.control.count(), 3);
    assert_eq!(shared.metrics.physics.count(), 3);
    assert_eq!(shared.metrics.publish.count(), 3);
    let s = shared.snapshot.lock().unwrap().clone();
    assert_eq!(s.tick, 2, "the snapshot carries the tick it was taken at");
    assert!((s.t - 3e-3).abs() < 1e-9, "three 1 ms ticks: t = {}", s.t);
    assert_eq!(s.phase, "idle");
    assert!(s.estimate.is_none());
    // Without a haptic link, the link's metrics stay off and the tip height unknown.
    assert!(!shared.metrics.haptic.enabled.load(Relaxed));
    assert_eq!(shared.metrics.no_halt.load(Relaxed), 0);
    assert_eq!(shared.metrics.realtime.load(Relaxed), 0);
}

#[test]
fn the_start_answers_the_ready_channel_without_a_haptic_link() {
    let (lp, shared) = default_loop();
    let (tx, rx) = std::sync::mpsc::sync_channel(1);
    let mut lp = lp.with_ready(tx);
    let _running = lp.start(&shared, &CFG);
    assert_eq!(rx.try_recv(), Ok(Ok(())));
}

#[test]
fn an_idle_shutdown_ends_the_loop_at_once_and_marks_it_stopped() {
    let (mut lp, shared) = default_loop();
    let mut running = lp.start(&shared, &CFG);
    assert!(lp.tick(&shared, &mut running, Instant::now()));
    shared.command(LoopCommand::Shutdown).unwrap();
    assert!(
        !lp.tick(&shared, &mut running, Instant::now()),
        "idle and parked: the loop ends"
    );
    lp.end(&shared, running);
    assert_eq!(shared.snapshot.lock().unwrap().phase, "stopped");
    assert_eq!(shared.metrics.ticks.load(Relaxed), 2);
}

#[test]
fn a_stop_with_no_push_running_is_ignored() {
    let (mut lp, shared) = default_loop();
    let mut running = lp.start(&shared, &CFG);
    shared.command(LoopCommand::Stop(StopReason::Operator)).unwrap();
    assert!(lp.tick(&shared, &mut running, Instant::now()));
    assert!(shared.events.pop().is_none(), "no run ended");
    assert!(shared.records.pop().is_none(), "nothing recorded");
    assert_eq!(shared.snapshot.lock().unwrap().phase, "idle");
}

#[test]
fn a_full_command_queue_refuses_and_counts_the_drop() {
    let (_lp, shared) = default_loop();
    let capacity = shared.commands.capacity();
    for _ in 0..capacity {
        shared.command(LoopCommand::Stop(StopReason::Operator)).unwrap();
    }
    assert_eq!(shared.command(LoopCommand::Stop(StopReason::Operator)), Err(QueueFull));
    assert_eq!(shared.metrics.dropped_commands.load(Relaxed), 1);
}
