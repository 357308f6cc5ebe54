//! Parameter sweeps of the paper's Figs 10-13: the settled particle `y` and deflection `ζ_z`
//! against the tilt `α`, the contact angle `β`, the friction `μ_as^s` or the radius `Rₐ`.
//!
//! Each point is computed two ways, because they differ:
//! - **Eq 18** ([`steady_state`]): the paper's closed-form steady state, which assumes pure
//!   sliding (no rolling) and kinetic friction at both contacts, as the paper's Sec 5 does;
//! - **the dynamic model** (Eq 17, [`run_push`]): the push is integrated until it settles and the
//!   settled values are the means over the tail of the run (Sec 3: "the mean of the periodic
//!   function can be used"), with the tail's spread (max − min) and friction-phase switches as
//!   the sign of a periodic (stick-slip) or unstable push. With free rotation the default 1 µm
//!   particle rolls instead of sliding, so this differs from Eq 18.
//!
//! The particle `y` of both is its offset behind the stage, `s − y_particle` in the frame of
//! the substrate: the tip's deflection projected on the push plus `Δy` (Eq 18's
//! `y = ζ_y cos α + ζ_z sin α + Δy`), zero at first contact as in the paper ("contact point
//! between the tip and particle is y = 0").
//!
//! Points are independent: [`compute_point`] computes one, the caller runs them in parallel.
//! [`Shard::range`] splits the global index range into contiguous blocks for batch schedulers.
//!
//! ```
//! use nanopush_study::sweep::{Param, grid};
//! let p = Param::parse("alpha").unwrap();
//! assert_eq!(p.figure(), 10);
//! assert_eq!(grid(0.0, 30.0, 4), vec![0.0, 10.0, 20.0, 30.0]);
//! ```

use std::panic::{AssertUnwindSafe, catch_unwind};

use nanopush_instrument::numerics::integrate::{Method, Options};
use nanopush_instrument::physics::pushing::steady::SteadyError;
use nanopush_instrument::physics::pushing::trace::{PushRun, run_push};
use nanopush_instrument::physics::pushing::{Dof, PushModel, PushParams, SteadyInputs, SteadyState, steady_state};
use nanopush_instrument::scene::{Scene, SceneError, SceneFile};

/// A swept scene parameter.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Param {
    /// Cantilever tilt `α` (`cantilever.tilt_deg`, degrees): Fig 10.
    Alpha,
    /// Tip-particle contact angle `β` (`push.contact_angle_deg`, degrees): Fig 11.
    Beta,
    /// Particle-substrate static friction `μ_as^s` (`friction.particle_substrate_static`); the
    /// kinetic coefficient follows it at the base scene's ratio `μ_as^k/μ_as^s` (0.2/0.3 in the
    /// paper's scene), so the pair keeps the paper's proportion and stays valid (`μᵏ ≤ μˢ`).
    /// The tip-particle coefficients are not changed: the paper's symbol is `μ_as^s`. Fig 12.
    MuAs,
    /// Radius `Rₐ` of the pushed particle (`particles[i].radius_nm`, nm): Fig 13.
    Radius,
}

/// Why a sweep cannot be set up.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SweepError {
    /// Not one of [`Param::ALL`].
    #[error("--param {given}: unknown; allowed: {allowed}")]
    UnknownParam {
        /// What was given.
        given: String,
        /// The names with their ranges.
        allowed: String,
    },
    /// A sweep bound outside the parameter's range.
    #[error("--{bound} {value} is out of range for {param}; allowed: {allowed}")]
    OutOfRange {
        /// `from` or `to`.
        bound: &'static str,
        /// The parameter's name.
        param: &'static str,
        /// The value given.
        value: f64,
        /// The range with its unit.
        allowed: String,
    },
    /// `--from` above `--to`, or one point asked for two different bounds.
    #[error("--from {from} and --to {to} with --steps {steps}: {message}")]
    Bounds {
        /// Lower bound.
        from: f64,
        /// Upper bound.
        to: f64,
        /// Points.
        steps: usize,
        /// What is wrong.
        message: &'static str,
    },
    /// A bad `--steps`.
    #[error("--steps {0} is out of range; allowed: [1, {MAX_STEPS}]")]
    Steps(usize),
    /// A bad `--shard`.
    #[error("--shard {given}: {message}")]
    Shard {
        /// What was given.
        given: String,
        /// What is wrong.
        message: String,
    },
}

/// Most points in one sweep.
pub const MAX_STEPS: usize = 100_000;

impl Param {
    /// Every parameter, in figure order.
    pub const ALL: [Param; 4] = [Param::Alpha, Param::Beta, Param::MuAs, Param::Radius];

    /// The command-line name.
    pub fn name(self) -> &'static str {
        match self {
            Param::Alpha => "alpha",
            Param::Beta => "beta",
            Param::MuAs => "mu_as",
            Param::Radius => "radius",
        }
    }

    /// The paper's symbol.
    pub fn symbol(self) -> &'static str {
        match self {
            Param::Alpha => "α",
            Param::Beta => "β",
            Param::MuAs => "μ_as^s",
            Param::Radius => "Rₐ",
        }
    }

    /// User unit of the values (empty when dimensionless).
    pub fn unit(self) -> &'static str {
        match self {
            Param::Alpha | Param::Beta => "deg",
            Param::MuAs => "",
            Param::Radius => "nm",
        }
    }

    /// The paper's figure.
    pub fn figure(self) -> u32 {
        match self {
            Param::Alpha => 10,
            Param::Beta => 11,
            Param::MuAs => 12,
            Param::Radius => 13,
        }
    }

    /// The scene field it sets.
    pub fn field(self) -> &'static str {
        match self {
            Param::Alpha => "cantilever.tilt_deg",
            Param::Beta => "push.contact_angle_deg",
            Param::MuAs => "friction.particle_substrate_static",
            Param::Radius => "particles[pushed].radius_nm",
        }
    }

    /// Allowed closed range in user units: the scene validation's range of [`Param::field`]
    /// (tested against it).
    pub fn range(self) -> (f64, f64) {
        match self {
            Param::Alpha => (0.0, 75.0),
            Param::Beta => (1.0, 89.0),
            Param::MuAs => (0.0, 5.0),
            Param::Radius => (2.0, 10000.0),
        }
    }

    /// `[lo, hi] unit`.
    pub fn range_text(self) -> String {
        let (lo, hi) = self.range();
        let unit = self.unit();
        if unit.is_empty() {
            format!("[{lo}, {hi}]")
        } else {
            format!("[{lo}, {hi}] {unit}")
        }
    }

    /// Parses a command-line name; the error lists every name with its range.
    pub fn parse(s: &str) -> Result<Param, SweepError> {
        Param::ALL
            .into_iter()
            .find(|p| p.name() == s)
            .ok_or_else(|| SweepError::UnknownParam {
                given: s.into(),
                allowed: Param::ALL
                    .iter()
                    .map(|p| format!("{} {} ({})", p.name(), p.range_text(), p.symbol()))
                    .collect::<Vec<_>>()
                    .join(", "),
            })
    }

    /// A copy of `base` with this parameter set to `value` (user units), validated again, so a
    /// value the scene does not allow gets the scene's own error.
    pub fn apply(self, base: &Scene, value: f64) -> Result<Scene, SceneError> {
        let mut file: SceneFile = base.file.clone();
        match self {
            Param::Alpha => file.cantilever.tilt_deg = value,
            Param::Beta => file.push.contact_angle_deg = value,
            Param::MuAs => {
                let f = &mut file.friction;
                let ratio = if f.particle_substrate_static > 0.0 {
                    f.particle_substrate_kinetic / f.particle_substrate_static
                } else {
                    1.0
                };
                f.particle_substrate_static = value;
                f.particle_substrate_kinetic = value * ratio;
            }
            Param::Radius => {
                let id = file.push.particle_id;
                if let Some(p) = file.particles.iter_mut().find(|p| p.id == id) {
                    p.radius_nm = value;
                }
            }
        }
        let origin = format!("{} with {} = {value}", base.origin, self.name());
        Scene::from_file(&origin, file)
    }

    /// Checks `--from`, `--to` and `--steps`.
    pub fn check_bounds(self, from: f64, to: f64, steps: usize) -> Result<(), SweepError> {
        let (lo, hi) = self.range();
        for (bound, value) in [("from", from), ("to", to)] {
            if !(value.is_finite() && value >= lo && value <= hi) {
                return Err(SweepError::OutOfRange {
                    bound,
                    param: self.name(),
                    value,
                    allowed: self.range_text(),
                });
            }
        }
        if !(1..=MAX_STEPS).contains(&steps) {
            return Err(SweepError::Steps(steps));
        }
        if from > to {
            return Err(SweepError::Bounds {
                from,
                to,
                steps,
                message: "--from must not be above --to",
            });
        }
        if steps == 1 && from != to {
            return Err(SweepError::Bounds {
                from,
                to,
                steps,
                message: "one point needs --from = --to (or use --steps 2 or more)",
            });
        }
        Ok(())
    }
}

/// `steps` evenly spaced values from `from` to `to`, both included (`from` alone for one step).
/// Each value is computed from its index, so a shard computes exactly the global grid's values.
pub fn grid(from: f64, to: f64, steps: usize) -> Vec<f64> {
    (0..steps).map(|i| grid_value(from, to, steps, i)).collect()
}

/// The `i`-th value of [`grid`], rounded to 12 significant digits (so a step of 0.1 prints as
/// 0.4, not 0.3999999999999999); the ends are exactly `from` and `to`.
pub fn grid_value(from: f64, to: f64, steps: usize, i: usize) -> f64 {
    if steps <= 1 || i == 0 {
        return from;
    }
    if i + 1 >= steps {
        return to;
    }
    let v = from + (to - from) * i as f64 / (steps - 1) as f64;
    format!("{v:.11e}").parse().unwrap_or(v)
}

/// A shard `i/n` of a sweep (`0 ≤ i < n`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    /// This shard, from 0.
    pub index: usize,
    /// Number of shards.
    pub count: usize,
}

impl Shard {
    /// The whole sweep.
    pub const ALL: Shard = Shard { index: 0, count: 1 };

    /// Parses `i/n`: a Slurm array's `$SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT`, a
    /// Kubernetes indexed job's `$JOB_COMPLETION_INDEX/<completions>`.
    pub fn parse(s: &str) -> Result<Shard, SweepError> {
        let bad = |message: String| SweepError::Shard {
            given: s.into(),
            message,
        };
        let (i, n) = s
            .split_once('/')
            .ok_or_else(|| bad("expected i/n, e.g. 0/4 (shards 0 to n−1 of n)".into()))?;
        let index: usize = i
            .trim()
            .parse()
            .map_err(|_| bad(format!("shard index {i:?} is not a non-negative integer")))?;
        let count: usize = n
            .trim()
            .parse()
            .map_err(|_| bad(format!("shard count {n:?} is not a positive integer")))?;
        if count == 0 {
            return Err(bad("the shard count must be at least 1".into()));
        }
        if index >= count {
            return Err(bad(format!(
                "shard index {index} is out of range; allowed: 0 to {} (shards are numbered from 0)",
                count - 1
            )));
        }
        Ok(Shard { index, count })
    }

    /// This shard's contiguous block of the global indices `0..points`:
    /// `[⌊i·N/n⌋, ⌊(i+1)·N/n⌋)`. The blocks of `0/n … (n−1)/n` cover `0..N` exactly once, in order.
    pub fn range(self, points: usize) -> std::ops::Range<usize> {
        let at = |k: usize| k * points / self.count;
        at(self.index)..at(self.index + 1)
    }
}

/// How each point's push is run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointOptions {
    /// Simulated push (s): long enough to shear and settle.
    pub duration: f64,
    /// Trace sample interval (s).
    pub sample: f64,
    /// Fraction of the run, at its end, over which the settled values are taken.
    pub tail: f64,
    /// Integration method.
    pub method: Method,
    /// Relative tolerance.
    pub rtol: f64,
    /// Turn the particle's rotation off, so it can only stick or slide: Eq 18's assumption.
    pub pure_sliding: bool,
}

impl Default for PointOptions {
    /// 0.2 s at 1 ms samples, settled values over the last quarter (50 ms, 50 nm of travel at
    /// the paper's 1 µm/s); Rodas4 at rtol 1e-6, free rotation.
    fn default() -> PointOptions {
        PointOptions {
            duration: 0.2,
            sample: 1e-3,
            tail: 0.25,
            method: Method::Rodas4,
            rtol: 1e-6,
            pure_sliding: false,
        }
    }
}

/// Mean and extremes of a quantity over the settled tail.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TailStats {
    /// Mean (m).
    pub mean: f64,
    /// Minimum (m).
    pub min: f64,
    /// Maximum (m).
    pub max: f64,
}

impl TailStats {
    fn of(values: impl Iterator<Item = f64>) -> TailStats {
        let (mut n, mut sum, mut min, mut max) = (0usize, 0.0, f64::INFINITY, f64::NEG_INFINITY);
        for v in values {
            n += 1;
            sum += v;
            min = min.min(v);
            max = max.max(v);
        }
        TailStats {
            mean: sum / n.max(1) as f64,
            min,
            max,
        }
    }

    /// `max − min` (m).
    pub fn spread(&self) -> f64 {
        self.max - self.min
    }
}

/// The dynamic model's settled state.
#[derive(Debug, Clone, PartialEq)]
pub struct Settled {
    /// Particle offset behind the stage, `s − y_particle`, over the tail.
    pub y: TailStats,
    /// Measured deflection `ζ_z` over the tail.
    pub zeta_z: TailStats,
    /// Friction phase at the end.
    pub phase: &'static str,
    /// Friction-phase changes inside the tail: stick-slip when above zero.
    pub tail_switches: usize,
    /// The particle stuck for the whole tail (the tip never sheared it within the run), so
    /// there is no pushing steady state to report.
    pub stuck: bool,
    /// Periodic or unstable: phase switches in the tail, or a spread of `y` or `ζ_z` above 1 %
    /// of its mean (+1 pm) while the particle moves.
    pub unstable: bool,
    /// Wall time of the push (s).
    pub wall_time: f64,
}

impl Settled {
    /// Settled values of a run: the last `tail` fraction of its samples (at least two).
    pub fn from_run(run: &PushRun, tail: f64) -> Settled {
        let n = run.trace.len();
        let k = ((n as f64 * tail).ceil() as usize).clamp(2.min(n), n);
        let rows = &run.trace[n - k..];
        let y = TailStats::of(rows.iter().map(|r| r.stage_y - r.particle_y));
        let zeta_z = TailStats::of(rows.iter().map(|r| r.zeta_z));
        let tail_switches = rows.windows(2).filter(|w| w[0].phase != w[1].phase).count();
        let stuck = rows.iter().all(|r| r.phase == "stick");
        let wide = |s: &TailStats| s.spread() > 0.01 * s.mean.abs() + 1e-12;
        let unstable = tail_switches > 0 || (!stuck && (wide(&y) || wide(&zeta_z)));
        Settled {
            y,
            zeta_z,
            phase: run.final_phase,
            tail_switches,
            stuck,
            unstable,
            wall_time: run.stats.wall_time,
        }
    }
}

/// One point of a sweep.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepPoint {
    /// Global index in the sweep.
    pub index: usize,
    /// Parameter value (user units).
    pub value: f64,
    /// Eq 18's steady state, or why it has none (e.g. the particle jams); `None` when the
    /// value makes the scene invalid.
    pub eq18: Option<Result<SteadyState, SteadyError>>,
    /// The dynamic model's settled state, or why the point failed (an invalid scene, an
    /// integrator failure, a panic).
    pub dynamic: Result<Settled, String>,
}

/// Eq 18 for a scene's parameters (the inputs `nanopush model` uses).
pub fn eq18(p: &PushParams) -> Result<SteadyState, SteadyError> {
    steady_state(&SteadyInputs::from_params(p), &p.jkr_as)
}

/// Computes point `index` (value `value`) of a sweep of `param` over `base`. Never panics: an
/// invalid value, a failed integration or a panic inside the model is the point's error.
pub fn compute_point(base: &Scene, param: Param, index: usize, value: f64, opts: &PointOptions) -> SweepPoint {
    let scene = match param.apply(base, value) {
        Ok(s) => s,
        Err(e) => {
            return SweepPoint {
                index,
                value,
                eq18: None,
                dynamic: Err(e.to_string()),
            };
        }
    };
    let mut params = scene.push_params();
    let eq18 = eq18(&params);
    if opts.pure_sliding {
        params.dofs.particle_rotation = Dof::Off;
    }
    let run = catch_unwind(AssertUnwindSafe(|| {
        run_push(
            PushModel::new(params),
            opts.method,
            Options::with_rtol(opts.rtol),
            opts.duration,
            opts.sample,
        )
    }));
    let dynamic = match run {
        Ok(Ok(run)) => Ok(Settled::from_run(&run, opts.tail)),
        Ok(Err(e)) => Err(format!("simulating the push: {e}")),
        Err(panic) => Err(format!(
            "the model panicked: {}",
            nanopush_instrument::panic_message(&*panic)
        )),
    };
    SweepPoint {
        index,
        value,
        eq18: Some(eq18),
        dynamic,
    }
}

impl SweepPoint {
    /// Eq 18's state when the scene was valid and Eq 18 has one.
    pub fn eq18_ok(&self) -> Option<&SteadyState> {
        self.eq18.as_ref().and_then(|r| r.as_ref().ok())
    }

    /// Why Eq 18 has no steady state here (`None` when it has one or the scene was invalid).
    pub fn eq18_note(&self) -> Option<String> {
        match &self.eq18 {
            Some(Err(e)) => Some(e.to_string()),
            _ => None,
        }
    }
}

/// The CSV header of a sweep of `param` (one line, with its newline).
pub fn csv_header(param: Param) -> String {
    let unit = param.unit();
    let col = if unit.is_empty() {
        param.name().to_string()
    } else {
        format!("{}_{unit}", param.name())
    };
    format!(
        "index,{col},eq18_y_m,eq18_zeta_z_m,y_m,zeta_z_m,y_spread_m,zeta_z_spread_m,phase,tail_switches,stuck,unstable,eq18_note,error\n"
    )
}

/// Quotes a CSV field when it needs it (RFC 4180).
fn csv_text(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// One CSV row (with its newline). Numbers are printed in full (`{:e}`, shortest round trip),
/// so the same point gives the same bytes in any shard.
pub fn csv_row(p: &SweepPoint) -> String {
    let num = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:e}"));
    let s = p.eq18_ok();
    let d = p.dynamic.as_ref().ok();
    format!(
        "{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
        p.index,
        p.value,
        num(s.map(|s| s.y)),
        num(s.map(|s| s.zeta_z)),
        num(d.map(|d| d.y.mean)),
        num(d.map(|d| d.zeta_z.mean)),
        num(d.map(|d| d.y.spread())),
        num(d.map(|d| d.zeta_z.spread())),
        d.map_or("", |d| d.phase),
        d.map_or(String::new(), |d| d.tail_switches.to_string()),
        d.map_or(String::new(), |d| d.stuck.to_string()),
        d.map_or(String::new(), |d| d.unstable.to_string()),
        csv_text(&p.eq18_note().unwrap_or_default()),
        csv_text(p.dynamic.as_ref().err().map_or("", |e| e.as_str())),
    )
}

#[cfg(test)]
mod tests;
