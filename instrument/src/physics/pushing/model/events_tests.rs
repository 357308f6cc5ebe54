//! Tests of the hybrid part of the Eq 17 model: the switching functions against their
//! definitions, the transitions of the tip contact, and the rates of the quasi-static rows
//! against finite differences of balanced states.

use super::*;
use crate::scene::{DEFAULT_SCENE, Scene};

fn model(replace: &[(&str, &str)]) -> PushModel {
    let mut text = DEFAULT_SCENE.to_string();
    for (from, to) in replace {
        assert!(text.contains(from), "{from}");
        text = text.replace(from, to);
    }
    PushModel::new(Scene::parse("test", &text).unwrap().push_params())
}

/// Every DOF dynamic (no algebraic rows).
fn dynamic() -> PushModel {
    model(&[
        ("particle_y = \"quasi_static\"", "particle_y = \"dynamic\""),
        ("particle_z = \"quasi_static\"", "particle_z = \"dynamic\""),
        (
            "particle_rotation = \"quasi_static\"",
            "particle_rotation = \"dynamic\"",
        ),
        ("cantilever = \"quasi_static\"", "cantilever = \"dynamic\""),
    ])
}

/// A state with the tip pressed 0.2 nm into the particle and everything moving.
fn pressed(m: &PushModel) -> Vec<f64> {
    let mut x = m.initial_state()[..m.len()].to_vec();
    x[m.layout.particle_y.pos] -= 0.2e-9;
    x[m.layout.zeta_z.pos] += 0.3e-9;
    let l = m.layout;
    for (k, slot) in [
        l.stage,
        Some(l.zeta_y),
        Some(l.zeta_z),
        Some(l.particle_y),
        l.particle_z,
        l.rotation,
    ]
    .into_iter()
    .flatten()
    .enumerate()
    {
        if let Some(v) = slot.vel {
            x[v] = 1e-6 * (1.0 + k as f64);
        }
    }
    x
}

/// The switching functions are what [`Switching`] defines, in each state of each switch:
/// stick `μˢ·N − |f|`, slip `direction·rate`; meniscus `h − (L_t + a₀)` absent and
/// `L_r + a₀ − h` formed; tip contact `(a₀ − h) − δ_min` in contact, `h − a₀` apart.
#[test]
fn switching_functions_are_their_definitions() {
    let m = dynamic();
    let x = pressed(&m);
    let t = 2e-4;
    let p = &m.p;
    let a0 = p.interactions.a0;
    let cap = p.interactions.tip_particle.capillary.unwrap();
    let stick = m.initial_mode();
    let pr = m.probe(t, &x, &stick);
    assert!(pr.load_as > 0.0 && pr.load_ta > 0.0 && pr.friction_as != 0.0 && pr.friction_ta != 0.0);
    assert!(pr.is_finite());
    assert!(
        !Probe { gap: f64::NAN, ..pr }.is_finite()
            && !Probe {
                stage: f64::INFINITY,
                ..pr
            }
            .is_finite()
    );
    let sw = m.switching(t, &x, &stick);
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * a.abs().max(b.abs()) + 1e-30;
    assert!(
        close(sw.substrate.unwrap(), p.mu_as_s * pr.load_as - pr.friction_as.abs()),
        "{sw:?}"
    );
    assert!(close(sw.tip.unwrap(), p.mu_ta_s * pr.load_ta - pr.friction_ta.abs()));
    assert!(close(sw.meniscus.unwrap(), cap.rupture_gap + a0 - pr.gap));
    assert!(close(
        sw.tip_contact.unwrap(),
        (a0 - pr.gap) - p.jkr_ta.min_indentation()
    ));

    // Slipping both ways: the direction times the contact's rate, from the state's own rate.
    let slip = Mode {
        substrate: Tangential::Slip { direction: -1.0 },
        tip: Tangential::Slip { direction: 1.0 },
        meniscus: Meniscus::Absent,
        ..stick
    };
    let (rate_as, rate_ta) = m.contact_rates(t, &x, &slip).unwrap();
    let pr = m.probe(t, &x, &slip);
    assert!(
        close(rate_as, pr.slip_rate_as) && close(rate_ta, pr.slip_rate_ta),
        "a dynamic state carries its rates"
    );
    let sw = m.switching(t, &x, &slip);
    assert!(
        close(sw.substrate.unwrap(), -rate_as) && close(sw.tip.unwrap(), rate_ta),
        "{sw:?}"
    );
    assert!(close(sw.meniscus.unwrap(), pr.gap - (cap.formation_gap + a0)));

    // Apart: no tip friction, and the contact's function is the gap beyond a₀.
    let apart = Mode {
        tip_contact: false,
        ..stick
    };
    let sw = m.switching(t, &x, &apart);
    assert_eq!(sw.tip, None);
    assert!(close(sw.tip_contact.unwrap(), m.probe(t, &x, &apart).gap - a0));
}

/// Without a possible meniscus (2 % RH: a Kelvin radius below a₀) the push starts dry and
/// there is no meniscus switch.
#[test]
fn a_dry_scene_starts_without_a_meniscus() {
    let m = model(&[("relative_humidity = 0.73", "relative_humidity = 0.02")]);
    let cap =
        m.p.interactions
            .tip_particle
            .capillary
            .expect("capillary forces are included");
    assert!(!cap.possible());
    assert_eq!(m.initial_mode().meniscus, Meniscus::Absent);
    let x = m.initial_state();
    assert_eq!(m.switching(0.0, &x[..m.len()], &m.initial_mode()).meniscus, None);
    assert_eq!(model(&[]).initial_mode().meniscus, Meniscus::Formed);
    assert!(
        !m.is_empty() && m.len() == 7,
        "stage (2) + lever (2) + particle y, z, θ (quasi-static, 1 each)"
    );
}

/// The tip contact's stick ↔ slip keeps the friction continuous, as the substrate's does
/// (`transitions_keep_the_friction_force_continuous`): it slips against the force it held, and
/// sticks again anchored where its spring gives the kinetic force.
#[test]
fn the_tip_contact_switches_with_its_friction_continuous() {
    let m = dynamic();
    let x = pressed(&m);
    let t = 2e-4;
    let stick = m.initial_mode();
    for shift in [0.05e-9, -0.05e-9] {
        let held = Mode {
            tip: Tangential::Stick {
                anchor: m.probe(t, &x, &stick).contact_ta + shift,
            },
            ..stick
        };
        let f_held = m.probe(t, &x, &held).friction_ta;
        let roll = m.transition(t, &x, &held, SwitchKind::Tip);
        assert_eq!(
            roll.tip,
            Tangential::Slip {
                direction: -f_held.signum()
            },
            "slips against the force it held ({f_held:e} N)"
        );
        let p_slip = m.probe(t, &x, &roll);
        assert!((p_slip.friction_ta - f_held.signum() * m.p.mu_ta_k * p_slip.load_ta).abs() < 1e-12 * p_slip.load_ta);
        let back = m.transition(t, &x, &roll, SwitchKind::Tip);
        assert!(matches!(back.tip, Tangential::Stick { .. }));
        // The spring alone (the damping term rides on the rate, which the anchor does not see).
        let spring = |mode: &Mode| {
            let Tangential::Stick { anchor } = mode.tip else {
                unreachable!()
            };
            -(m.probe(t, &x, mode).contact_ta - anchor) * m.p.k_ta_t
        };
        assert!(
            (spring(&back) - p_slip.friction_ta).abs() < 1e-9 * p_slip.friction_ta.abs(),
            "sticks at the kinetic force: {:e} vs {:e}",
            spring(&back),
            p_slip.friction_ta
        );
    }
    // Touching again, the tip sticks where it touched.
    let apart = Mode {
        tip_contact: false,
        ..stick
    };
    let touch = m.transition(t, &x, &apart, SwitchKind::TipContact);
    assert!(touch.tip_contact);
    assert_eq!(
        touch.tip,
        Tangential::Stick {
            anchor: m.probe(t, &x, &apart).contact_ta
        }
    );
}

/// The rates of the quasi-static rows (`state_rate`: the derivative of the constraint,
/// `J_aa ẋ_a = −(J_ad ẋ_d + ∂f_a/∂t)`) against a central difference of balanced states: the
/// differential states moved along their rates, the algebraic ones balanced again by Newton.
/// The default scene (dynamic stage, quasi-static rest) and a fully quasi-static one.
#[test]
fn quasi_static_rates_are_the_slope_of_the_balanced_states() {
    for m in [
        model(&[]),
        model(&[("stage = \"dynamic\"", "stage = \"off\"")]),
        model(&[("cantilever = \"quasi_static\"", "cantilever = \"dynamic\"")]),
    ] {
        let n = m.len();
        let mode = m.initial_mode();
        let t = 3e-3;
        let mut x = m.initial_state()[..n].to_vec();
        if let Some(st) = m.layout.stage {
            x[st.pos] = 2.5e-9;
            x[st.vel.unwrap()] = 0.8e-6;
        }
        assert!(m.equilibrate(t, &mut x, &mode) < 1e-13);
        let mut rate = vec![0.0; n];
        assert!(m.state_rate(t, &x, &mode, &mut rate));
        let mut f = vec![0.0; n];
        m.rhs(t, &x, &mode, &mut f);
        let dt = 1e-7;
        let shifted = |sign: f64| {
            let mut y = x.clone();
            for i in 0..n {
                if m.mass_diagonal()[i] != 0.0 {
                    y[i] += sign * dt * f[i];
                }
            }
            assert!(m.equilibrate(t + sign * dt, &mut y, &mode) < 1e-13);
            y
        };
        let (after, before) = (shifted(1.0), shifted(-1.0));
        let names = m.layout.names();
        let mut moved = 0;
        for i in 0..n {
            let slope = (after[i] - before[i]) / (2.0 * dt);
            if m.mass_diagonal()[i] == 0.0 {
                moved += usize::from(slope.abs() > 1e-12);
                assert!(
                    (rate[i] - slope).abs() <= 1e-4 * slope.abs() + 1e-12,
                    "{}: state_rate {:e}, balanced states move at {:e}",
                    names[i],
                    rate[i],
                    slope
                );
            } else {
                assert_eq!(rate[i], f[i], "{}: a differential row's rate is f", names[i]);
            }
        }
        assert!(moved >= 2, "the push moves the balanced states");
    }
}

/// With JKR contacts (γ_SL = 20 mJ/m²) the tip contact holds down to a negative indentation
/// `δ_min`, so its switching function `(a₀ − h) − δ_min` is positive at `h = a₀` and reaches
/// zero only at `h = a₀ − δ_min` (beyond a₀, where the JKR branch ends).
#[test]
fn a_jkr_tip_contact_lets_go_beyond_a0() {
    let m = model(&[(
        "solid_liquid_energy_mj_per_m2 = 0.0",
        "solid_liquid_energy_mj_per_m2 = 20.0",
    )]);
    let d_min = m.p.jkr_ta.min_indentation();
    assert!(d_min < -1e-12, "JKR holds at a negative indentation: {d_min}");
    let a0 = m.p.interactions.a0;
    let x = m.initial_state()[..m.len()].to_vec();
    let mode = m.initial_mode();
    assert!(mode.tip_contact);
    let gap = m.probe(0.0, &x, &mode).gap;
    let sw = m.switching(0.0, &x, &mode).tip_contact.unwrap();
    let want = (a0 - gap) - d_min;
    assert!((sw - want).abs() <= 1e-9 * want.abs(), "{sw} vs {want}");
    assert!(sw > -d_min * 0.5, "the function holds the contact past a₀: {sw}");
}
