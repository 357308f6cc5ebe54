//! The fake controller's microscope: a sample (a scene's substrate and particles), a tip moved by
//! Follow Me at its speed in wall-clock time, a Z controller that lands the tip and holds the
//! normal deflection at its set point, a scan engine, and the signals a logger streams.
//!
//! A push, as the fake models it: with the Z feedback on, a tip that runs into a particle
//! (centres closer than the two radii) carries it ahead on its line of travel, and the lateral
//! deflection reads [`LATERAL_PUSHING`] while it does.

use std::time::Instant;

use nanopush_instrument::scan::{HeightImage, ScanParams, Surface, Tip, scan};
use nanopush_instrument::scene::Scene;
use nanopush_proto::nanonis::{BodyReader, BodyWriter, ErrorBlock, FrameError};

/// The signals the fake names, in index order.
pub const SIGNALS: [&str; 7] = [
    "Current (A)",
    "X (m)",
    "Y (m)",
    "Z (m)",
    "Normal deflection (V)",
    "Lateral deflection (V)",
    "Bias (V)",
];
const X: usize = 1;
const Y: usize = 2;
const Z: usize = 3;
const NORMAL: usize = 4;
const LATERAL: usize = 5;

/// Lateral deflection while the tip carries a particle (V).
pub const LATERAL_PUSHING: f64 = 0.25;
/// Lateral deflection of the bare tip on the substrate (V).
pub const LATERAL_FREE: f64 = 0.01;
/// The Z range the fake reports: `[low, high]` (m).
pub const Z_LIMITS: [f64; 2] = [-5e-6, 5e-6];
/// The landing's time constant (s): the normal deflection reaches the set point like this.
const LAND_TAU: f64 = 0.01;

/// The fake microscope's state.
#[derive(Debug)]
pub struct World {
    /// The sample.
    pub surface: Surface,
    tip_shape: Tip,
    noise: ScanParams,
    /// Tip x, y (m).
    pub tip: [f64; 2],
    /// Follow Me's target and speed.
    target: Option<[f64; 2]>,
    speed: f64,
    /// Z controller on.
    pub z_on: bool,
    /// Tip withdrawn (Z at its high limit, controller off).
    pub withdrawn: bool,
    z_held: f64,
    setpoint: f64,
    /// The normal deflection now (V).
    normal: f64,
    pushing: Option<usize>,
    /// Scan frame: centre x, y, width, height (m), angle (deg).
    pub frame: [f64; 5],
    /// Buffer: channels, pixels, lines.
    pub buffer: (Vec<i32>, usize, usize),
    /// Lines per second of the scan engine.
    pub line_rate: f64,
    scan_until: Option<Instant>,
    /// The last recorded image (heights, rows from the bottom up).
    pub image: Option<HeightImage>,
    /// Acquisition period of polled reads (s).
    pub acq_period: f64,
    /// Logger channels and oversampling; running.
    pub log_channels: Vec<i32>,
    /// Logger oversampling.
    pub log_oversampling: i32,
    /// Logger running.
    pub log_running: bool,
    /// Every command, in order, with its connection's number.
    pub log: Vec<(u64, String)>,
}

impl World {
    /// A world with the scene's sample, the tip withdrawn over the frame's centre, and a first
    /// image already recorded (what the controller's own software would show).
    pub fn new(scene: &Scene, line_rate: f64) -> World {
        let p = ScanParams::from_scene(scene);
        let mut w = World {
            surface: Surface::from_scene(scene),
            tip_shape: Tip::from_scene(scene),
            noise: p,
            tip: [p.centre_x, p.centre_y],
            target: None,
            speed: 1e-6,
            z_on: false,
            withdrawn: true,
            z_held: Z_LIMITS[1],
            setpoint: 0.0,
            normal: 0.0,
            pushing: None,
            frame: [p.centre_x, p.centre_y, p.size, p.size, 0.0],
            buffer: (vec![Z as i32], 64, 64),
            line_rate,
            scan_until: None,
            image: None,
            acq_period: 0.02,
            log_channels: Vec::new(),
            log_oversampling: 1,
            log_running: false,
            log: Vec::new(),
        };
        w.image = Some(w.record());
        w
    }

    /// The image of the sample as it is now, in the current frame and buffer: the scanner of
    /// the instrument crate (tip dilation and the scene's noise) on a square frame.
    pub fn record(&self) -> HeightImage {
        let [cx, cy, width, _, _] = self.frame;
        let mut p = self.noise;
        p.centre_x = cx;
        p.centre_y = cy;
        p.size = width;
        p.pixels = self.buffer.1;
        scan(&self.surface, self.tip_shape, p)
    }

    /// Tip height now (m).
    pub fn z(&self) -> f64 {
        if self.z_on {
            self.surface.topography.height(self.tip[0], self.tip[1])
        } else {
            self.z_held
        }
    }

    /// Advances `dt` seconds of wall-clock time.
    pub fn step(&mut self, dt: f64) {
        if let Some([tx, ty]) = self.target {
            let (dx, dy) = (tx - self.tip[0], ty - self.tip[1]);
            let left = dx.hypot(dy);
            let reach = self.speed * dt;
            let (ux, uy) = if left > 0.0 { (dx / left, dy / left) } else { (0.0, 0.0) };
            if left <= reach {
                self.tip = [tx, ty];
                self.target = None;
            } else {
                self.tip = [self.tip[0] + ux * reach, self.tip[1] + uy * reach];
            }
            self.carry(ux, uy);
        } else {
            self.pushing = None;
        }
        let goal = if self.z_on { self.setpoint } else { 0.0 };
        self.normal += (goal - self.normal) * (1.0 - (-dt / LAND_TAU).exp());
        if let Some(until) = self.scan_until
            && Instant::now() >= until
        {
            self.scan_until = None;
            self.image = Some(self.record());
        }
    }

    /// With the feedback on, a particle the tip runs into moves ahead of it.
    fn carry(&mut self, ux: f64, uy: f64) {
        self.pushing = None;
        if !self.z_on {
            return;
        }
        let rt = self.tip_shape.radius;
        for (i, s) in self.surface.spheres.iter_mut().enumerate() {
            let reach = s.r + rt;
            let (dx, dy) = (s.x - self.tip[0], s.y - self.tip[1]);
            let ahead = dx * ux + dy * uy;
            if dx.hypot(dy) < reach && ahead > 0.0 {
                s.x = self.tip[0] + ux * reach;
                s.y = self.tip[1] + uy * reach;
                self.pushing = Some(i);
            }
        }
    }

    /// A signal's value now.
    pub fn signal(&self, i: usize) -> f64 {
        match i {
            X => self.tip[0],
            Y => self.tip[1],
            Z => self.z(),
            NORMAL => self.normal,
            LATERAL if self.pushing.is_some() => LATERAL_PUSHING,
            LATERAL if self.z_on => LATERAL_FREE,
            _ => 0.0,
        }
    }

    /// Whether a scan is running.
    pub fn scanning(&self) -> bool {
        self.scan_until.is_some()
    }

    /// Answers one command: the response body (its error block included).
    pub fn handle(&mut self, name: &str, body: &[u8]) -> Vec<u8> {
        let mut w = BodyWriter::new();
        match self.dispatch(name, &mut BodyReader::new(body), &mut w) {
            Ok(()) => {
                ErrorBlock::ok().write(&mut w);
                w.into_bytes()
            }
            Err(message) => {
                let mut e = BodyWriter::new();
                ErrorBlock {
                    status: 1,
                    description: message,
                }
                .write(&mut e);
                e.into_bytes()
            }
        }
    }

    fn dispatch(&mut self, name: &str, r: &mut BodyReader<'_>, w: &mut BodyWriter) -> Result<(), String> {
        let f = |e: FrameError| format!("{name}: {e}");
        match name {
            "FolMe.XYPosSet" => {
                let (x, y, _wait) = (
                    r.f64("X").map_err(f)?,
                    r.f64("Y").map_err(f)?,
                    r.u32("wait").map_err(f)?,
                );
                if !(x.is_finite() && y.is_finite()) {
                    return Err("position is not a number".into());
                }
                self.target = Some([x, y]);
            }
            "FolMe.XYPosGet" => {
                r.u32("wait").map_err(f)?;
                w.f64(self.tip[0]).f64(self.tip[1]);
            }
            "FolMe.SpeedSet" => {
                let v = f64::from(r.f32("speed").map_err(f)?);
                r.u32("custom").map_err(f)?;
                if !(v.is_finite() && v > 0.0) {
                    return Err(format!("speed {v} m/s must be > 0"));
                }
                self.speed = v;
            }
            "FolMe.SpeedGet" => {
                w.f32(self.speed as f32).u32(1);
            }
            "FolMe.Stop" => self.target = None,
            "ZCtrl.OnOffSet" => {
                let on = r.u32("status").map_err(f)? == 1;
                if on {
                    self.withdrawn = false;
                } else {
                    self.z_held = self.z();
                }
                self.z_on = on;
            }
            "ZCtrl.OnOffGet" => {
                w.u32(self.z_on.into());
            }
            "ZCtrl.ZPosSet" => {
                let z = f64::from(r.f32("Z").map_err(f)?);
                if self.z_on {
                    return Err("Z-Controller is on: switch it off before setting Z".into());
                }
                self.z_held = z.clamp(Z_LIMITS[0], Z_LIMITS[1]);
                self.withdrawn = false;
            }
            "ZCtrl.ZPosGet" => {
                w.f32(self.z() as f32);
            }
            "ZCtrl.SetpntSet" => self.setpoint = f64::from(r.f32("setpoint").map_err(f)?),
            "ZCtrl.SetpntGet" => {
                w.f32(self.setpoint as f32);
            }
            "ZCtrl.Withdraw" => {
                r.u32("wait").map_err(f)?;
                r.i32("timeout").map_err(f)?;
                self.z_on = false;
                self.z_held = Z_LIMITS[1];
                self.withdrawn = true;
                self.target = None;
                self.pushing = None;
            }
            "ZCtrl.Home" => {
                self.z_on = false;
                self.z_held = 0.0;
            }
            "ZCtrl.StatusGet" => {
                w.u16(if self.z_on { 2 } else { 1 });
            }
            "ZCtrl.LimitsGet" => {
                w.f32(Z_LIMITS[1] as f32).f32(Z_LIMITS[0] as f32);
            }
            "Signals.NamesGet" => {
                let bytes: usize = SIGNALS.iter().map(|s| 4 + s.len()).sum();
                w.i32(bytes as i32).i32(SIGNALS.len() as i32);
                for s in SIGNALS {
                    w.string(s);
                }
            }
            "Signals.ValGet" => {
                let i = r.i32("index").map_err(f)?;
                r.u32("wait").map_err(f)?;
                let i = self.index(i)?;
                w.f32(self.signal(i) as f32);
            }
            "Signals.ValsGet" => {
                let n = r.count("count", SIGNALS.len() * 4).map_err(f)?;
                let idx = r.i32s("indexes", n).map_err(f)?;
                r.u32("wait").map_err(f)?;
                let vals: Result<Vec<f32>, String> =
                    idx.iter().map(|&i| Ok(self.signal(self.index(i)?) as f32)).collect();
                let vals = vals?;
                w.i32(vals.len() as i32).f32s(&vals);
            }
            "Scan.Action" => {
                let action = r.u16("action").map_err(f)?;
                r.u32("direction").map_err(f)?;
                match action {
                    0 => {
                        if self.withdrawn {
                            return Err("the tip is withdrawn: approach before scanning".into());
                        }
                        let secs = self.buffer.2 as f64 / self.line_rate;
                        self.scan_until = Some(Instant::now() + std::time::Duration::from_secs_f64(secs));
                    }
                    1 => self.scan_until = None,
                    2..=6 => {}
                    a => return Err(format!("scan action {a} is not one of 0-6")),
                }
            }
            "Scan.FrameSet" => {
                let v: Result<Vec<f32>, FrameError> = (0..5).map(|_| r.f32("frame")).collect();
                let v = v.map_err(f)?;
                if v[2] <= 0.0 || v[3] <= 0.0 || v.iter().any(|x| !x.is_finite()) {
                    return Err(format!("frame {v:?} must have a positive width and height"));
                }
                self.frame = std::array::from_fn(|i| f64::from(v[i]));
            }
            "Scan.FrameGet" => {
                for v in self.frame {
                    w.f32(v as f32);
                }
            }
            "Scan.BufferSet" => {
                let n = r.count("channels", 16).map_err(f)?;
                let ch = r.i32s("channel indexes", n).map_err(f)?;
                let px = r.count("pixels", 8192).map_err(f)?;
                let lines = r.count("lines", 8192).map_err(f)?;
                for &c in &ch {
                    self.index(c)?;
                }
                if px < 16 {
                    return Err(format!("pixels {px} must be at least 16"));
                }
                // The fake's scan engine images squares.
                self.buffer = (ch, px, if lines == 0 { px } else { lines });
            }
            "Scan.BufferGet" => {
                let (ch, px, lines) = &self.buffer;
                w.i32(ch.len() as i32).i32s(ch).i32(*px as i32).i32(*lines as i32);
            }
            "Scan.StatusGet" => {
                w.u32(self.scanning().into());
            }
            "Scan.WaitEndOfScan" => {
                // Answered by the connection, which waits without holding the world.
                r.i32("timeout").map_err(f)?;
                w.u32(u32::from(self.scanning())).u32(0);
            }
            "Scan.FrameDataGrab" => {
                let ch = r.u32("channel").map_err(f)? as i32;
                r.u32("direction").map_err(f)?;
                if !self.buffer.0.contains(&ch) {
                    return Err(format!("channel {ch} is not in the scan buffer {:?}", self.buffer.0));
                }
                let img = self.image.as_ref().ok_or("no scan recorded yet")?;
                let name = SIGNALS[ch as usize];
                w.string(name).i32(img.yres as i32).i32(img.xres as i32);
                let data: Vec<f32> = if ch as usize == Z {
                    img.data.iter().map(|&v| v as f32).collect()
                } else {
                    vec![0.0; img.data.len()]
                };
                w.f32s(&data).u32(1);
            }
            "Util.AcqPeriodSet" => {
                let p = f64::from(r.f32("period").map_err(f)?);
                if !(p.is_finite() && (1e-3..=1.0).contains(&p)) {
                    return Err(format!("acquisition period {p} s out of [0.001, 1] s"));
                }
                self.acq_period = p;
            }
            "Util.RTFreqGet" => {
                w.f32(10_000.0);
            }
            "TCPLog.ChsSet" => {
                let n = r.count("channels", 24).map_err(f)?;
                let ch = r.i32s("channel indexes", n).map_err(f)?;
                for &c in &ch {
                    self.index(c)?;
                }
                self.log_channels = ch;
            }
            "TCPLog.OversamplSet" => {
                let n = r.i32("oversampling").map_err(f)?;
                if !(0..=1000).contains(&n) {
                    return Err(format!("oversampling {n} out of [0, 1000]"));
                }
                self.log_oversampling = n;
            }
            "TCPLog.Start" => {
                if self.log_channels.is_empty() {
                    return Err("no logger channels set".into());
                }
                self.log_running = true;
            }
            "TCPLog.Stop" => self.log_running = false,
            "TCPLog.StatusGet" => {
                w.i32(if self.log_running { 4 } else { 1 });
            }
            other => return Err(format!("unknown command {other:?}")),
        }
        if r.remaining() != 0 {
            return Err(format!(
                "{name}: {} bytes more than the command's arguments",
                r.remaining()
            ));
        }
        Ok(())
    }

    fn index(&self, i: i32) -> Result<usize, String> {
        usize::try_from(i)
            .ok()
            .filter(|&i| i < SIGNALS.len())
            .ok_or_else(|| format!("signal index {i} out of [0, {}]", SIGNALS.len() - 1))
    }
}
