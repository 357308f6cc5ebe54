//! The simulated operator: the hand as a spring-damper pulling the handle toward a set point
//! that a script moves, so that everything runs headless and repeatably.
//!
//! ```text
//! F_hand = k_h · (x_set(t) − x) + b_h · (ẋ_set(t) − ẋ)
//! ```
//!
//! with a firm grip (`k_h` = 500 N/m, `b_h` = 8 N·s/m: the stiffness and damping of a human
//! wrist and fingers holding a stylus lie around 200-1000 N/m and 2-10 N·s/m). The grips that
//! probe the loop's stability ([`Grip`]): a stiff one (1000 N/m, 20 N·s/m: a clenched hand, which
//! hides little), a loose one (50 N/m, 1 N·s/m: fingertips, which add almost no damping), and a
//! hand that lets go of the handle in contact (nothing but the device's own friction is left).
//!
//! Scripts (`--operator`), in handle coordinates (m, positive up):
//! - `hold`: keep the handle where it started;
//! - `sine`: ±3 mm at 0.5 Hz about the start, from the start (free motion when engaged with the
//!   tip parked above the surface);
//! - `press`: once haptic z-control is engaged, move down at 3 mm/s until the hand feels the
//!   surface push back with 0.8 N (or 30 mm at most), hold 1 s, move back up at 3 mm/s to 3 mm
//!   above where it started (through the adhesive pull-off), rest 0.5 s, end;
//! - `stiff-grip`, `loose-grip`: `press` with the stiff or the loose grip;
//! - `let-go`: `press` with the firm grip, but 0.3 s into the hold the hand lets go of the handle
//!   for 1 s (no hand force at all: the handle must come to rest on its own), then takes it again
//!   where its set point was and finishes the press (the closed cycle);
//! - `tap`: once engaged, move down at 3 mm/s until the hand feels 0.3 N (or 30 mm at most), then
//!   tap the surface 4 times at 2 Hz (the set point rises 4 mm above that depth and comes back,
//!   `x = d + A (1 − cos 2π f t)/2`), then up to 3 mm above the start, rest 0.5 s, end;
//! - `file:PATH`: once engaged, follow the set points of a CSV `t_s,handle_m` (a header line is
//!   allowed; times increasing from 0), linearly between rows; ends after the last row.
//!
//! `press`, its grips, `tap` and `file:` wait for the engagement, as a person would: until the link says the tip
//! is under haptic control and the force ramp has ended.

use std::path::Path;

/// Why a script could not be made.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ScriptError {
    /// Not a known script.
    #[error(
        "--operator {0:?}: unknown script; allowed: hold, sine, press, stiff-grip, loose-grip, let-go, tap, file:PATH"
    )]
    Unknown(String),
    /// The script file could not be read.
    #[error("--operator file:{path}: {source}")]
    Read {
        /// File.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// A row of the script file is wrong.
    #[error("--operator file:{path}, line {line}: {why}")]
    Row {
        /// File.
        path: String,
        /// Line (1-based).
        line: usize,
        /// What is wrong, with the allowed range.
        why: String,
    },
}

/// Stiffness of the hand's grip (N/m).
pub const HAND_STIFFNESS: f64 = 500.0;
/// Damping of the hand's grip (N·s/m).
pub const HAND_DAMPING: f64 = 8.0;
/// Set-point speed of `press` (m/s): 3 mm/s, 30 nm/s of tip at the default scaling.
pub const PRESS_SPEED: f64 = 3e-3;
/// Force at which `press` stops going down (N).
pub const PRESS_FORCE: f64 = 0.8;
/// Deepest `press` goes below its start (m).
pub const PRESS_DEPTH: f64 = 0.03;
/// Force at which `tap` has found the surface (N).
pub const TAP_FORCE: f64 = 0.3;
/// `tap`'s rate (Hz).
pub const TAP_HZ: f64 = 2.0;
/// How far `tap`'s set point rises above the depth where it found the surface (m).
pub const TAP_LIFT: f64 = 4e-3;
/// Taps `tap` makes.
pub const TAPS: u32 = 4;
/// How long into the hold `let-go` lets go (s).
pub const LET_GO_AFTER: f64 = 0.3;
/// How long `let-go` leaves the handle alone (s).
pub const LET_GO_FOR: f64 = 1.0;
/// Set points of a script file, at most.
pub const MAX_FILE_ROWS: usize = 1_000_000;
/// Travel a script file may ask for (m): ±0.1 m.
pub const FILE_RANGE: f64 = 0.1;

/// A script of hand set points.
#[derive(Debug, Clone, PartialEq)]
pub enum Script {
    /// Stay at the start.
    Hold,
    /// ±`amplitude` (m) at `hz` about the start.
    Sine {
        /// Amplitude (m).
        amplitude: f64,
        /// Frequency (Hz).
        hz: f64,
    },
    /// Press into the surface and pull off with a grip (see the module doc).
    Press(Grip),
    /// Find the surface and tap it at 2 Hz (see the module doc).
    Tap,
    /// Set points `(t_s, handle_m)` from a file.
    File(Vec<(f64, f64)>),
}

impl Script {
    /// Parses `--operator`.
    pub fn parse(s: &str) -> Result<Script, ScriptError> {
        match s {
            "hold" => Ok(Script::Hold),
            "sine" => Ok(Script::Sine {
                amplitude: 3e-3,
                hz: 0.5,
            }),
            "press" => Ok(Script::Press(Grip::Firm)),
            "stiff-grip" => Ok(Script::Press(Grip::Stiff)),
            "loose-grip" => Ok(Script::Press(Grip::Loose)),
            "let-go" => Ok(Script::Press(Grip::LetGo)),
            "tap" => Ok(Script::Tap),
            _ => match s.strip_prefix("file:") {
                Some(path) => Script::from_file(Path::new(path)),
                None => Err(ScriptError::Unknown(s.to_string())),
            },
        }
    }

    /// Reads a `t_s,handle_m` CSV.
    pub fn from_file(path: &Path) -> Result<Script, ScriptError> {
        let p = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|source| ScriptError::Read {
            path: p.clone(),
            source,
        })?;
        Script::from_csv(&p, &text)
    }

    /// Parses a `t_s,handle_m` CSV (`path` names it in errors).
    pub fn from_csv(path: &str, text: &str) -> Result<Script, ScriptError> {
        let mut rows: Vec<(f64, f64)> = Vec::new();
        for (i, line) in text.lines().enumerate() {
            let line = line.trim();
            let err = |why: String| ScriptError::Row {
                path: path.to_string(),
                line: i + 1,
                why,
            };
            if line.is_empty() || line.starts_with('#') || (i == 0 && line.starts_with("t_s")) {
                continue;
            }
            if rows.len() == MAX_FILE_ROWS {
                return Err(err(format!("more than {MAX_FILE_ROWS} rows")));
            }
            let mut cols = line.split(',').map(str::trim);
            let (Some(t), Some(x), None) = (cols.next(), cols.next(), cols.next()) else {
                return Err(err("expected two columns t_s,handle_m".into()));
            };
            let t: f64 = t.parse().map_err(|_| err(format!("t_s {t:?} is not a number")))?;
            let x: f64 = x.parse().map_err(|_| err(format!("handle_m {x:?} is not a number")))?;
            if !(t.is_finite() && t >= 0.0) {
                return Err(err(format!("t_s = {t} is out of range; allowed: [0, ∞) s")));
            }
            if rows.last().is_some_and(|&(t0, _)| t <= t0) {
                return Err(err(format!("t_s = {t} does not increase")));
            }
            if !(x.is_finite() && x.abs() <= FILE_RANGE) {
                return Err(err(format!(
                    "handle_m = {x} is out of range; allowed: [-{FILE_RANGE}, {FILE_RANGE}] m"
                )));
            }
            rows.push((t, x));
        }
        if rows.is_empty() {
            return Err(ScriptError::Row {
                path: path.to_string(),
                line: 0,
                why: "no set points".into(),
            });
        }
        Ok(Script::File(rows))
    }

    /// Whether the script waits for the engagement before it starts.
    pub fn waits_for_engagement(&self) -> bool {
        matches!(self, Script::Press(_) | Script::Tap | Script::File(_))
    }
}

/// How the hand holds the handle during `press`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Grip {
    /// [`HAND_STIFFNESS`], [`HAND_DAMPING`].
    Firm,
    /// 1000 N/m, 20 N·s/m.
    Stiff,
    /// 50 N/m, 1 N·s/m.
    Loose,
    /// Firm, but lets go of the handle for [`LET_GO_FOR`] in the hold.
    LetGo,
}

impl Grip {
    /// The grip's stiffness (N/m) and damping (N·s/m).
    pub fn impedance(self) -> (f64, f64) {
        match self {
            Grip::Firm | Grip::LetGo => (HAND_STIFFNESS, HAND_DAMPING),
            Grip::Stiff => (1000.0, 20.0),
            Grip::Loose => (50.0, 1.0),
        }
    }
}

/// Where `press` is.
#[derive(Debug, Clone, Copy, PartialEq)]
enum PressPhase {
    Settle { until: f64 },
    Down,
    Hold { until: f64 },
    Tap { from: f64 },
    Up,
    Rest { until: f64 },
    Done,
}

/// The hand: a spring-damper following a script.
#[derive(Debug, Clone, PartialEq)]
pub struct Operator {
    script: Script,
    /// Handle position the hand started from (m).
    origin: f64,
    /// Script clock origin (s), once started.
    start: Option<f64>,
    /// Current set point (m) and its rate (m/s).
    set: f64,
    rate: f64,
    press: PressPhase,
    /// Lowest set point `press` reached (m).
    deepest: f64,
    /// Time of the last update (s).
    last_t: f64,
    /// The hand has let go of the handle (`let-go`): it exerts no force.
    released: bool,
    /// The hand has let go once: after it takes the handle again, the hold is not the steady
    /// one the tip-force bound is for.
    let_go_once: bool,
    /// Hand stiffness (N/m) and damping (N·s/m).
    pub stiffness: f64,
    /// Hand damping (N·s/m).
    pub damping: f64,
}

impl Operator {
    /// A hand holding the handle at `origin` (m) that will play `script`.
    pub fn new(script: Script, origin: f64) -> Operator {
        let (stiffness, damping) = match script {
            Script::Press(grip) => grip.impedance(),
            _ => (HAND_STIFFNESS, HAND_DAMPING),
        };
        Operator {
            script,
            origin,
            start: None,
            set: origin,
            rate: 0.0,
            press: PressPhase::Settle { until: 0.3 },
            deepest: origin,
            last_t: 0.0,
            released: false,
            let_go_once: false,
            stiffness,
            damping,
        }
    }

    /// Advances the script to time `t` (s since the bridge started): `engaged` says the tip is
    /// under haptic control, `felt` is the force the device renders now (N, positive up).
    pub fn update(&mut self, t: f64, dt: f64, engaged: bool, felt: f64) {
        self.last_t = t;
        if self.start.is_none() && (engaged || !self.script.waits_for_engagement()) {
            self.start = Some(t);
        }
        let Some(t0) = self.start else {
            self.rate = 0.0;
            return;
        };
        let s = t - t0;
        let (set, rate) = match &self.script {
            Script::Hold => (self.origin, 0.0),
            Script::Sine { amplitude, hz } => {
                let w = 2.0 * std::f64::consts::PI * hz;
                (self.origin + amplitude * (w * s).sin(), amplitude * w * (w * s).cos())
            }
            Script::File(rows) => interpolate(rows, s),
            Script::Press(grip) => {
                let grip = *grip;
                self.press_step(s, dt, felt, grip)
            }
            Script::Tap => self.press_step(s, dt, felt, Grip::Firm),
        };
        self.set = set;
        self.rate = rate;
    }

    /// `press` (with `grip`) and `tap`: down until the surface is felt, then hold (or tap), up,
    /// rest.
    fn press_step(&mut self, s: f64, dt: f64, felt: f64, grip: Grip) -> (f64, f64) {
        let (mut set, mut rate) = (self.set, 0.0);
        let tap = self.script == Script::Tap;
        let enough = if tap { TAP_FORCE } else { PRESS_FORCE };
        self.press = match self.press {
            PressPhase::Settle { until } if s >= until => PressPhase::Down,
            PressPhase::Down if felt >= enough || self.origin - set >= PRESS_DEPTH => {
                self.deepest = set;
                if tap {
                    PressPhase::Tap { from: s }
                } else {
                    PressPhase::Hold {
                        until: s + 1.0 + if grip == Grip::LetGo { LET_GO_FOR } else { 0.0 },
                    }
                }
            }
            PressPhase::Tap { from } if s - from >= f64::from(TAPS) / TAP_HZ => {
                set = self.deepest;
                PressPhase::Up
            }
            PressPhase::Tap { from } => {
                let w = 2.0 * std::f64::consts::PI * TAP_HZ;
                let u = s - from;
                set = self.deepest + 0.5 * TAP_LIFT * (1.0 - (w * u).cos());
                rate = 0.5 * TAP_LIFT * w * (w * u).sin();
                PressPhase::Tap { from }
            }
            PressPhase::Hold { until } if grip == Grip::LetGo => {
                let held_for = s - (until - 1.0 - LET_GO_FOR);
                self.released = (LET_GO_AFTER..LET_GO_AFTER + LET_GO_FOR).contains(&held_for);
                self.let_go_once |= self.released;
                if s >= until {
                    PressPhase::Up
                } else {
                    PressPhase::Hold { until }
                }
            }
            PressPhase::Down => {
                set -= PRESS_SPEED * dt;
                rate = -PRESS_SPEED;
                PressPhase::Down
            }
            PressPhase::Hold { until } if s >= until => PressPhase::Up,
            PressPhase::Up if set >= self.origin + 3e-3 => PressPhase::Rest { until: s + 0.5 },
            PressPhase::Up => {
                set += PRESS_SPEED * dt;
                rate = PRESS_SPEED;
                PressPhase::Up
            }
            PressPhase::Rest { until } if s >= until => PressPhase::Done,
            p => p,
        };
        (set, rate)
    }

    /// The hand's force on the handle at position `x`, velocity `v` (N): none while it has let
    /// go.
    pub fn force(&self, x: f64, v: f64) -> f64 {
        if self.released {
            return 0.0;
        }
        self.stiffness * (self.set - x) + self.damping * (self.rate - v)
    }

    /// Whether the hand holds the tip in contact now: `press` (any grip) in its hold, with the
    /// handle in its hand.
    pub fn holding(&self) -> bool {
        matches!(self.press, PressPhase::Hold { .. }) && !self.let_go_once && matches!(self.script, Script::Press(_))
    }

    /// Whether the hand has let go of the handle (`let-go`).
    pub fn released(&self) -> bool {
        self.released
    }

    /// The lowest set point `press` went down to (m).
    pub fn deepest(&self) -> f64 {
        self.deepest
    }

    /// The set point now (m).
    pub fn set_point(&self) -> f64 {
        self.set
    }

    /// Whether a finite script has ended.
    pub fn finished(&self) -> bool {
        match &self.script {
            Script::Hold | Script::Sine { .. } => false,
            Script::Press(_) | Script::Tap => self.press == PressPhase::Done,
            Script::File(rows) => match (self.start, rows.last()) {
                (Some(_), Some(&(t_last, _))) => self.elapsed() > t_last,
                _ => false,
            },
        }
    }

    /// Script time (s) since it started; 0 before.
    fn elapsed(&self) -> f64 {
        self.last_t - self.start.unwrap_or(self.last_t)
    }
}

/// Linear interpolation of set points at `s`, with the slope.
fn interpolate(rows: &[(f64, f64)], s: f64) -> (f64, f64) {
    let i = rows.partition_point(|&(t, _)| t <= s);
    match (i, rows.get(i)) {
        (0, _) => (rows[0].1, 0.0),
        (_, None) => (rows[rows.len() - 1].1, 0.0),
        (i, Some(&(t1, x1))) => {
            let (t0, x0) = rows[i - 1];
            let slope = (x1 - x0) / (t1 - t0);
            (x0 + slope * (s - t0), slope)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scripts_parse_and_bad_ones_name_what_is_wrong() {
        assert_eq!(Script::parse("hold").unwrap(), Script::Hold);
        assert_eq!(Script::parse("press").unwrap(), Script::Press(Grip::Firm));
        assert_eq!(Script::parse("stiff-grip").unwrap(), Script::Press(Grip::Stiff));
        assert_eq!(Script::parse("loose-grip").unwrap(), Script::Press(Grip::Loose));
        assert_eq!(Script::parse("let-go").unwrap(), Script::Press(Grip::LetGo));
        assert_eq!(Script::parse("tap").unwrap(), Script::Tap);
        assert!(matches!(Script::parse("sine").unwrap(), Script::Sine { .. }));
        let e = Script::parse("wiggle").unwrap_err().to_string();
        assert!(
            e.contains("wiggle")
                && e.contains("allowed: hold, sine, press, stiff-grip, loose-grip, let-go, tap, file:PATH"),
            "{e}"
        );
        let e = Script::parse("file:/nonexistent/x.csv").unwrap_err().to_string();
        assert!(e.contains("/nonexistent/x.csv"), "{e}");
        let ok = Script::from_csv("s.csv", "t_s,handle_m\n0,0\n1,0.01\n").unwrap();
        assert_eq!(ok, Script::File(vec![(0.0, 0.0), (1.0, 0.01)]));
        for (text, why) in [
            ("0,0\n0,0.01\n", "does not increase"),
            ("0,0\n1,0.5\n", "allowed: [-0.1, 0.1] m"),
            ("0,abc\n", "not a number"),
            ("-1,0\n", "allowed: [0, ∞) s"),
            ("0,0,0\n", "two columns"),
            ("t_s,handle_m\n", "no set points"),
            ("0,NaN\n", "out of range"),
        ] {
            let e = Script::from_csv("s.csv", text).unwrap_err().to_string();
            assert!(e.contains(why) && e.contains("s.csv"), "{text:?}: {e}");
        }
    }

    #[test]
    fn a_file_script_interpolates_and_ends_after_its_last_row() {
        let mut op = Operator::new(Script::from_csv("s", "0,0\n1,0.01\n2,0.01\n").unwrap(), 0.0);
        // Waits for the engagement.
        op.update(0.5, 1e-3, false, 0.0);
        assert_eq!(op.set_point(), 0.0);
        op.update(1.0, 1e-3, true, 0.0);
        op.update(1.5, 1e-3, true, 0.0);
        assert!((op.set_point() - 0.005).abs() < 1e-12);
        assert!((op.rate - 0.01).abs() < 1e-12);
        assert!(!op.finished());
        op.update(3.1, 1e-3, true, 0.0);
        assert_eq!(op.set_point(), 0.01);
        assert!(op.finished());
    }

    /// `press` goes down until it feels the surface, holds, comes back up past its start, ends.
    #[test]
    fn press_follows_its_phases_on_what_the_hand_feels() {
        let dt = 1e-3;
        let mut op = Operator::new(Script::Press(Grip::Firm), 0.002);
        let mut t = 0.0;
        let mut step = |op: &mut Operator, engaged: bool, felt: f64| {
            t += dt;
            op.update(t, dt, engaged, felt);
        };
        for _ in 0..100 {
            step(&mut op, false, 0.0);
        }
        assert_eq!(op.set_point(), 0.002, "waits for the engagement");
        // Settles, then goes down at 3 mm/s.
        for _ in 0..1300 {
            step(&mut op, true, 0.0);
        }
        assert!(
            (op.set_point() - (0.002 - PRESS_SPEED * 1.0)).abs() < 2e-5,
            "{}",
            op.set_point()
        );
        // The surface pushes back: it holds where it is for 1 s.
        step(&mut op, true, 1.0);
        let held = op.set_point();
        for _ in 0..900 {
            step(&mut op, true, 1.0);
        }
        assert_eq!(op.set_point(), held);
        assert_eq!(op.deepest(), held);
        // Then up to 3 mm above the start, rest, end.
        for _ in 0..3000 {
            step(&mut op, true, -0.5);
        }
        assert!(op.set_point() >= 0.005 - 1e-9);
        assert!(!op.finished() || op.set_point() >= 0.005 - 1e-9);
        for _ in 0..700 {
            step(&mut op, true, 0.0);
        }
        assert!(op.finished());
        // The hand is a spring-damper toward the set point.
        assert!((op.force(op.set_point() - 0.001, 0.0) - HAND_STIFFNESS * 0.001).abs() < 1e-12);
    }
}
