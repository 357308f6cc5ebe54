//! The scene's validation: the tables of [`super::fields`] in file order, with the checks that
//! relate several fields between them. The first failure is returned.

use super::fields::{CONTACT, Field, HAPTIC, INSTRUMENT, PARTICLE, SCAN, SENSOR_LEVELS, SENSOR_PERTURBATION};
use super::fields::{SENSOR_READOUT, STRATEGY};
use super::{MAX_PARTICLES, check, first_clash};
use crate::scene::error::SceneError;
use crate::scene::file::{DofFile, SceneFile};
use crate::scene::hand_set::HandSet;

/// Every check of a scene, in file order; the first failure is returned.
pub fn validate(origin: &str, s: &SceneFile, hand_set: &HandSet) -> Result<(), SceneError> {
    let table = |fields: &[Field]| -> Result<(), SceneError> {
        for f in fields {
            check(origin, f.name, (f.value)(s), (f.range)(s))?;
        }
        Ok(())
    };
    table(INSTRUMENT)?;
    particles(origin, s)?;
    table(CONTACT)?;
    pushed_particle(origin, s)?;
    table(SENSOR_LEVELS)?;
    if s.sensor.gain_v_per_nm == 0.0 {
        return Err(SceneError::OutOfRange {
            origin: origin.into(),
            field: "sensor.gain_v_per_nm".into(),
            value: 0.0,
            allowed: "[-10, 10] V/nm, not 0".into(),
        });
    }
    table(SENSOR_READOUT)?;
    table(STRATEGY)?;
    strategy_levels(origin, s, hand_set)?;
    table(SENSOR_PERTURBATION)?;
    table(SCAN)?;
    resolvable(origin, s)?;
    table(HAPTIC)?;
    hamaker_across_water(origin, s)?;
    degrees_of_freedom(origin, s)
}

fn inconsistent(origin: &str, field: impl Into<String>, message: String) -> SceneError {
    SceneError::Inconsistent {
        origin: origin.into(),
        field: field.into(),
        message,
    }
}

/// `[[particles]]`: at least one and at most [`MAX_PARTICLES`], each number in range, no two
/// of one id and none overlapping another.
fn particles(origin: &str, s: &SceneFile) -> Result<(), SceneError> {
    if s.particles.is_empty() {
        return Err(inconsistent(
            origin,
            "particles",
            "the scene needs at least one [[particles]] entry".into(),
        ));
    }
    if s.particles.len() > MAX_PARTICLES {
        return Err(inconsistent(
            origin,
            "particles",
            format!(
                "{} particles; allowed: at most {MAX_PARTICLES} (every scan images each particle at every pixel: 4705 took 11.5 s a push)",
                s.particles.len()
            ),
        ));
    }
    for (i, p) in s.particles.iter().enumerate() {
        for f in PARTICLE {
            check(
                origin,
                &format!("particles[{i}].{}", f.name),
                (f.value)(p),
                (f.range)(s),
            )?;
        }
    }
    if let Some((i, j, same_id)) = first_clash(&s.particles) {
        let (p, q) = (&s.particles[i], &s.particles[j]);
        let field = format!("particles[{i}].{}", if same_id { "id" } else { "x_um" });
        let message = if same_id {
            format!("id {} is already used by particles[{j}]", p.id)
        } else {
            let d_nm = ((p.x_um - q.x_um).powi(2) + (p.y_um - q.y_um).powi(2)).sqrt() * 1e3;
            format!(
                "particle {} overlaps particle {}: centres {d_nm:.1} nm apart, radii sum to {:.1} nm",
                p.id,
                q.id,
                p.radius_nm + q.radius_nm
            )
        };
        return Err(inconsistent(origin, field, message));
    }
    Ok(())
}

/// `push.particle_id` names a particle of the scene.
fn pushed_particle(origin: &str, s: &SceneFile) -> Result<(), SceneError> {
    if s.particles.iter().any(|p| p.id == s.push.particle_id) {
        return Ok(());
    }
    let ids: Vec<String> = s.particles.iter().map(|p| p.id.to_string()).collect();
    Err(inconsistent(
        origin,
        "push.particle_id",
        format!(
            "no particle has id {}; ids in the scene: {}",
            s.push.particle_id,
            ids.join(", ")
        ),
    ))
}

/// The set point the scene gives lies off the baseline, on the side the strategy reads the
/// contact on: the push side (`ζ_z > 0`, the reading moving along the gain's sign) or, for a push
/// that bends the lever the other way, the pull side (`control::estimator::ContactSide`). The
/// safety limit lies beyond it on the same side, and every level the strategy reads within the
/// readout's full scale. Levels the scene does not give are derived by the plan from the sensor
/// and the model (`control::derive`), not checked here.
fn strategy_levels(origin: &str, s: &SceneFile, hand_set: &HandSet) -> Result<(), SceneError> {
    let st = &s.strategy;
    let given = |key: &str| hand_set.contains(key);
    let dir = s.sensor.gain_v_per_nm.signum();
    let base = s.sensor.baseline_v;
    let set = (st.set_point_v - base) * dir;
    if set == 0.0 && given("strategy.set_point_v") {
        return Err(inconsistent(
            origin,
            "strategy.set_point_v",
            format!(
                "{} V is the baseline: the set point must lie off it, on the side the push bends the lever (above it for a push read on the push side with sensor.gain_v_per_nm = {})",
                st.set_point_v, s.sensor.gain_v_per_nm
            ),
        ));
    }
    // Distances from the baseline on the set point's side (the push side for a set point the
    // scene leaves to the plan).
    let contact = if set < 0.0 && given("strategy.set_point_v") {
        -1.0
    } else {
        1.0
    };
    let (set, safety) = (set * contact, (st.safety_limit_v - base) * dir * contact);
    let side = if dir * contact < 0.0 { "below" } else { "above" };
    if safety <= set && (given("strategy.set_point_v") || given("strategy.safety_limit_v")) {
        return Err(inconsistent(
            origin,
            "strategy.safety_limit_v",
            format!(
                "{} V must lie beyond the set point {} V (further {side} the baseline {base} V)",
                st.safety_limit_v, st.set_point_v
            ),
        ));
    }
    // The ADC saturates at its full scale: every level the strategy reads must lie inside it.
    let fs = s.sensor.full_scale_v;
    for (field, v) in [
        ("sensor.baseline_v", base),
        ("strategy.set_point_v", st.set_point_v),
        ("strategy.safety_limit_v", st.safety_limit_v),
    ] {
        if v.abs() >= fs && (field == "sensor.baseline_v" || given(field)) {
            return Err(inconsistent(
                origin,
                field,
                format!(
                    "{v} V is outside the readout's range (-{fs}, {fs}) V (sensor.full_scale_v = {fs}): the ADC saturates there"
                ),
            ));
        }
    }
    Ok(())
}

/// Every particle stands out of a scan: the localization takes a pixel as a particle when it is
/// more than max(6σ, 0.5 nm) above the levelled substrate, σ the image's noise (scan noise and
/// roughness); a particle whose height 2Rₐ is not twice that cannot be found before a push.
/// (The local scan's pixels follow the particle and tip radii, see
/// `control::moves::locate::local_scan_size`, so the pitch never hides it.)
fn resolvable(origin: &str, s: &SceneFile) -> Result<(), SceneError> {
    let sigma = s.scan.noise_rms_nm.hypot(s.substrate.roughness_rms_nm);
    let threshold = (6.0 * sigma).max(0.5);
    for (k, p) in s.particles.iter().enumerate() {
        if 2.0 * p.radius_nm < 2.0 * threshold {
            return Err(inconsistent(
                origin,
                format!("particles[{k}].radius_nm"),
                format!(
                    "{} nm: a scan cannot resolve it: its height 2Rₐ = {} nm is less than twice the localization threshold max(6σ, 0.5 nm) = {threshold:.3} nm, with σ = √(scan.noise_rms_nm² + substrate.roughness_rms_nm²) = {sigma:.3} nm; lower the noise or the roughness, or use a larger particle",
                    p.radius_nm,
                    2.0 * p.radius_nm
                ),
            ));
        }
    }
    Ok(())
}

/// Across the water layer the Hamaker combining rule (Sec 2.2.1) is attractive only when every
/// body's constant exceeds the medium's; the model's van der Waals laws are attractive.
fn hamaker_across_water(origin: &str, s: &SceneFile) -> Result<(), SceneError> {
    if !(s.physics.van_der_waals && s.environment.relative_humidity > 0.0) {
        return Ok(());
    }
    let medium = s.environment.medium_hamaker_zj;
    let mut bodies: Vec<(String, f64)> = vec![
        ("tip.hamaker_zj".into(), s.tip.hamaker_zj),
        ("substrate.hamaker_zj".into(), s.substrate.hamaker_zj),
    ];
    bodies.extend(
        s.particles
            .iter()
            .enumerate()
            .map(|(i, p)| (format!("particles[{i}].hamaker_zj"), p.hamaker_zj)),
    );
    for (field, h) in bodies {
        if h <= medium {
            return Err(SceneError::OutOfRange {
                origin: origin.into(),
                field,
                value: h,
                allowed: format!(
                    "above environment.medium_hamaker_zj = {medium} zJ: at or below it van der Waals across the water layer is repulsive, which the model does not describe"
                ),
            });
        }
    }
    Ok(())
}

/// `[physics]`: each degree of freedom in a mode the model has for it.
fn degrees_of_freedom(origin: &str, s: &SceneFile) -> Result<(), SceneError> {
    use DofFile::*;
    let ph = &s.physics;
    let table: [(&str, DofFile, &[DofFile]); 5] = [
        ("physics.particle_y", ph.particle_y, &[Dynamic, QuasiStatic]),
        ("physics.particle_z", ph.particle_z, &[Dynamic, QuasiStatic, Off]),
        (
            "physics.particle_rotation",
            ph.particle_rotation,
            &[Dynamic, QuasiStatic, Off],
        ),
        ("physics.cantilever", ph.cantilever, &[Dynamic, QuasiStatic]),
        ("physics.stage", ph.stage, &[Dynamic, Off]),
    ];
    for (field, v, allowed) in table {
        if !allowed.contains(&v) {
            let names: Vec<&str> = allowed.iter().map(|d| dof_name(*d)).collect();
            return Err(inconsistent(
                origin,
                field,
                format!("\"{}\" is not allowed here; allowed: {}", dof_name(v), names.join(", ")),
            ));
        }
    }
    Ok(())
}

fn dof_name(d: DofFile) -> &'static str {
    match d {
        DofFile::Dynamic => "dynamic",
        DofFile::QuasiStatic => "quasi_static",
        DofFile::Off => "off",
    }
}
