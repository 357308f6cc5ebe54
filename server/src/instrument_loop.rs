//! The loop over a real controller: a thread that owns the backend, follows its readings at the
//! rate it feeds them (the TCP Logger's, or polled reads'), publishes each as the telemetry
//! snapshot, and withdraws the tip on Stop and at shutdown. It stands where the 1 kHz control loop
//! stands for the simulated AFM; the force is held by the controller's own Z feedback, so there is
//! no force loop here to close.

use std::sync::atomic::Ordering::{Relaxed, Release};
use std::sync::atomic::{AtomicBool, AtomicU64};
use std::sync::mpsc::{Receiver, Sender, SyncSender};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use nanopush_instrument::afm::{Capabilities, Limits, Microscope, ScanFrame};
use nanopush_instrument::scan::HeightImage;
use nanopush_proto::ws::InstrumentInfo;

use crate::control_loop::{LoopCommand, LoopEvent, Shared};

/// What the server's jobs ask of the loop's thread, with where to answer.
pub enum Request {
    /// A scan: the frame given, or the controller's own.
    Scan {
        /// The frame, or None for the controller's.
        frame: Option<ScanFrame>,
        /// The image, or why there is none.
        reply: SyncSender<Result<HeightImage, String>>,
    },
}

/// A real controller behind the server.
pub struct RealInstrument {
    /// What it can do, as it said when it connected.
    pub caps: Capabilities,
    /// The backend, taken by the loop's thread when it starts.
    pub backend: Mutex<Option<Box<dyn Microscope + Send>>>,
    /// Requests to the loop's thread.
    requests: Mutex<Sender<Request>>,
    /// Their receiving end, taken by the loop's thread.
    receiver: Mutex<Option<Receiver<Request>>>,
    /// Set by a stop: a scan in progress ends early.
    pub cancel: Arc<AtomicBool>,
    /// The XY travel the backend allows (a scan's square is checked against it on arrival).
    pub limits: Option<Limits>,
    /// A withdraw that failed, in words, for the clients (taken by the telemetry task).
    pub fault: Arc<Mutex<Option<String>>>,
    /// When the last reading came (ns since the loop started; 0: none yet).
    pub last_reading_ns: Arc<AtomicU64>,
    /// When the loop started.
    pub started: Instant,
}

impl std::fmt::Debug for RealInstrument {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "RealInstrument({})", self.caps.backend)
    }
}

impl RealInstrument {
    /// A connected backend.
    pub fn new(mut backend: Box<dyn Microscope + Send>) -> RealInstrument {
        let cancel = Arc::new(AtomicBool::new(false));
        backend.set_cancel(cancel.clone());
        let (tx, rx) = std::sync::mpsc::channel();
        RealInstrument {
            caps: backend.capabilities(),
            limits: backend.limits().ok(),
            backend: Mutex::new(Some(backend)),
            requests: Mutex::new(tx),
            receiver: Mutex::new(Some(rx)),
            cancel,
            fault: Arc::new(Mutex::new(None)),
            last_reading_ns: Arc::new(AtomicU64::new(0)),
            started: Instant::now(),
        }
    }

    /// Seconds since the last reading (None before the first).
    pub fn reading_age_s(&self) -> Option<f64> {
        match self.last_reading_ns.load(Relaxed) {
            0 => None,
            ns => Some(self.started.elapsed().as_secs_f64() - ns as f64 * 1e-9),
        }
    }

    /// The failed withdraw not yet told, if any.
    pub fn take_fault(&self) -> Option<String> {
        self.fault.lock().ok().and_then(|mut f| f.take())
    }

    /// Scans on the loop's thread (telemetry pauses meanwhile) and waits for the image. (The
    /// command that asks for it clears `cancel` before it is accepted, so a stop after it ends it.)
    pub fn scan(&self, frame: Option<ScanFrame>) -> Result<HeightImage, String> {
        let (reply, answer) = std::sync::mpsc::sync_channel(1);
        self.requests
            .lock()
            .map_err(|_| "the instrument's request queue is poisoned".to_string())?
            .send(Request::Scan { frame, reply })
            .map_err(|_| "the instrument loop has ended".to_string())?;
        answer
            .recv()
            .map_err(|_| "the instrument loop ended during the scan".to_string())?
    }

    /// What the page is told of it: it offers scans (through the controller's scan engine).
    /// Pushes and assemblies from the server, and the haptic force loop, run on the simulated
    /// AFM only: on a real controller the command line pushes (`nanopush push --instrument`).
    pub fn info(&self) -> InstrumentInfo {
        InstrumentInfo {
            backend: self.caps.backend.clone(),
            feed_rate_hz: self.caps.feed_rate_hz,
            z_closed_locally: self.caps.z_closed_locally,
            read_only: self.caps.read_only,
            offers: vec!["scan".into()],
        }
    }
}

/// Why the push the loop was handed cannot run here.
const NO_PUSH: &str = "pushes from the server are not offered on a real controller yet; use nanopush push --instrument";

/// Starts the loop's thread on `real`'s backend.
pub fn start(real: &RealInstrument, shared: Arc<Shared>) -> std::io::Result<std::thread::JoinHandle<()>> {
    let backend = real
        .backend
        .lock()
        .ok()
        .and_then(|mut b| b.take())
        .ok_or_else(|| std::io::Error::other("the instrument's backend was already taken"))?;
    let requests = real
        .receiver
        .lock()
        .ok()
        .and_then(|mut r| r.take())
        .ok_or_else(|| std::io::Error::other("the instrument's requests were already taken"))?;
    let ctx = Context {
        fault: real.fault.clone(),
        last_reading_ns: real.last_reading_ns.clone(),
        started: real.started,
    };
    std::thread::Builder::new().name("instrument-loop".into()).spawn(move || {
        let ran = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| run(backend, &requests, &shared, &ctx)));
        if let Err(p) = ran {
            // The backend went with the panic: nothing can withdraw the tip from here.
            let words = format!(
                "the instrument loop failed ({}); the tip may still be on the surface: withdraw it at the controller",
                nanopush_instrument::panic_message(&p)
            );
            tracing::error!("instrument: {words}");
            if let Ok(mut f) = ctx.fault.lock() {
                *f = Some(words);
            }
            shared.finished.store(true, Release);
        }
    })
}

/// What the loop's thread reports back beside the snapshot.
struct Context {
    fault: Arc<Mutex<Option<String>>>,
    last_reading_ns: Arc<AtomicU64>,
    started: Instant,
}

/// Withdraws first (on a dead link the motion's stop would only spend a time-out before it),
/// then stops any motion; a withdraw that fails is logged and told to the clients.
fn withdraw(m: &mut dyn Microscope, why: &str, ctx: &Context) {
    if m.capabilities().read_only {
        return;
    }
    match m.withdraw() {
        Ok(()) => {
            tracing::info!("instrument: tip withdrawn ({why})");
            let _ = m.stop_move();
        }
        Err(e) => {
            let words = format!("the tip could NOT be withdrawn ({why}): {e}; withdraw it at the controller");
            tracing::error!("instrument: {words}");
            if let Ok(mut f) = ctx.fault.lock() {
                *f = Some(words);
            }
        }
    }
}

fn run(mut m: Box<dyn Microscope + Send>, requests: &Receiver<Request>, shared: &Shared, ctx: &Context) {
    let mut failing_since: Option<Instant> = None;
    let mut last_warned = Instant::now() - Duration::from_secs(60);
    loop {
        // Every command waiting, taken at once: a shutdown goes first, and any number of stops
        // is one withdraw.
        let mut stop: Option<&'static str> = None;
        while let Some(cmd) = shared.commands.pop() {
            match cmd {
                LoopCommand::Shutdown => {
                    withdraw(m.as_mut(), "server shutting down", ctx);
                    shared.finished.store(true, Release);
                    return;
                }
                LoopCommand::Stop(why) => stop = Some(why.words()),
                LoopCommand::Push(job) => {
                    let _ = shared.events.push(LoopEvent::RunDone {
                        run: job.run,
                        particle: job.particle,
                        outcome: "refused",
                        failure: Some(NO_PUSH.into()),
                        estimate: job.legs.first().map_or([f64::NAN; 2], |l| [l.from.0, l.from.1]),
                        truth: [f64::NAN; 2],
                        legs: 0,
                    });
                    shared.busy.store(false, Relaxed);
                }
                LoopCommand::Haptic(_) => {}
            }
        }
        if let Some(why) = stop {
            // (`cancel` stays set: a scan asked before this stop and not yet begun is ended by
            // it too; the next scan command clears it before it is accepted.)
            withdraw(m.as_mut(), why, ctx);
        }
        while let Ok(Request::Scan { frame, reply }) = requests.try_recv() {
            let image = m.scan(frame.as_ref()).map_err(|e| e.to_string());
            if let Err(e) = &image {
                tracing::warn!("instrument: scan failed: {e}");
            }
            let _ = reply.send(image);
        }
        match m.poll() {
            Ok((sample, _)) if !(sample.tip.iter().all(|v| v.is_finite()) && sample.normal.is_finite()) => {
                // Not published: telemetry shows the last reading that was a number.
                if last_warned.elapsed() >= Duration::from_secs(10) {
                    tracing::warn!(
                        "instrument: a reading that is not a number: tip {:?} m, normal {} V",
                        sample.tip,
                        sample.normal
                    );
                    last_warned = Instant::now();
                }
            }
            Ok((sample, _)) => {
                failing_since = None;
                ctx.last_reading_ns
                    .store(ctx.started.elapsed().as_nanos().max(1) as u64, Relaxed);
                if let Ok(mut s) = shared.snapshot.lock() {
                    s.t = ctx.started.elapsed().as_secs_f64();
                    s.stage = sample.tip;
                    s.volts = sample.normal;
                    s.tick += 1;
                }
                shared.metrics.ticks.fetch_add(1, Relaxed);
            }
            Err(e) => {
                let since = *failing_since.get_or_insert_with(Instant::now);
                if last_warned.elapsed() >= Duration::from_secs(10) {
                    tracing::warn!("instrument: no reading for {:.1} s: {e}", since.elapsed().as_secs_f64());
                    last_warned = Instant::now();
                }
                std::thread::sleep(Duration::from_millis(100));
            }
        }
    }
}
