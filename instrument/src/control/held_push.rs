//! A push on a controller that holds the normal force itself (its own Z feedback): the
//! strategy's phases of Sec 2.1 with the force loop left where it runs fastest.
//!
//! 1. **Withdraw**: the tip away from the surface before any travel.
//! 2. **Travel** to the approach point, `approach_gap` behind the particle's edge on the line of
//!    the push, at the travel speed.
//! 3. **Land**: the controller's Z feedback brings the tip onto the substrate and holds the normal
//!    deflection at the set point; landed when `settle_samples` readings in a row lie within
//!    `land_tolerance` of it.
//! 4. **Push** along the line at the push speed, the tip's centre ending `R + r_tip` behind the
//!    target so that the particle's centre ends on it. The lateral deflection over its value at
//!    landing marks the contact (`lateral_contact`); after a contact, three readings in a row
//!    below half of it mean the particle was lost (the tip passed it), and the push stops. A
//!    normal deflection more than `normal_limit` from the set point stops it too (the tip climbing
//!    the particle, or a crash).
//! 5. **Retract**: withdraw — after the push, and after any error or stop on the way.

use std::sync::atomic::{AtomicBool, Ordering};

use crate::afm::{Microscope, MicroscopeError, Sample};

/// What a held push is asked to do (SI; deflections in V).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeldPush {
    /// The particle's centre where it was located (m).
    pub from: [f64; 2],
    /// Where its centre should end (m).
    pub to: [f64; 2],
    /// Its radius (m).
    pub radius: f64,
    /// The tip's radius (m).
    pub tip_radius: f64,
    /// Gap between the tip and the particle's edge where the tip lands (m).
    pub approach_gap: f64,
    /// Speed of travel with the tip withdrawn (m/s).
    pub travel_speed: f64,
    /// Speed of the push (m/s).
    pub push_speed: f64,
    /// Normal deflection the controller holds (V).
    pub setpoint: f64,
    /// Landed when within this of the set point (V).
    pub land_tolerance: f64,
    /// Readings in a row within the tolerance to call it landed.
    pub settle_samples: u32,
    /// A lateral deflection this far over its landing value is a contact (V).
    pub lateral_contact: f64,
    /// The push stops when the normal deflection leaves the set point by more than this (V).
    pub normal_limit: f64,
    /// Longest the landing may take (s, the backend's clock).
    pub land_timeout: f64,
}

/// A motion may take twice its length at its speed, and this much more (s).
pub const MOTION_SLACK: f64 = 10.0;

/// The phases, in order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HeldPhase {
    /// The tip taken away from the surface.
    Withdraw,
    /// Travel to the approach point.
    Travel,
    /// The controller's feedback lands the tip.
    Land,
    /// The push.
    Push,
    /// The tip withdrawn at the end.
    Retract,
}

impl HeldPhase {
    /// Its name in reports.
    pub fn as_str(self) -> &'static str {
        match self {
            HeldPhase::Withdraw => "withdraw",
            HeldPhase::Travel => "travel",
            HeldPhase::Land => "land",
            HeldPhase::Push => "push",
            HeldPhase::Retract => "retract",
        }
    }
}

/// How the push phase ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HeldOutcome {
    /// The tip reached the end of the push with the particle in contact (or, without a lateral
    /// signal, reached it unwatched).
    Pushed,
    /// The contact was seen, then lost: the particle stayed behind or slipped aside.
    Lost,
    /// The tip reached the end without ever touching the particle.
    NoContact,
    /// The operator stopped it.
    Stopped,
}

impl HeldOutcome {
    /// Its name in reports.
    pub fn as_str(self) -> &'static str {
        match self {
            HeldOutcome::Pushed => "pushed",
            HeldOutcome::Lost => "lost",
            HeldOutcome::NoContact => "no_contact",
            HeldOutcome::Stopped => "stopped",
        }
    }
}

/// What a held push did.
#[derive(Debug, Clone, PartialEq)]
pub struct HeldReport {
    /// Phases entered, in order, with the backend's time at their start (s).
    pub phases: Vec<(HeldPhase, f64)>,
    /// How the push phase ended.
    pub outcome: HeldOutcome,
    /// Where the tip met the particle (m).
    pub contact_at: Option<[f64; 2]>,
    /// Where the contact was lost (m).
    pub lost_at: Option<[f64; 2]>,
    /// Every reading of the push phase.
    pub samples: Vec<Sample>,
    /// Whether the backend reports a lateral deflection (contact watched).
    pub watched: bool,
}

/// Why a held push ended early.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum HeldError {
    /// A setting out of range.
    #[error("{0}")]
    Setting(String),
    /// The backend cannot hold the force itself.
    #[error("{0} does not hold the force with its own Z feedback; push with the strategy instead")]
    NoLocalZ(String),
    /// The backend failed during a phase; the tip was then withdrawn (or the message says it could
    /// not be).
    #[error("{phase}: {cause}{withdrawn}")]
    Backend {
        /// The phase.
        phase: &'static str,
        /// What failed (in the message, not a `source`: printed once).
        cause: MicroscopeError,
        /// What became of the tip: empty, or `; the tip was withdrawn` and the like.
        withdrawn: String,
    },
    /// A safety limit tripped; the tip was withdrawn.
    #[error("{phase}: {what}{withdrawn}")]
    Safety {
        /// The phase.
        phase: &'static str,
        /// What tripped.
        what: String,
        /// What became of the tip.
        withdrawn: String,
    },
}

impl HeldPush {
    fn check(&self) -> Result<(), HeldError> {
        let pos = |name: &str, v: f64| -> Result<(), HeldError> {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(HeldError::Setting(format!("{name} = {v} must be finite and > 0")))
            }
        };
        pos("radius", self.radius)?;
        pos("tip radius", self.tip_radius)?;
        pos("approach gap", self.approach_gap)?;
        pos("travel speed", self.travel_speed)?;
        pos("push speed", self.push_speed)?;
        pos("land tolerance", self.land_tolerance)?;
        pos("lateral contact", self.lateral_contact)?;
        pos("normal limit", self.normal_limit)?;
        pos("land time-out", self.land_timeout)?;
        if !(self.from.iter().chain(&self.to).all(|v| v.is_finite()) && self.setpoint.is_finite()) {
            return Err(HeldError::Setting(
                "the particle, the target and the set point must be finite".into(),
            ));
        }
        let d = (self.to[0] - self.from[0]).hypot(self.to[1] - self.from[1]);
        if d < 1e-10 {
            return Err(HeldError::Setting(format!(
                "the target is {:.3} nm from the particle: nothing to push",
                d * 1e9
            )));
        }
        Ok(())
    }

    /// Unit vector of the push.
    fn direction(&self) -> [f64; 2] {
        let (dx, dy) = (self.to[0] - self.from[0], self.to[1] - self.from[1]);
        let d = dx.hypot(dy);
        [dx / d, dy / d]
    }

    /// Where the tip lands: behind the particle on the line of the push (m).
    pub fn approach_point(&self) -> [f64; 2] {
        let u = self.direction();
        let back = self.radius + self.tip_radius + self.approach_gap;
        [self.from[0] - u[0] * back, self.from[1] - u[1] * back]
    }

    /// Where the tip's centre ends (m).
    pub fn end_point(&self) -> [f64; 2] {
        let u = self.direction();
        let back = self.radius + self.tip_radius;
        [self.to[0] - u[0] * back, self.to[1] - u[1] * back]
    }
}

/// Runs a held push on `m`; `stop` ends the push early (the tip is withdrawn).
pub fn held_push(m: &mut dyn Microscope, p: &HeldPush, stop: &AtomicBool) -> Result<HeldReport, HeldError> {
    p.check()?;
    let caps = m.capabilities();
    if !caps.z_closed_locally {
        return Err(HeldError::NoLocalZ(caps.backend));
    }
    let mut report = HeldReport {
        phases: Vec::new(),
        outcome: HeldOutcome::Pushed,
        contact_at: None,
        lost_at: None,
        samples: Vec::new(),
        watched: false,
    };
    // Nothing is sent for a push that would leave the limits.
    check_limits(m, p)?;
    let result = phases(m, p, stop, &mut report);
    let t = report.samples.last().map_or(0.0, |s| s.t);
    report.phases.push((HeldPhase::Retract, t));
    let retract = m.withdraw();
    // A motion an error or a limit cut short would run on to its end point, withdrawn: stopped.
    let _ = m.stop_move();
    match (result, retract) {
        (Ok(()), Ok(())) => Ok(report),
        (Ok(()), Err(e)) => Err(HeldError::Backend {
            phase: "retract",
            cause: e,
            withdrawn: "; the tip may still be on the surface: withdraw it at the controller".into(),
        }),
        (Err(e), retract) => Err(with_retract(e, retract)),
    }
}

fn with_retract(e: HeldError, retract: Result<(), MicroscopeError>) -> HeldError {
    let withdrawn = match retract {
        Ok(()) => "; the tip was withdrawn".to_string(),
        Err(r) => format!("; the tip could not be withdrawn ({r}): withdraw it at the controller"),
    };
    match e {
        // The backend said what became of the tip after its own failure; the retract after it
        // changes nothing it said.
        HeldError::Backend { phase, cause, .. } if cause.to_string().contains("withdrawn") => HeldError::Backend {
            phase,
            cause,
            withdrawn: String::new(),
        },
        HeldError::Backend { phase, cause, .. } => HeldError::Backend {
            phase,
            cause,
            withdrawn,
        },
        HeldError::Safety { phase, what, .. } => HeldError::Safety { phase, what, withdrawn },
        other => other,
    }
}

fn backend(phase: HeldPhase) -> impl Fn(MicroscopeError) -> HeldError {
    move |cause| HeldError::Backend {
        phase: phase.as_str(),
        cause,
        withdrawn: String::new(),
    }
}

/// A reading, refused when any of its values is not a number: a push is not watched blind.
fn poll(m: &mut dyn Microscope, phase: HeldPhase) -> Result<(Sample, bool), HeldError> {
    let (s, arrived) = m.poll().map_err(backend(phase))?;
    let finite = s.tip[0].is_finite() && s.tip[1].is_finite() && s.normal.is_finite() && s.t.is_finite();
    if !finite || s.lateral.is_some_and(|l| !l.is_finite()) {
        return Err(HeldError::Safety {
            phase: phase.as_str(),
            what: format!(
                "a reading that is not a number (tip ({}, {}) m, normal {} V, lateral {:?} V)",
                s.tip[0], s.tip[1], s.normal, s.lateral
            ),
            withdrawn: String::new(),
        });
    }
    Ok((s, arrived))
}

/// Checks that every point the push will send lies inside the backend's limits, and its speeds
/// under its fastest, before anything is sent.
fn check_limits(m: &mut dyn Microscope, p: &HeldPush) -> Result<(), HeldError> {
    let l = m.limits().map_err(backend(HeldPhase::Withdraw))?;
    let um = |v: [f64; 2]| format!("({:.4}, {:.4}) µm", v[0] * 1e6, v[1] * 1e6);
    for (what, at) in [
        ("the approach point", p.approach_point()),
        ("the tip's end point", p.end_point()),
        ("the target", p.to),
    ] {
        if !l.contains_xy(at[0], at[1]) {
            return Err(HeldError::Setting(format!(
                "{what} {} lies outside the limits, {}; nothing was sent",
                um(at),
                l.xy_text()
            )));
        }
    }
    for (what, v) in [("travel speed", p.travel_speed), ("push speed", p.push_speed)] {
        if v > l.max_speed * (1.0 + 1e-9) {
            return Err(HeldError::Setting(format!(
                "the {what} {:.3} µm/s is over the fastest allowed, {:.3} µm/s; nothing was sent",
                v * 1e6,
                l.max_speed * 1e6
            )));
        }
    }
    Ok(())
}

fn phases(m: &mut dyn Microscope, p: &HeldPush, stop: &AtomicBool, r: &mut HeldReport) -> Result<(), HeldError> {
    // 1. Withdraw.
    r.phases.push((HeldPhase::Withdraw, 0.0));
    m.withdraw().map_err(backend(HeldPhase::Withdraw))?;

    // 2. Travel.
    let a = p.approach_point();
    let (s, _) = poll(m, HeldPhase::Travel)?;
    r.phases.push((HeldPhase::Travel, s.t));
    m.start_move(a[0], a[1], p.travel_speed)
        .map_err(backend(HeldPhase::Travel))?;
    let length = (a[0] - s.tip[0]).hypot(a[1] - s.tip[1]);
    follow(
        m,
        stop,
        HeldPhase::Travel,
        (s.t, 2.0 * length / p.travel_speed + MOTION_SLACK),
        |_| Ok(false),
    )?;
    if stop.load(Ordering::Relaxed) {
        r.outcome = HeldOutcome::Stopped;
        return Ok(());
    }

    // 3. Land.
    let (s, _) = poll(m, HeldPhase::Land)?;
    r.phases.push((HeldPhase::Land, s.t));
    m.hold_force(p.setpoint).map_err(backend(HeldPhase::Land))?;
    let deadline = s.t + p.land_timeout;
    let mut settled = 0;
    let landed = loop {
        if stop.load(Ordering::Relaxed) {
            r.outcome = HeldOutcome::Stopped;
            return Ok(());
        }
        let (s, _) = poll(m, HeldPhase::Land)?;
        settled = if (s.normal - p.setpoint).abs() <= p.land_tolerance {
            settled + 1
        } else {
            0
        };
        if settled >= p.settle_samples {
            break s;
        }
        if s.t > deadline {
            return Err(HeldError::Safety {
                phase: "land",
                what: format!(
                    "the normal deflection did not settle within {} V of the set point {} V in {} s (last {:.4} V)",
                    p.land_tolerance, p.setpoint, p.land_timeout, s.normal
                ),
                withdrawn: String::new(),
            });
        }
    };

    // 4. Push.
    r.phases.push((HeldPhase::Push, landed.t));
    r.watched = landed.lateral.is_some();
    let baseline = landed.lateral.unwrap_or(0.0);
    let e = p.end_point();
    m.start_move(e[0], e[1], p.push_speed)
        .map_err(backend(HeldPhase::Push))?;
    let length = (e[0] - landed.tip[0]).hypot(e[1] - landed.tip[1]);
    let mut below = 0;
    let mut samples = Vec::new();
    let outcome = {
        let contact_at = &mut r.contact_at;
        let lost_at = &mut r.lost_at;
        let budget = 2.0 * length / p.push_speed + MOTION_SLACK;
        follow(m, stop, HeldPhase::Push, (landed.t, budget), |s| {
            samples.push(*s);
            if (s.normal - p.setpoint).abs() > p.normal_limit {
                return Err(HeldError::Safety {
                    phase: "push",
                    what: format!(
                        "the normal deflection {:.4} V left the set point {} V by more than {} V at ({:.4}, {:.4}) µm",
                        s.normal,
                        p.setpoint,
                        p.normal_limit,
                        s.tip[0] * 1e6,
                        s.tip[1] * 1e6
                    ),
                    withdrawn: String::new(),
                });
            }
            let Some(lat) = s.lateral else { return Ok(false) };
            let over = lat - baseline;
            if contact_at.is_none() {
                if over > p.lateral_contact {
                    *contact_at = Some([s.tip[0], s.tip[1]]);
                }
                return Ok(false);
            }
            below = if over < 0.5 * p.lateral_contact { below + 1 } else { 0 };
            if below >= 3 {
                *lost_at = Some([s.tip[0], s.tip[1]]);
                return Ok(true);
            }
            Ok(false)
        })
    };
    r.samples = samples;
    let ended_early = outcome?;
    r.outcome = if stop.load(Ordering::Relaxed) {
        HeldOutcome::Stopped
    } else if ended_early {
        m.stop_move().map_err(backend(HeldPhase::Push))?;
        HeldOutcome::Lost
    } else if r.watched && r.contact_at.is_none() {
        HeldOutcome::NoContact
    } else {
        HeldOutcome::Pushed
    };
    Ok(())
}

/// Polls until the motion arrives, `check` says to end (true), or `stop` is set; fails when the
/// backend's clock passes `budget` (s) after `start` first.
fn follow(
    m: &mut dyn Microscope,
    stop: &AtomicBool,
    phase: HeldPhase,
    (start, budget): (f64, f64),
    mut check: impl FnMut(&Sample) -> Result<bool, HeldError>,
) -> Result<bool, HeldError> {
    loop {
        if stop.load(Ordering::Relaxed) {
            m.stop_move().map_err(backend(phase))?;
            return Ok(true);
        }
        let (s, arrived) = poll(m, phase)?;
        if check(&s)? {
            return Ok(true);
        }
        if arrived {
            return Ok(false);
        }
        if s.t > start + budget {
            m.stop_move().map_err(backend(phase))?;
            return Err(HeldError::Safety {
                phase: phase.as_str(),
                what: format!(
                    "the motion did not arrive within {:.1} s (twice its length at its speed, and {MOTION_SLACK} s); the tip is at ({:.4}, {:.4}) µm",
                    budget,
                    s.tip[0] * 1e6,
                    s.tip[1] * 1e6
                ),
                withdrawn: String::new(),
            });
        }
    }
}

#[cfg(test)]
mod tests;
