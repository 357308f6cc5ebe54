//! The strategy's settings and one push's task, as the operator and the scene give them.

use crate::control::estimator::ContactSide;

/// How the push closes its loops (Sec 3).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Control {
    /// xy-position control: stop when the Eq 19 estimate reaches the distance.
    Xy,
    /// z-position control: hold the deflection by moving the tip height; stop on stage travel.
    Z,
    /// Both.
    Xyz,
}

/// The strategy's settings, SI.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StrategyParams {
    /// Control tick (s).
    pub tick: f64,
    /// Tip height above the (unknown) substrate to retract to (m): the start height.
    pub start_height: f64,
    /// z approach and retract speed (m/s).
    pub approach_speed: f64,
    /// Speed of travel moves (m/s).
    pub travel_speed: f64,
    /// Reading change that means the substrate was touched (V).
    pub substrate_threshold: f64,
    /// Contact-search step `Δ` (m).
    pub step: f64,
    /// Ticks of dwell after each step.
    pub dwell_ticks: u32,
    /// Push and contact-search speed `V` (m/s).
    pub speed: f64,
    /// Reading at zero deflection (V).
    pub baseline: f64,
    /// +1 when a push (ζ_z > 0) raises the reading, −1 when it lowers it (the gain's sign).
    pub polarity: f64,
    /// `ζ_set` (V).
    pub set_point: f64,
    /// Safety limit (V).
    pub safety_limit: f64,
    /// The readout's full scale (V): a reading at `±full_scale` is saturated, the force unknown.
    pub full_scale: f64,
    /// Distance from the baseline under which a pushed particle counts as lost (V).
    pub lost_threshold: f64,
    /// Readout noise RMS (V), for margins.
    pub noise: f64,
    /// Longest contact search (m).
    pub search_range: f64,
    /// Longest any phase may take (s).
    pub timeout: f64,
    /// Loop closure.
    pub control: Control,
    /// z-loop gain (m of height per V of error, per tick).
    pub z_gain: f64,
    /// The rise above the detected substrate within which a reading saturated on the pull side
    /// is ridden out, and by which the tip must have let go of the substrate (m):
    /// [`super::pull_off::pull_off_rise`].
    pub pull_off_rise: f64,
    /// The side of the baseline the contact is read on: the side of the set point.
    pub contact_side: ContactSide,
    /// Whether the tip follows the substrate's slope ([`PushTask::slope`]) through the contact
    /// search and the push (`strategy.follow_slope`).
    pub follow_slope: bool,
}

impl StrategyParams {
    /// The reading as a deflection signal (V): positive on the push's side of the baseline.
    pub fn signal(&self, volts: f64) -> f64 {
        (volts - self.baseline) * self.polarity
    }

    /// The reading as a contact signal (V): the distance from the baseline toward the side the
    /// contact is read on ([`ContactSide`]); the push-side signal on the push side.
    pub fn contact_signal(&self, volts: f64) -> f64 {
        self.signal(volts) * self.contact_side.sign()
    }
}

/// One push, as the operator asks for it, with what the controller knows of the particle (from
/// a scan: its estimated centre and radius).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PushTask {
    /// Estimated particle centre (m).
    pub particle: (f64, f64),
    /// Estimated particle radius (m).
    pub radius: f64,
    /// Unit push direction in the plane.
    pub direction: (f64, f64),
    /// Distance to push (m).
    pub distance: f64,
    /// Contact angle to aim for, `β` (rad).
    pub beta: f64,
    /// Tip radius (m).
    pub tip_radius: f64,
    /// Distance behind the contact point where the search starts (m).
    pub approach_distance: f64,
    /// A brief stop during the push (Fig 15: "a short stop interval"): at this push travel
    /// (m), for this many ticks.
    pub pause: Option<(f64, u32)>,
    /// How far above the true substrate auto-parking detects it (m): the snap-in (and the tick
    /// the reading takes to pass the threshold) stops the approach early, by up to a few nm
    /// ([`crate::control::strategy::runner::detection_offset`]). The parking height makes up for it.
    pub detect_offset: f64,
    /// The farthest the particle may be pushed (m, along `direction`) and still lie on the
    /// stage whole ([`crate::control::route::travel_on_stage`]): the push stops there even when
    /// the retraction's drag asks for more, and the particle then ends short (the move is judged
    /// by the scan after it).
    pub max_travel: f64,
    /// The substrate's slope `(∂z/∂x, ∂z/∂y)` the scan before the push measured: the height the
    /// tip follows along the push when [`StrategyParams::follow_slope`] is set.
    pub slope: (f64, f64),
}

impl PushTask {
    /// Horizontal distance between the tip's and the particle's centres at contact,
    /// `(Rₐ + Rₜ) cos β` (m).
    pub fn contact_reach(&self) -> f64 {
        (self.radius + self.tip_radius) * self.beta.cos()
    }

    /// Tip apex height above the substrate that puts the contact at `β`:
    /// `h = Rₐ − Rₜ + (Rₐ + Rₜ) sin β` (m).
    pub fn parking_height(&self) -> f64 {
        self.radius - self.tip_radius + (self.radius + self.tip_radius) * self.beta.sin()
    }

    /// The stage's rise from the detected substrate to the parking height (m): the parking
    /// height less the detection offset.
    pub fn parking_rise(&self) -> f64 {
        self.parking_height() - self.detect_offset
    }

    /// Where the contact search starts (xy, m).
    pub fn search_start(&self) -> (f64, f64) {
        let back = self.contact_reach() + self.approach_distance;
        (
            self.particle.0 - self.direction.0 * back,
            self.particle.1 - self.direction.1 * back,
        )
    }
}
