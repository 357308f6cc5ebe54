//! The way out a refusal names, checked before it is said: each value (a stiffer lever, a larger
//! or smaller gain) is applied to the scene and the plan derived again; the value passes when
//! the plan is given and its dry run was run and passed. The model's figure comes first. While
//! the plan at a value still refuses for want of more (the same refusal, or one that names a
//! figure further the same way), the next value is that figure, and at least one step of 2 past
//! the last; once a value fails otherwise (a lever now too stiff to read the contact), the next
//! lies between it and the last value that was not enough (their geometric mean). Never past
//! what a scene allows or the readout needs, never a value twice. The refusal then names the
//! value that passed, or says that none tried did.

use super::{Advice, Derivation, Refusal, short};
use crate::scene::Scene;

/// The most plans derived to check one refusal's values: each is a whole derivation with its
/// dry runs (0.1-3 s on the lab campaign's scenes).
const MAX_CHECKS: usize = 4;

/// The least step from a value that was not enough, as a factor: the figures of successive
/// refusals may creep (1.645, 4.609, 4.689 N/m), and each plan derived costs seconds.
const MIN_STEP: f64 = 2.0;

/// What the plan at one value says, for the walk: passed, or the code of why not and the figure
/// its refusal names for the same field the same way.
enum Verdict {
    Passes,
    Fails(&'static str, Option<f64>),
}

/// Checks the values `r` names on `scene` and rewrites its field with what was found. The first
/// value named gets the walk, the others their model figure only; once one passes the rest are
/// not checked (and not said: the refusal names a way out that works).
pub(super) fn check(scene: &Scene, id: u32, tolerance: f64, mut r: Refusal) -> Refusal {
    if r.advice.is_empty() {
        return r;
    }
    for a in &mut r.advice {
        a.value = round_toward(a.value, a.direction);
    }
    let code = r.code;
    let mut budget = MAX_CHECKS;
    for (i, a) in r.advice.iter_mut().enumerate() {
        let mut next = Some(a.value).filter(|&v| within(a, v));
        // The furthest value whose plan still wanted more.
        let mut short_of: Option<f64> = None;
        while let Some(v) = next.take() {
            if budget == 0 || a.tried.iter().any(|t| same(t.0, v)) {
                break;
            }
            budget -= 1;
            let Some(applied) = a.applied(scene, v) else { break };
            let (failed, figure) = match verdict(&applied, id, tolerance, a) {
                Verdict::Passes => {
                    a.value = v;
                    a.checked = Some(true);
                    budget = 0;
                    break;
                }
                Verdict::Fails(failed, figure) => (failed, figure),
            };
            a.tried.push((v, failed));
            a.checked = Some(false);
            if i > 0 {
                break;
            }
            let step = v * MIN_STEP.powf(a.direction);
            next = if failed == code || figure.is_some() {
                short_of = Some(v);
                let further = figure.map_or(step, |f| if (f - step) * a.direction > 0.0 { f } else { step });
                Some(further)
            } else if let Some(lo) = short_of {
                Some((lo * v).sqrt())
            } else {
                Some(step)
            }
            .map(|n| round_toward(if within(a, n) { n } else { a.bound }, a.direction));
        }
    }
    r.field = field_text(&r.field, &r.advice);
    r
}

/// The plan on `applied`, for the walk of `a`.
fn verdict(applied: &Scene, id: u32, tolerance: f64, a: &Advice) -> Verdict {
    match Derivation::new(applied, id, tolerance).and_then(|d| d.run()) {
        Ok(plan) if plan.dry_run_passed => Verdict::Passes,
        Ok(_) => Verdict::Fails("no_dry_run", None),
        Err(e) => {
            let figure = e
                .advice
                .iter()
                .find(|b| b.key == a.key && b.direction == a.direction)
                .map(|b| b.estimate)
                .filter(|&f| within(a, f));
            Verdict::Fails(e.code, figure)
        }
    }
}

/// Whether `v` lies within what `a`'s field may take the way it goes.
fn within(a: &Advice, v: f64) -> bool {
    v.is_finite() && v > 0.0 && if a.direction > 0.0 { v <= a.bound } else { v >= a.bound }
}

fn same(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * a.abs().max(b.abs())
}

/// `v` to four significant digits, as the refusal prints it, rounded the way the advice goes (a
/// stiffness the plan needs at least is never rounded below it): the value checked is the value
/// said.
fn round_toward(v: f64, direction: f64) -> f64 {
    if v <= 0.0 || !v.is_finite() {
        return v;
    }
    let scale = 10f64.powi(3 - v.log10().floor() as i32);
    let r = if direction > 0.0 {
        (v * scale - 1e-9).ceil() / scale
    } else {
        (v * scale + 1e-9).floor() / scale
    };
    short(r).parse().unwrap_or(r)
}

/// The field of a refusal once its values are checked: the values that pass (with the model's
/// figure when that did not), then those that did not; the original text when nothing was
/// checked.
fn field_text(original: &str, advice: &[Advice]) -> String {
    let list = |a: &Advice| {
        a.tried
            .iter()
            .map(|(v, code)| format!("{} {} ({code})", short(*v), a.key.unit()))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let passed: Vec<String> = advice
        .iter()
        .filter(|a| a.checked == Some(true))
        .map(|a| {
            let before = if a.tried.is_empty() {
                String::new()
            } else {
                format!("; the plan still refused at {}", list(a))
            };
            format!(
                "{} = {} {} (checked: with it the plan passes its checks and its dry run{before})",
                a.key.said(),
                short(a.value),
                a.key.unit()
            )
        })
        .collect();
    let failed: Vec<String> = advice
        .iter()
        .filter(|a| a.checked == Some(false))
        .map(|a| format!("{} at {}", a.key.said(), list(a)))
        .collect();
    match (passed.is_empty(), failed.is_empty()) {
        (true, true) => original.to_string(),
        (false, true) => passed.join(", or "),
        (false, false) => format!(
            "{} (checked and not enough: {})",
            passed.join(", or "),
            failed.join("; ")
        ),
        (true, false) => format!(
            "{original}; but checked by deriving the plan again, no value tried works: {}",
            failed.join("; ")
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::super::AdviceKey;
    use super::*;

    #[test]
    fn values_round_the_way_the_advice_goes() {
        assert_eq!(round_toward(0.117_83, 1.0), 0.1179);
        assert_eq!(round_toward(0.117_83, -1.0), 0.1178);
        assert_eq!(round_toward(4.326, 1.0), 4.326, "a value already at four digits stays");
        assert_eq!(round_toward(6.514_040_673_7, 1.0), 6.515);
        let scene = Scene::default_scene();
        let smaller = Advice::new(AdviceKey::Gain, 0.5, -1.0, 0.2);
        let applied = smaller.applied(&scene, 0.25).expect("a valid scene");
        assert_eq!(
            applied.file.sensor.gain_v_per_nm,
            0.25f64.copysign(scene.file.sensor.gain_v_per_nm),
            "the gain keeps its sign"
        );
        assert!(!within(&smaller, 0.1) && within(&smaller, 0.3));
    }

    #[test]
    fn the_field_names_the_value_that_passed_and_what_did_not() {
        let mut k = Advice::new(AdviceKey::Stiffness, 4.0, 1.0, 100.0);
        k.tried.push((4.0, "dry_run"));
        k.value = 16.0;
        k.checked = Some(true);
        let mut g = Advice::new(AdviceKey::Gain, 0.1, -1.0, 0.01);
        g.tried.push((0.1, "unreadable"));
        g.checked = Some(false);
        let text = field_text("orig", &[k.clone(), g.clone()]);
        assert_eq!(
            text,
            "cantilever.stiffness_n_per_m = 16 N/m (checked: with it the plan passes its checks and its dry run; the plan still refused at 4 N/m (dry_run)) (checked and not enough: |sensor.gain_v_per_nm| at 0.1 V/nm (unreadable))"
        );
        let none = field_text("orig", &[g]);
        assert!(none.starts_with("orig; but checked"), "{none}");
    }
}
