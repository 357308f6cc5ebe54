//! The way out a refusal names, checked before it is said: each value (a stiffer lever, a larger
//! or smaller gain) is applied to the scene and the plan derived again, dry run included. The
//! model's figure comes first; when the plan still refuses, values further the same way are
//! tried (one and four steps past it, a step being the factor the figure asks for and at least
//! 2; never past what a scene allows or the readout needs). The refusal then names the value that passed, or says that
//! none tried did.

use super::{Advice, Derivation, Refusal, short};
use crate::scene::Scene;

/// The most plans derived to check one refusal's values: each is a whole derivation with its
/// dry runs (0.3-3 s on the lab campaign's scenes).
const MAX_CHECKS: usize = 3;

/// Powers of the ladder's step: the model's figure, one step past it, four steps past it.
const LADDER: [f64; 3] = [0.0, 1.0, 4.0];

/// The least step of the ladder, as a factor: a figure close to the scene's own value still
/// doubles (or halves) from one rung to the next.
const MIN_STEP: f64 = 2.0;

/// Checks the values `r` names on `scene` and rewrites its field with what was found. The first
/// value named gets the whole ladder (restarted from a further figure that a refusal on the way
/// names for the same field), the others their model figure only; once one passes the rest are
/// not checked (and not said: the refusal names a way out that works).
pub(super) fn check(scene: &Scene, id: u32, tolerance: f64, mut r: Refusal) -> Refusal {
    if r.advice.is_empty() {
        return r;
    }
    let mut budget = MAX_CHECKS;
    for (i, a) in r.advice.iter_mut().enumerate() {
        let mut rungs = ladder(now(scene, a), a.estimate, a);
        rungs.truncate(if i == 0 { LADDER.len() } else { 1 });
        let mut next = 0;
        while next < rungs.len() && budget > 0 {
            let v = rungs[next];
            next += 1;
            budget -= 1;
            let result = match a.applied(scene, v) {
                Some(s) => Derivation::new(&s, id, tolerance).and_then(|d| d.run()).map(|_| ()),
                None => break,
            };
            match result {
                Ok(()) => {
                    a.value = v;
                    a.checked = Some(true);
                    budget = 0;
                }
                Err(e) => {
                    a.tried.push((v, e.code));
                    a.checked = Some(false);
                    // The refusal at `v` may name its own figure for the same field (the
                    // adhesion's stiffness, then the deflection limit's): the rest of the
                    // ladder starts from it when it lies further.
                    let further = e
                        .advice
                        .iter()
                        .find(|b| b.key == a.key && b.direction == a.direction)
                        .map(|b| b.estimate)
                        .filter(|&n| (n - v) * a.direction > 0.0);
                    if let Some(n) = further
                        && i == 0
                    {
                        rungs.truncate(next);
                        rungs.extend(ladder(v, n, a));
                    }
                }
            }
        }
    }
    r.field = field_text(&r.field, &r.advice);
    r
}

/// The scene's own value of `a`'s field (the gain's magnitude).
fn now(scene: &Scene, a: &Advice) -> f64 {
    match a.key {
        "cantilever.stiffness_n_per_m" => scene.file.cantilever.stiffness_n_per_m,
        _ => scene.file.sensor.gain_v_per_nm.abs(),
    }
}

/// The values to try for `a`'s field, now at `now`, whose figure is `estimate`: the figure, then
/// one and four steps past it, a step being the factor the figure asks for (at least
/// [`MIN_STEP`]), each within `a.bound`; none when the figure is already past it.
fn ladder(now: f64, estimate: f64, a: &Advice) -> Vec<f64> {
    let within = |v: f64| if a.direction > 0.0 { v <= a.bound } else { v >= a.bound };
    if !within(estimate) {
        return Vec::new();
    }
    // Multiplicative steps: the figures span decades (0.01-500 N/m).
    let step = (estimate / now).powf(a.direction).max(MIN_STEP);
    let mut values: Vec<f64> = Vec::new();
    for m in LADDER {
        let v = round4(if within(estimate * step.powf(m * a.direction)) {
            estimate * step.powf(m * a.direction)
        } else {
            a.bound
        });
        if values.last().is_none_or(|l| (l - v).abs() > 1e-9 * v.abs()) {
            values.push(v);
        }
    }
    values
}

/// Four significant digits, as the refusal prints it: the value checked is the value said.
fn round4(v: f64) -> f64 {
    short(v).parse().unwrap_or(v)
}

/// The field of a refusal once its values are checked: the values that pass (with the model's
/// figure when that did not), then those that did not; the original text when nothing was
/// checked.
fn field_text(original: &str, advice: &[Advice]) -> String {
    let name = |a: &Advice| {
        if a.key == "sensor.gain_v_per_nm" {
            "|sensor.gain_v_per_nm|".to_string()
        } else {
            a.key.to_string()
        }
    };
    let list = |a: &Advice| {
        a.tried
            .iter()
            .map(|(v, code)| format!("{} {} ({code})", short(*v), a.unit()))
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
                name(a),
                short(a.value),
                a.unit()
            )
        })
        .collect();
    let failed: Vec<String> = advice
        .iter()
        .filter(|a| a.checked == Some(false))
        .map(|a| format!("{} at {}", name(a), list(a)))
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
    use super::*;

    #[test]
    fn the_ladder_goes_past_the_figure_and_stops_at_the_bound() {
        let mut scene = Scene::default_scene();
        scene.file.cantilever.stiffness_n_per_m = 1.0;
        let a = Advice::new("cantilever.stiffness_n_per_m", 4.0, 1.0, 50.0);
        assert_eq!(ladder(now(&scene, &a), a.estimate, &a), vec![4.0, 16.0, 50.0]);
        let close = Advice::new("cantilever.stiffness_n_per_m", 1.1, 1.0, 50.0);
        assert_eq!(
            ladder(now(&scene, &close), close.estimate, &close),
            vec![1.1, 2.2, 17.6],
            "at least doubling"
        );
        let far = Advice::new("cantilever.stiffness_n_per_m", 60.0, 1.0, 50.0);
        assert!(
            ladder(now(&scene, &far), far.estimate, &far).is_empty(),
            "a figure past the bound is not tried"
        );
        scene.file.sensor.gain_v_per_nm = -1.0;
        let smaller = Advice::new("sensor.gain_v_per_nm", 0.5, -1.0, 0.2);
        assert_eq!(
            ladder(now(&scene, &smaller), smaller.estimate, &smaller),
            vec![0.5, 0.25, 0.2]
        );
        let applied = smaller.applied(&scene, 0.25).expect("a valid scene");
        assert_eq!(applied.file.sensor.gain_v_per_nm, -0.25, "the gain keeps its sign");
    }

    #[test]
    fn the_field_names_the_value_that_passed_and_what_did_not() {
        let mut k = Advice::new("cantilever.stiffness_n_per_m", 4.0, 1.0, 100.0);
        k.tried.push((4.0, "dry_run"));
        k.value = 16.0;
        k.checked = Some(true);
        let mut g = Advice::new("sensor.gain_v_per_nm", 0.1, -1.0, 0.01);
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
