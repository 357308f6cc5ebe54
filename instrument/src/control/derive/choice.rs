//! What the strategy plan decided: one line per setting, with its reason, and how it is applied
//! to a scene.

use crate::control::estimator::PushPrediction;
use crate::scene::Scene;
use crate::scene::file::StrategyFile;

/// One setting of the strategy: its scene key, its value in the scene file's unit, whether the
/// scene gave it by hand, and why it has this value.
#[derive(Debug, Clone, PartialEq)]
pub struct Choice {
    /// `section.field` of the scene file (`strategy.set_point_v`), or `local_scan.*` for the
    /// local scan and `pull_off.*` for the rise that lets go of the substrate, which the scene
    /// does not set.
    pub key: &'static str,
    /// The value, in the unit the key names; a switch ([`SWITCHES`]) is 1 on, 0 off.
    pub value: f64,
    /// Given by the scene (it wins over the derived value).
    pub hand_set: bool,
    /// Why, in one line.
    pub why: String,
}

/// The settings that are on or off (`true` or `false` in the scene file).
pub const SWITCHES: [&str; 1] = ["strategy.follow_slope"];

/// Value `value` of setting `key` as the scene file writes it: a switch `true` or `false`, a
/// number with four significant digits.
pub(super) fn value_text(key: &str, value: f64) -> String {
    if SWITCHES.contains(&key) {
        (value != 0.0).to_string()
    } else {
        short(value)
    }
}

impl Choice {
    /// The value as the scene file writes it.
    pub fn value_text(&self) -> String {
        value_text(self.key, self.value)
    }
}

impl std::fmt::Display for Choice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let source = if self.hand_set { "hand-set" } else { "derived" };
        write!(f, "{} = {} ({source}): {}", self.key, self.value_text(), self.why)
    }
}

/// A value with four significant digits, without trailing zeros.
pub fn short(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return v.to_string();
    }
    let digits = (3 - v.abs().log10().floor() as i32).clamp(0, 12) as usize;
    let s = format!("{v:.digits$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// The strategy for pushing one particle of a scene, derived from the scene's model.
#[derive(Debug, Clone, PartialEq)]
pub struct DerivedStrategy {
    /// The particle (id).
    pub particle: u32,
    /// How close to the target the particle must end for `ok` (m).
    pub tolerance: f64,
    /// Every setting with its reason, in the order the strategy uses them.
    pub choices: Vec<Choice>,
    /// Hand-set values that cannot work as they are, and risks the plan sees.
    pub warnings: Vec<String>,
    /// The resolved `[strategy]`.
    pub strategy: StrategyFile,
    /// The resolved contact angle β (degrees).
    pub contact_angle_deg: f64,
    /// The resolved stage speed V (µm/s).
    pub speed_um_per_s: f64,
    /// The local scan's side (m) and pixels.
    pub local_scan: (f64, usize),
    /// The model's prediction at the chosen β and V (retraction lifted to the release).
    pub prediction: PushPrediction,
    /// What the plan tried before this strategy and why each was not taken, a line each: the
    /// angles that failed the model's checks, and those whose dry run failed.
    pub tried: Vec<String>,
    /// The longest push was cut short because a dry run of a longer one lost the particle.
    pub shortened: bool,
    /// The plan passed its dry run: one was run, and it did not fail (a plan too slow to
    /// dry-run, or with no leg on the stage, is given without one; a hand-set contact angle is
    /// planned with a warning even when its dry run fails).
    pub dry_run_passed: bool,
}

impl DerivedStrategy {
    /// Writes the resolved settings into the scene (hand-set ones are unchanged by
    /// construction).
    pub fn apply(&self, scene: &mut Scene) {
        scene.file.strategy = self.strategy.clone();
        scene.file.push.contact_angle_deg = self.contact_angle_deg;
        scene.file.push.speed_um_per_s = self.speed_um_per_s;
    }

    /// Whether the tip follows the substrate's slope, in words.
    pub(super) fn height(&self) -> &'static str {
        if self.strategy.follow_slope {
            "following the substrate's slope"
        } else {
            "at one height"
        }
    }

    /// The strategy in one line: the contact angle, the side the contact is read on, the loop
    /// closure, the speed and the longest push, and why this one.
    pub fn summary(&self) -> String {
        let hand = |key: &str| self.choices.iter().any(|c| c.key == key && c.hand_set);
        let control = self.strategy.control.name();
        let max_push = self.strategy.max_push_um;
        let shorter = self.shortened;
        let why = if hand("push.contact_angle_deg") {
            "the scene's own contact angle".to_string()
        } else if self.tried.is_empty() {
            "the first angle tried, and it passes every check and its dry run".to_string()
        } else {
            format!(
                "the first angle that passes every check and its dry run, after {} tried before it",
                self.tried.len()
            )
        };
        // A push whose particle rolls on in front of the tip with no load has no lost test.
        let side = self.prediction.side.name();
        let reading = if self.strategy.lost_threshold_mv > 0.0 {
            format!("read on the {side} side")
        } else if hand("strategy.lost_threshold_mv") {
            format!("read on the {side} side until t*, then no lost-particle test (hand-set)")
        } else {
            format!(
                "read on the {side} side until t*, then no lost-particle test (the particle rolls on in front of the tip)"
            )
        };
        let height = self.height();
        format!(
            "β = {}°, {reading}, {control} control, {height}, {} µm/s, pushes of at most {} µm{}: {why}",
            short(self.contact_angle_deg),
            short(self.speed_um_per_s),
            short(max_push),
            if shorter {
                " (a longer push lost the particle in the dry run)"
            } else {
                ""
            },
        )
    }

    /// The plan in words: a line per setting, then the warnings.
    pub fn explain(&self) -> String {
        let mut s = String::new();
        for c in &self.choices {
            s.push_str(&format!("  {c}\n"));
        }
        for w in &self.warnings {
            s.push_str(&format!("  warning: {w}\n"));
        }
        s
    }
}

/// Why no strategy can push the particle: what fails, and the scene field to change.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("no strategy can push particle {particle}: {reason}; change {field}")]
pub struct Refusal {
    /// The particle (id).
    pub particle: u32,
    /// A short code for tables: `geometry`, `unreadable`, `no_resistance`, `deflection_limit`,
    /// `no_separation`, `stuck`, `too_tall`, `adhesion`, `stage`, `escapes`, `model`, `dry_run`.
    pub code: &'static str,
    /// What fails, with the numbers.
    pub reason: String,
    /// The scene field(s) to change, and how.
    pub field: String,
    /// The values named in `field`, each with whether the plan, given it, passes its checks and
    /// its dry run ([`Advice::checked`]).
    pub advice: Vec<Advice>,
}

/// The scene field an [`Advice`] changes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AdviceKey {
    /// `cantilever.stiffness_n_per_m`.
    Stiffness,
    /// `sensor.gain_v_per_nm`, by its magnitude (the sign is the scene's).
    Gain,
}

impl AdviceKey {
    /// The field's key in a scene file.
    pub fn field(self) -> &'static str {
        match self {
            AdviceKey::Stiffness => "cantilever.stiffness_n_per_m",
            AdviceKey::Gain => "sensor.gain_v_per_nm",
        }
    }

    /// The field as a refusal names its value: the gain by its magnitude.
    pub fn said(self) -> &'static str {
        match self {
            AdviceKey::Stiffness => "cantilever.stiffness_n_per_m",
            AdviceKey::Gain => "|sensor.gain_v_per_nm|",
        }
    }

    /// The field's unit.
    pub fn unit(self) -> &'static str {
        match self {
            AdviceKey::Stiffness => "N/m",
            AdviceKey::Gain => "V/nm",
        }
    }

    /// The field's value in `scene`, as the scene file holds it (the gain with its sign).
    pub fn of(self, scene: &Scene) -> f64 {
        match self {
            AdviceKey::Stiffness => scene.file.cantilever.stiffness_n_per_m,
            AdviceKey::Gain => scene.file.sensor.gain_v_per_nm,
        }
    }
}

/// A scene value a refusal names as a way out: a stiffer lever, a larger or smaller gain.
#[derive(Debug, Clone, PartialEq)]
pub struct Advice {
    /// The scene field.
    pub key: AdviceKey,
    /// The value, in the field's unit (for the gain its magnitude: the sign is the scene's).
    pub value: f64,
    /// `+1` when a larger value goes further the right way, `-1` when a smaller one does.
    pub direction: f64,
    /// The furthest value a scene allows, or that still lets the readout work, that way.
    pub bound: f64,
    /// The model's figure before it was checked (equal to `value` when that passed first).
    pub estimate: f64,
    /// `Some(true)`: the plan with this value passes its checks and dry run; `Some(false)`:
    /// no value tried that way did ([`Advice::tried`]); `None`: not checked.
    pub checked: Option<bool>,
    /// Values that were tried and refused, with the refusal's code.
    pub tried: Vec<(f64, &'static str)>,
}

impl Advice {
    /// An unchecked way out: `key` moved to `value` (towards `bound`, `direction` ±1).
    pub fn new(key: AdviceKey, value: f64, direction: f64, bound: f64) -> Advice {
        Advice {
            key,
            value,
            direction,
            bound,
            estimate: value,
            checked: None,
            tried: Vec::new(),
        }
    }

    /// `scene` with this advice applied at `value`, validated as a scene file is (the gain
    /// keeps its sign); `None` when the scene would not be valid.
    pub fn applied(&self, scene: &Scene, value: f64) -> Option<Scene> {
        let mut file = scene.file.clone();
        match self.key {
            AdviceKey::Stiffness => file.cantilever.stiffness_n_per_m = value,
            AdviceKey::Gain => file.sensor.gain_v_per_nm = value.copysign(file.sensor.gain_v_per_nm),
        }
        Scene::from_file_with(&scene.origin, file, scene.hand_set.clone()).ok()
    }
}

#[cfg(test)]
mod tests {
    use super::short;

    #[test]
    fn values_print_with_four_significant_digits() {
        assert_eq!(short(-1.5), "-1.5");
        assert_eq!(short(0.1), "0.1");
        assert_eq!(short(4.2512), "4.251");
        assert_eq!(short(120.0), "120");
        assert_eq!(short(0.012345), "0.01235");
        assert_eq!(short(0.0), "0");
    }
}
