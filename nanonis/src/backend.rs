//! A Nanonis controller as a [`Microscope`]: XY through Follow Me, the normal force held by the
//! controller's own Z feedback, signals from the TCP Logger stream (or polled reads when there is
//! no logger port), images from its scan engine.
//!
//! Safety, as this backend keeps it:
//! - Every call has a time-out; a slow controller shows as an error naming the command.
//! - Moves and frames are checked against the limits before anything is sent: the controller's
//!   Z range (`ZCtrl.LimitsGet`), XY inside the scan frame the controller had when nanopush
//!   connected (the region the operator has imaged), and the user's own speed limit.
//! - When the connection fails during a move or a scan it is reopened (a bounded number of
//!   tries); the first command on the new connection is `ZCtrl.Withdraw`, and the move or scan
//!   then ends with the error.
//! - Read-only: nothing that moves the tip or changes Z is sent — no Follow Me, no Z controller
//!   command, no scan start or frame change; a scan grabs the frame the controller last recorded.

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use nanopush_instrument::afm::{Capabilities, Limits, Microscope, MicroscopeError, Sample, ScanFrame};
use nanopush_instrument::scan::HeightImage;

use crate::client::Connection;
use crate::commands as cmd;
use crate::logger::LoggerStream;

mod link;
mod scan;

/// How nanopush talks to the controller.
#[derive(Debug, Clone)]
pub struct NanonisOptions {
    /// The command port (`HOST:PORT`).
    pub addr: SocketAddr,
    /// The TCP Logger's stream port, when the logger is used.
    pub logger_port: Option<u16>,
    /// Time-out of every call.
    pub timeout: Duration,
    /// Send nothing that moves the tip or changes Z.
    pub read_only: bool,
    /// The signal that reads the normal deflection (a name or its start, e.g. `Normal deflection`).
    pub deflection_signal: String,
    /// The signal that reads the lateral deflection, if any.
    pub lateral_signal: Option<String>,
    /// The signal the scan engine records the height in.
    pub height_signal: String,
    /// The fastest XY speed nanopush asks for (m/s).
    pub max_speed: f64,
    /// Reopen a lost connection this many times before giving up.
    pub reconnect_tries: u32,
    /// The longest a scan may take (s).
    pub scan_timeout: Duration,
    /// The acquisition period polled reads are averaged over (s).
    pub acquisition_period: f64,
    /// The user's own XY limits `[[x_min, x_max], [y_min, y_max]]` (m), within the controller's.
    pub xy_limits: Option<[[f64; 2]; 2]>,
}

impl NanonisOptions {
    /// Defaults for a controller at `addr`.
    pub fn new(addr: SocketAddr) -> NanonisOptions {
        NanonisOptions {
            addr,
            logger_port: None,
            timeout: Duration::from_secs(5),
            read_only: false,
            deflection_signal: "Normal deflection".into(),
            lateral_signal: Some("Lateral deflection".into()),
            height_signal: "Z".into(),
            max_speed: 20e-6,
            reconnect_tries: 3,
            scan_timeout: Duration::from_secs(3600),
            acquisition_period: 0.02,
            xy_limits: None,
        }
    }
}

/// Signal indexes nanopush reads.
#[derive(Debug, Clone, Copy)]
struct Indexes {
    x: Option<usize>,
    y: Option<usize>,
    z: usize,
    normal: usize,
    lateral: Option<usize>,
}

/// A Nanonis controller behind the instrument interface.
#[derive(Debug)]
pub struct NanonisMicroscope {
    opts: NanonisOptions,
    conn: Option<Connection>,
    names: Vec<String>,
    idx: Indexes,
    limits: Limits,
    logger: Option<LoggerStream>,
    /// Logger frames seen so far; the logger's columns: x, y, z, normal, lateral.
    seen: u64,
    columns: Vec<usize>,
    target: Option<[f64; 2]>,
    feed_rate_hz: f64,
    started: Instant,
    /// Set to end a scan early.
    cancel: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
    /// When to try the logger stream again after it failed.
    logger_retry: Option<Instant>,
    /// A scan is in progress (its calls are not retried on a new link).
    scanning: bool,
}

/// How long after a logger stream fails it is started again (polled reads meanwhile).
const LOGGER_RETRY: Duration = Duration::from_secs(2);

/// Finds the signal whose name is `want` or starts with it (case-insensitive).
pub fn find_signal(names: &[String], want: &str) -> Result<usize, String> {
    let w = want.trim().to_lowercase();
    if let Some(i) = names.iter().position(|n| n.to_lowercase() == w) {
        return Ok(i);
    }
    let hits: Vec<usize> = (0..names.len())
        .filter(|&i| names[i].to_lowercase().starts_with(&w))
        .collect();
    match hits.as_slice() {
        [i] => Ok(*i),
        [] => Err(format!(
            "no signal named {want:?}; the controller has: {}",
            names
                .iter()
                .filter(|n| !n.is_empty())
                .cloned()
                .collect::<Vec<_>>()
                .join(", ")
        )),
        many => Err(format!(
            "{want:?} names several signals: {}; give the whole name",
            many.iter().map(|&i| names[i].clone()).collect::<Vec<_>>().join(", ")
        )),
    }
}

fn setup(command: &str, message: String) -> MicroscopeError {
    MicroscopeError::Controller {
        command: command.into(),
        message,
    }
}

impl NanonisMicroscope {
    /// Connects, reads the signal names, the limits and the scan frame, and starts the logger.
    pub fn connect(opts: NanonisOptions) -> Result<NanonisMicroscope, MicroscopeError> {
        let mut conn = Connection::open(opts.addr, opts.timeout)?;
        let names = cmd::signal_names(&mut conn)?;
        let find = |want: &str| find_signal(&names, want).map_err(|m| setup("Signals.NamesGet", m));
        let idx = Indexes {
            x: find("X").ok(),
            y: find("Y").ok(),
            z: find(&opts.height_signal)?,
            normal: find(&opts.deflection_signal)?,
            lateral: match &opts.lateral_signal {
                Some(l) => Some(find(l)?),
                None => None,
            },
        };
        let z = cmd::z_limits(&mut conn)?;
        if !(z[0].is_finite() && z[1].is_finite() && z[0] < z[1]) {
            return Err(setup(
                "ZCtrl.LimitsGet",
                format!(
                    "the Z range [{}, {}] m is not a range (low below high, both finite)",
                    z[0], z[1]
                ),
            ));
        }
        let frame = cmd::frame_get(&mut conn)?;
        let sane = [
            frame.centre_x,
            frame.centre_y,
            frame.width,
            frame.height,
            frame.angle_deg,
        ];
        if !(sane.iter().all(|v| v.is_finite()) && frame.width > 0.0 && frame.height > 0.0) {
            return Err(setup(
                "Scan.FrameGet",
                format!(
                    "the scan frame (centre ({}, {}) m, {} × {} m, {}°) is not a frame: finite, with a positive width and height",
                    frame.centre_x, frame.centre_y, frame.width, frame.height, frame.angle_deg
                ),
            ));
        }
        if frame.angle_deg.abs() > 1e-6 && opts.xy_limits.is_none() {
            return Err(setup(
                "Scan.FrameGet",
                format!(
                    "the scan frame is rotated by {:.2}°: nanopush keeps moves inside an unrotated frame; set the angle to 0 at the controller, or give --xy-limits-um",
                    frame.angle_deg
                ),
            ));
        }
        let mut limits = Limits {
            x: [frame.centre_x - 0.5 * frame.width, frame.centre_x + 0.5 * frame.width],
            y: [frame.centre_y - 0.5 * frame.height, frame.centre_y + 0.5 * frame.height],
            z,
            max_speed: opts.max_speed,
        };
        if let Some([ux, uy]) = opts.xy_limits {
            let (x, y) = (
                [limits.x[0].max(ux[0]), limits.x[1].min(ux[1])],
                [limits.y[0].max(uy[0]), limits.y[1].min(uy[1])],
            );
            if !(x[0] <= x[1] && y[0] <= y[1]) {
                return Err(MicroscopeError::OutOfLimits {
                    what: format!("the XY limits {}", Limits { x: ux, y: uy, ..limits }.xy_text()),
                    allowed: format!("a region overlapping the controller's scan frame, {}", limits.xy_text()),
                });
            }
            limits.x = x;
            limits.y = y;
        }
        let mut m = NanonisMicroscope {
            opts,
            conn: Some(conn),
            names,
            idx,
            limits,
            logger: None,
            seen: 0,
            columns: Vec::new(),
            target: None,
            feed_rate_hz: 0.0,
            started: Instant::now(),
            cancel: None,
            logger_retry: None,
            scanning: false,
        };
        m.feed_rate_hz = 1.0 / m.opts.acquisition_period;
        // Read-only starts no logger either: TCPLog.ChsSet changes the controller's settings.
        if let Some(port) = m.opts.logger_port.filter(|_| !m.opts.read_only) {
            let patience = m.opts.timeout;
            m.start_logger(port, patience)?;
        } else if !m.opts.read_only {
            let period = m.opts.acquisition_period;
            m.call("Util.AcqPeriodSet", |c| cmd::acq_period_set(c, period))?;
        }
        Ok(m)
    }

    /// Sets the logger's channels, starts it and opens its stream, each wait at most `patience`.
    fn start_logger(&mut self, port: u16, patience: Duration) -> Result<(), MicroscopeError> {
        let mut cols = vec![self.idx.z, self.idx.normal];
        cols.extend(self.idx.x);
        cols.extend(self.idx.y);
        cols.extend(self.idx.lateral);
        self.columns = cols.clone();
        self.call("TCPLog.ChsSet", |c| cmd::log_channels_set(c, &cols))?;
        self.call("TCPLog.Start", cmd::log_start)?;
        let addr = SocketAddr::new(self.opts.addr.ip(), port);
        let logger = LoggerStream::open(addr, patience).map_err(|m| MicroscopeError::Link {
            command: "TCP Logger stream".into(),
            message: m,
        })?;
        // The rate the stream really gives: frames over a short window.
        let start = Instant::now();
        let mut seen = 0;
        while start.elapsed() < Duration::from_millis(300) {
            let (_, n) = logger.next_after(seen, patience).map_err(|m| MicroscopeError::Link {
                command: "TCP Logger stream".into(),
                message: m,
            })?;
            seen = n;
        }
        self.feed_rate_hz = logger.rate_hz().unwrap_or(1.0 / self.opts.acquisition_period);
        self.seen = seen;
        self.logger = Some(logger);
        Ok(())
    }

    /// Starts the logger stream again once its retry time has come (a controller that
    /// restarted, a stream that dropped); until then, and when that fails, readings are polled.
    fn revive_logger(&mut self) {
        let (Some(port), Some(at)) = (self.opts.logger_port, self.logger_retry) else {
            return;
        };
        if self.logger.is_some() || Instant::now() < at || self.opts.read_only {
            return;
        }
        // Briefly: the loop that polls waits behind this, and a stop with it.
        match self.start_logger(port, self.opts.timeout.min(Duration::from_secs(1))) {
            Ok(()) => self.logger_retry = None,
            Err(_) => self.logger_retry = Some(Instant::now() + LOGGER_RETRY),
        }
    }

    /// The signal names the controller reported.
    pub fn signal_names(&self) -> &[String] {
        &self.names
    }

    fn refuse_if_read_only(&self, what: &str) -> Result<(), MicroscopeError> {
        if self.opts.read_only {
            return Err(MicroscopeError::ReadOnly { what: what.into() });
        }
        Ok(())
    }

    fn check_xy(&self, what: &str, x: f64, y: f64) -> Result<(), MicroscopeError> {
        let l = &self.limits;
        if !(x.is_finite() && y.is_finite() && l.contains_xy(x, y)) {
            return Err(MicroscopeError::OutOfLimits {
                what: format!("{what} ({:.4}, {:.4}) µm", x * 1e6, y * 1e6),
                allowed: format!("{} (the controller's scan frame and --xy-limits-um)", l.xy_text()),
            });
        }
        Ok(())
    }

    fn polled_sample(&mut self) -> Result<Sample, MicroscopeError> {
        let mut want = vec![self.idx.z, self.idx.normal];
        want.extend(self.idx.lateral);
        let (x, y) = self.call("FolMe.XYPosGet", cmd::xy_pos_get)?;
        let v = self.call("Signals.ValsGet", |c| cmd::signal_values(c, &want))?;
        std::thread::sleep(Duration::from_secs_f64(self.opts.acquisition_period));
        Ok(Sample {
            t: self.started.elapsed().as_secs_f64(),
            tip: [x, y, v[0]],
            normal: v[1],
            lateral: v.get(2).copied(),
        })
    }

    fn logged_sample(&mut self) -> Result<Sample, MicroscopeError> {
        let logger = self.logger.as_ref().expect("logger running");
        let wait = self.opts.timeout;
        let (frame, n) = logger.next_after(self.seen, wait).map_err(|m| MicroscopeError::Link {
            command: "TCP Logger stream".into(),
            message: m,
        })?;
        self.seen = n;
        let cols = self.columns.clone();
        if frame.values.len() != cols.len() {
            return Err(MicroscopeError::Controller {
                command: "TCP Logger stream".into(),
                message: format!(
                    "{} values in a frame; {} channels were set",
                    frame.values.len(),
                    cols.len()
                ),
            });
        }
        let at = |i: usize| cols.iter().position(|&c| c == i).map(|k| f64::from(frame.values[k]));
        let (x, y) = match (self.idx.x.and_then(at), self.idx.y.and_then(at)) {
            (Some(x), Some(y)) => (x, y),
            _ => self.call("FolMe.XYPosGet", cmd::xy_pos_get)?,
        };
        Ok(Sample {
            t: self.started.elapsed().as_secs_f64(),
            tip: [x, y, at(self.idx.z).unwrap_or(f64::NAN)],
            normal: at(self.idx.normal).unwrap_or(f64::NAN),
            lateral: self.idx.lateral.and_then(at),
        })
    }
}

impl Microscope for NanonisMicroscope {
    fn capabilities(&self) -> Capabilities {
        Capabilities {
            backend: format!("Nanonis {}", self.opts.addr),
            feed_rate_hz: self.feed_rate_hz,
            z_closed_locally: true,
            scan_engine: true,
            read_only: self.opts.read_only,
        }
    }

    fn limits(&mut self) -> Result<Limits, MicroscopeError> {
        Ok(self.limits)
    }

    fn start_move(&mut self, x: f64, y: f64, speed: f64) -> Result<(), MicroscopeError> {
        self.refuse_if_read_only("FolMe.XYPosSet")?;
        self.check_xy("move to", x, y)?;
        if !(speed.is_finite() && speed > 0.0 && speed <= self.limits.max_speed * (1.0 + 1e-9)) {
            return Err(MicroscopeError::OutOfLimits {
                what: format!("speed {:.3} µm/s", speed * 1e6),
                allowed: format!("(0, {:.3}] µm/s (--max-speed-um-per-s)", self.limits.max_speed * 1e6),
            });
        }
        let result = self
            .call("FolMe.SpeedSet", |c| cmd::speed_set(c, speed))
            .and_then(|()| self.call("FolMe.XYPosSet", |c| cmd::xy_pos_set(c, x, y, false)));
        match result {
            Ok(()) => {
                self.target = Some([x, y]);
                Ok(())
            }
            Err(e) => Err(self.recover(e)),
        }
    }

    fn stop_move(&mut self) -> Result<(), MicroscopeError> {
        self.target = None;
        if self.opts.read_only {
            return Ok(());
        }
        self.call("FolMe.Stop", cmd::folme_stop)
    }

    fn poll(&mut self) -> Result<(Sample, bool), MicroscopeError> {
        self.revive_logger();
        let sample = if self.logger.is_some() {
            match self.logged_sample() {
                // A stream that failed is dropped: polled reads stand in until it is back.
                Err(MicroscopeError::Link { command, message }) if command == "TCP Logger stream" => {
                    self.logger = None;
                    self.logger_retry = Some(Instant::now() + LOGGER_RETRY);
                    Err(MicroscopeError::Link { command, message })
                }
                other => other,
            }
        } else {
            self.polled_sample()
        };
        let sample = match sample {
            Ok(s) => s,
            Err(e) if self.target.is_some() => return Err(self.recover(e)),
            Err(e) => return Err(e),
        };
        let arrived = match self.target {
            None => true,
            Some([x, y]) => {
                let close = (sample.tip[0] - x).hypot(sample.tip[1] - y) <= 1e-10;
                if close {
                    self.target = None;
                }
                close
            }
        };
        Ok((sample, arrived))
    }

    fn hold_force(&mut self, setpoint: f64) -> Result<(), MicroscopeError> {
        self.refuse_if_read_only("ZCtrl.SetpntSet")?;
        if !setpoint.is_finite() {
            return Err(MicroscopeError::OutOfLimits {
                what: format!("set point {setpoint} V"),
                allowed: "a finite deflection (V)".into(),
            });
        }
        let result = self
            .call("ZCtrl.SetpntSet", |c| cmd::setpoint_set(c, setpoint))
            .and_then(|()| self.call("ZCtrl.OnOffSet", |c| cmd::z_on_off_set(c, true)));
        result.map_err(|e| self.recover(e))
    }

    fn scan(&mut self, frame: Option<&ScanFrame>) -> Result<HeightImage, MicroscopeError> {
        if let Some(f) = frame {
            self.check_xy("frame corner", f.centre_x - 0.5 * f.width, f.centre_y - 0.5 * f.height)?;
            self.check_xy("frame corner", f.centre_x + 0.5 * f.width, f.centre_y + 0.5 * f.height)?;
            if !(16..=crate::commands::MAX_PIXELS).contains(&f.pixels)
                || !(1..=crate::commands::MAX_PIXELS).contains(&f.lines)
            {
                return Err(MicroscopeError::OutOfLimits {
                    what: format!("{} × {} pixels", f.pixels, f.lines),
                    allowed: format!("16-{} pixels per line, 1-{} lines", cmd::MAX_PIXELS, cmd::MAX_PIXELS),
                });
            }
        }
        self.scanning = true;
        let (result, restore) = self.scan_inner(frame);
        self.scanning = false;
        let result = match result {
            Ok(img) => Ok(img),
            Err(
                e @ (MicroscopeError::ReadOnly { .. }
                | MicroscopeError::OutOfLimits { .. }
                | MicroscopeError::Unsupported { .. }),
            ) => Err(e),
            Err(e) if self.opts.read_only => Err(e),
            Err(MicroscopeError::Cancelled(what)) => {
                // A stop: the engine was stopped; the tip goes away as after any stop.
                let words = match self.withdraw() {
                    Ok(()) => "the tip was withdrawn".to_string(),
                    Err(w) => format!("the tip could NOT be withdrawn ({w}): withdraw it at the controller"),
                };
                Err(MicroscopeError::Cancelled(format!("{what}; {words}")))
            }
            Err(e) => {
                // Stop the scan engine if the link still answers, withdraw: then the rest.
                // (Only on the link still open: on a new one the withdraw goes first.)
                if self.conn.is_some() {
                    let _ = self.call("Scan.Action", |c| cmd::scan_action(c, 1, true));
                }
                Err(self.recover(e))
            }
        };
        // The operator's own frame and buffer back, as their software had them: after the tip
        // is safe.
        if let Some((frame0, buffer0)) = restore.filter(|_| self.conn.is_some()) {
            let _ = self.call("Scan.FrameSet", |c| cmd::frame_set(c, &frame0));
            let _ = self.call("Scan.BufferSet", |c| cmd::buffer_set(c, &buffer0));
        }
        result
    }

    fn current_frame(&mut self) -> Result<ScanFrame, MicroscopeError> {
        let f = self.call("Scan.FrameGet", cmd::frame_get)?;
        let b = self.call("Scan.BufferGet", cmd::buffer_get)?;
        Ok(Self::frame_to_scan(&f, &b))
    }

    fn set_cancel(&mut self, cancel: std::sync::Arc<std::sync::atomic::AtomicBool>) {
        self.cancel = Some(cancel);
    }

    fn withdraw(&mut self) -> Result<(), MicroscopeError> {
        self.target = None;
        self.refuse_if_read_only("ZCtrl.Withdraw")?;
        let t = self.opts.timeout;
        self.call("ZCtrl.Withdraw", |c| cmd::withdraw(c, t))
    }
}
