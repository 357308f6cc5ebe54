//! Eq 17 assembled a second way, as the free-body diagrams of Sec 2.5 draw it, and held against
//! [`PushModel`]'s right-hand side and probe at generic states in every mode.
//!
//! The per-equation pieces (JKR load, Eq 1-4 long-range forces, Eq 10 stiffness, Eq 13 stage
//! constants) are the library's, each tested against its own references; what this checks is
//! the assembly the model's `eval` does in scalar, generic-number code: the geometry (rotation of
//! the lever by `α`, line of centres, contact coordinates and their rates), which force acts on
//! which body with which sign, the friction laws of each mode, the stage's load, and how each
//! row enters `M x' = f` (dynamic: `[rate, force/mass]`; quasi-static: `force/scale`). Written
//! with nalgebra vectors and matrices, the rotation as a matrix and Newton's third law as a
//! negation, so a slip of sign or factor in either version shows as a mismatch.
//!
//! Tests of settled states and signs miss most slips in `eval`: this compares every row and
//! probe field to 1e-9.

use super::*;
use crate::scene::{DEFAULT_SCENE, Scene};
use nalgebra::{Matrix2, Vector2};

fn model(physics: &str) -> PushModel {
    let start = DEFAULT_SCENE.find("[physics]").unwrap();
    let text = format!("{}[physics]\n{physics}\n", &DEFAULT_SCENE[..start]);
    PushModel::new(Scene::parse("test", &text).unwrap().push_params())
}

fn physics(dof: &str, stage: &str) -> String {
    format!(
        "van_der_waals = true\ncapillary = true\nelectrostatic = true\nparticle_y = \"{dof}\"\nparticle_z = \"{dof}\"\nparticle_rotation = \"{dof}\"\ncantilever = \"{dof}\"\nstage = \"{stage}\"\n"
    )
}

/// A drive with every term nonzero (a segment that started at `t₀ ≠ 0`, moving in y and z).
fn drive() -> Drive {
    Drive {
        t0: 0.4e-4,
        y0: 7e-9,
        vy: 1.3e-6,
        z0: -0.3e-9,
        vz: 0.8e-6,
    }
}

/// A generic state: every coordinate off its initial value, every rate nonzero.
fn generic(m: &PushModel) -> Vec<f64> {
    let l = m.layout;
    let mut x = m.initial_state()[..m.len()].to_vec();
    let mut set = |slot: Option<crate::physics::pushing::layout::Slot>, pos: f64, vel: f64| {
        if let Some(s) = slot {
            x[s.pos] += pos;
            if let Some(v) = s.vel {
                x[v] = vel;
            }
        }
    };
    set(l.stage, 7.6e-9, 0.9e-6);
    set(Some(l.zeta_y), 0.21e-9, -3.1e-6);
    set(Some(l.zeta_z), -1.7e-9, 2.3e-6);
    set(Some(l.particle_y), 0.35e-9, 1.9e-6);
    set(l.particle_z, -0.04e-9, -0.7e-6);
    set(l.rotation, 2.1e-4, 3.3);
    x
}

/// What the reference finds at one state: the rows of `f` and the probe.
struct Reference {
    f: Vec<f64>,
    probe: Probe<f64>,
}

/// Eq 17 from the free-body diagrams.
fn reference(m: &PushModel, t: f64, x: &[f64], mode: &Mode) -> Reference {
    let p = &m.p;
    let l = m.layout;
    let a0 = p.interactions.a0;
    let get = |slot: Option<crate::physics::pushing::layout::Slot>, frozen: f64| -> (f64, f64) {
        match slot {
            Some(s) => (x[s.pos], s.vel.map_or(0.0, |v| x[v])),
            None => (frozen, 0.0),
        }
    };
    // The base: the stage's travel along y (Eq 13, or the commanded y_ref(t) of an ideal stage)
    // and the commanded height z(t), about the base's starting point.
    let y_ref = m.drive.y0 + m.drive.vy * (t - m.drive.t0);
    let (s, s_dot) = match l.stage {
        Some(_) => get(l.stage, 0.0),
        None => (y_ref, m.drive.vy),
    };
    let height = m.drive.z0 + m.drive.vz * (t - m.drive.t0);
    let base = Vector2::new(m.base.0 + s, m.base.1 + height);
    let base_v = Vector2::new(s_dot, m.drive.vz);
    // The lever's axes in (y, z): y' = (cos α, −sin α), z' = (sin α, cos α), as the columns of R.
    let alpha = p.cantilever.tilt;
    let r = Matrix2::new(alpha.cos(), alpha.sin(), -alpha.sin(), alpha.cos());
    let (zeta_y, zeta_y_d) = get(Some(l.zeta_y), 0.0);
    let (zeta_z, zeta_z_d) = get(Some(l.zeta_z), 0.0);
    let zeta = Vector2::new(zeta_y, zeta_z);
    let zeta_d = Vector2::new(zeta_y_d, zeta_z_d);
    let tip = base + r * zeta;
    let tip_v = base_v + r * zeta_d;
    // The particle: centre (y, Rₐ + a₀ + z), rotation θ.
    let (y, y_d) = get(Some(l.particle_y), 0.0);
    let (z, z_d) = get(l.particle_z, m.frozen_particle_z());
    let (theta, omega) = get(l.rotation, 0.0);
    let centre = Vector2::new(y, p.r_a + a0 + z);
    let centre_v = Vector2::new(y_d, z_d);

    // The tip-particle contact: line of centres n (tip → particle), its normal t = n rotated by
    // +90°, the gap, and the contact coordinate ξ = (Rₜ + Rₐ)φ + Rₐθ with φ the angle of n.
    let d = centre - tip;
    let dist = d.norm();
    let n = d / dist;
    let tangent = Vector2::new(-n.y, n.x);
    let gap = dist - (p.r_t + p.r_a);
    let rel_v = centre_v - tip_v;
    let gap_d = n.dot(&rel_v);
    let phi_d = tangent.dot(&rel_v) / dist;
    let xi = (p.r_t + p.r_a) * n.y.atan2(n.x) + p.r_a * theta;
    let xi_d = (p.r_t + p.r_a) * phi_d + p.r_a * omega;
    let elastic_ta = if mode.tip_contact {
        p.jkr_ta.load_from_indentation(a0 - gap).unwrap_or(0.0)
    } else {
        0.0
    };
    let normal_ta = elastic_ta + p.interactions.tip_particle_force(gap, mode.meniscus)
        - if mode.tip_contact { p.b_ta * gap_d } else { 0.0 };
    // Eq 7's load: the elastic load less the JKR pull-off (the long-range part of F_l and of A_ta
    // cancel), never negative.
    let load_ta = if mode.tip_contact {
        (elastic_ta - p.jkr_ta.pull_off_load()).max(0.0)
    } else {
        0.0
    };
    let friction_ta = match (mode.tip_contact, mode.tip) {
        (false, _) => 0.0,
        (true, Tangential::Stick { anchor }) => -p.k_ta_t * (xi - anchor) - p.b_ta * xi_d,
        (true, Tangential::Slip { direction }) => -direction * p.mu_ta_k * load_ta,
    };
    // The tip's force on the particle: the normal force along n, and the friction, which acts
    // along ξ: a virtual displacement δp of the particle moves ξ by (Rₜ+Rₐ)/dist · t·δp.
    let on_particle = n * normal_ta + tangent * (friction_ta * (p.r_t + p.r_a) / dist);

    // The particle-substrate contact (Eq 6): the load is the tip's downward push plus the
    // adhesion; the contact point moves with y − Rₐθ.
    let load_as = (p.adhesion_as() - on_particle.y).max(0.0);
    let contact_as = y - p.r_a * theta;
    let slip_rate_as = y_d - p.r_a * omega;
    let friction_as = match mode.substrate {
        Tangential::Stick { anchor } => -p.k_as_t * (contact_as - anchor) - p.b_as * slip_rate_as,
        Tangential::Slip { direction } => -direction * p.mu_as_k * load_as,
    };
    let normal_as = p.jkr_as.load_from_indentation(-z).unwrap_or(0.0) + p.interactions.particle_substrate_force(a0 + z);

    // Eq 13: the stage is a second-order system driven towards y_ref and loaded by the friction
    // the substrate carries (−f_as on the substrate, whose frame is the stage's).
    let stage_accel = if l.stage.is_some() {
        p.stage.acceleration(s, s_dot, y_ref, -friction_as)
    } else {
        0.0
    };

    // The cantilever: the tip feels −(force on the particle), resolved on the lever's axes
    // (Rᵀ), against the stiffness K = C⁻¹ (Eq 10) and the lever's damping.
    let on_tip = -on_particle;
    let k = p.cantilever.stiffness_yz();
    let dynamic_lever = l.zeta_y.vel.is_some();
    let lever_damping = if dynamic_lever { p.cantilever.damping() } else { 0.0 };
    let lever = r.transpose() * on_tip - k * zeta - zeta_d * lever_damping;

    // The particle's three equations (Eq 17 lines 3-5), in the moving frame of the substrate.
    let particle_y = on_particle.x + friction_as + p.m_a * stage_accel;
    let particle_z_damping = if l.particle_z.is_some_and(|s| s.vel.is_some()) {
        p.b_as * z_d
    } else {
        0.0
    };
    let particle_z = normal_as + on_particle.y - particle_z_damping;
    let torque = p.r_a * (friction_ta - friction_as);

    // Rows: dynamic DOFs as [position' = rate, rate' = force/mass], quasi-static ones as
    // force/scale = 0 (a zero-mass row).
    let mut f = vec![f64::NAN; m.len()];
    let mut row =
        |slot: crate::physics::pushing::layout::Slot, force: f64, mass: f64, scale: f64, rate: f64| match slot.vel {
            Some(v) => {
                f[slot.pos] = rate;
                f[v] = force / mass;
            }
            None => f[slot.pos] = force / scale,
        };
    let m_c = p.cantilever.effective_mass();
    row(l.zeta_y, lever.x, m_c, p.cantilever.k_c, zeta_y_d);
    row(l.zeta_z, lever.y, m_c, p.cantilever.k_c, zeta_z_d);
    row(l.particle_y, particle_y, p.m_a, p.k_as_t, y_d);
    if let Some(sl) = l.particle_z {
        row(sl, particle_z, p.m_a, p.k_as_t, z_d);
    }
    if let Some(sl) = l.rotation {
        row(sl, torque, 0.4 * p.m_a * p.r_a * p.r_a, p.k_as_t * p.r_a * p.r_a, omega);
    }
    if let Some(st) = l.stage {
        f[st.pos] = s_dot;
        f[st.vel.unwrap()] = stage_accel;
    }
    Reference {
        f,
        probe: Probe {
            gap,
            normal_ta,
            friction_ta,
            load_ta,
            friction_as,
            load_as,
            contact_as,
            contact_ta: xi,
            slip_rate_as,
            slip_rate_ta: xi_d,
            zeta_z,
            zeta_y,
            stage: s,
            stage_accel,
        },
    }
}

/// Every mode the hybrid model has: stick, slip either way, roll, no meniscus, and the tip off
/// the particle.
fn every_mode(m: &PushModel, x: &[f64]) -> Vec<(&'static str, Mode)> {
    let stick = m.initial_mode();
    // Anchors away from the state so that the sticking springs carry a force.
    let pr = m.probe(1e-4, x, &stick);
    let stick = Mode {
        substrate: Tangential::Stick {
            anchor: pr.contact_as - 0.13e-9,
        },
        tip: Tangential::Stick {
            anchor: pr.contact_ta + 0.07e-9,
        },
        ..stick
    };
    vec![
        ("stick", stick),
        (
            "slip forward",
            Mode {
                substrate: Tangential::Slip { direction: 1.0 },
                ..stick
            },
        ),
        (
            "slip back, tip slipping",
            Mode {
                substrate: Tangential::Slip { direction: -1.0 },
                tip: Tangential::Slip { direction: 1.0 },
                ..stick
            },
        ),
        (
            "roll",
            Mode {
                tip: Tangential::Slip { direction: -1.0 },
                ..stick
            },
        ),
        (
            "dry",
            Mode {
                meniscus: Meniscus::Absent,
                ..stick
            },
        ),
        (
            "apart",
            Mode {
                tip_contact: false,
                ..stick
            },
        ),
    ]
}

fn compare(label: &str, m: &PushModel, t: f64, x: &[f64], mode: &Mode) {
    let want = reference(m, t, x, mode);
    let mut f = vec![0.0; m.len()];
    m.rhs(t, x, mode, &mut f);
    let names = m.layout.names();
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * a.abs().max(b.abs()) + 1e-30;
    for i in 0..m.len() {
        assert!(
            close(f[i], want.f[i]),
            "{label}: row {} is {:e}, the free-body diagrams give {:e}",
            names[i],
            f[i],
            want.f[i]
        );
    }
    let got = m.probe(t, x, mode);
    assert_eq!(
        m.measured_deflection(x),
        want.probe.zeta_z,
        "{label}: the measured deflection is ζ_z'"
    );
    let fields = |p: &Probe<f64>| {
        [
            ("gap", p.gap),
            ("normal_ta", p.normal_ta),
            ("friction_ta", p.friction_ta),
            ("load_ta", p.load_ta),
            ("friction_as", p.friction_as),
            ("load_as", p.load_as),
            ("contact_as", p.contact_as),
            ("contact_ta", p.contact_ta),
            ("slip_rate_as", p.slip_rate_as),
            ("slip_rate_ta", p.slip_rate_ta),
            ("zeta_z", p.zeta_z),
            ("zeta_y", p.zeta_y),
            ("stage", p.stage),
            ("stage_accel", p.stage_accel),
        ]
    };
    for ((name, a), (_, b)) in fields(&got).into_iter().zip(fields(&want.probe)) {
        assert!(
            close(a, b),
            "{label}: probe {name} is {a:e}, the free-body diagrams give {b:e}"
        );
    }
}

/// Every DOF dynamic, the stage following Eq 13: all twelve rows in all six modes.
#[test]
fn eq17_rows_equal_the_free_body_diagrams_with_every_dof_dynamic() {
    let mut m = model(&physics("dynamic", "dynamic"));
    // The stage 1 µm behind its command, so that it accelerates (2.5 m/s²) and the particle
    // feels the frame's fictitious force (−mₐs̈, 1e-14 N: small, but a row's sign all the same).
    m.drive = Drive { y0: 1e-6, ..drive() };
    assert_eq!(m.len(), 12);
    let x = generic(&m);
    for (label, mode) in every_mode(&m, &x) {
        compare(label, &m, 1e-4, &x, &mode);
    }
    // The particle lifted 0.3 nm off the substrate: the long-range forces at a gap beyond a₀,
    // no substrate contact load.
    let mut lifted = x.clone();
    lifted[m.layout.particle_z.unwrap().pos] = 0.3e-9;
    for (label, mode) in every_mode(&m, &lifted) {
        compare(&format!("{label}, lifted"), &m, 1e-4, &lifted, &mode);
    }
    // JKR contacts (γ_SL = 20 mJ/m²): the pull-off enters the tip's friction load.
    let start = DEFAULT_SCENE.find("[physics]").unwrap();
    let text = format!(
        "{}[physics]\n{}\n",
        &DEFAULT_SCENE[..start],
        physics("dynamic", "dynamic")
    )
    .replace(
        "solid_liquid_energy_mj_per_m2 = 0.0",
        "solid_liquid_energy_mj_per_m2 = 20.0",
    );
    let mut sticky = PushModel::new(Scene::parse("test", &text).unwrap().push_params());
    assert!(sticky.p.jkr_ta.pull_off_load() < 0.0);
    sticky.drive = drive();
    let x = generic(&sticky);
    for (label, mode) in every_mode(&sticky, &x) {
        compare(&format!("{label}, JKR"), &sticky, 1e-4, &x, &mode);
    }
}

/// Every DOF quasi-static under an ideal stage (the default scene's reduction, with its stage
/// ideal): the zero-mass rows are forces over their scales.
#[test]
fn eq17_rows_equal_the_free_body_diagrams_quasi_static() {
    let mut m = model(&physics("quasi_static", "off"));
    m.drive = drive();
    assert_eq!(m.len(), 5);
    assert!(m.layout.stage.is_none());
    let x = generic(&m);
    for (label, mode) in every_mode(&m, &x) {
        compare(label, &m, 1e-4, &x, &mode);
    }
}

/// The default scene's own mix (quasi-static particle and lever, dynamic stage), a dynamic
/// particle on a quasi-static lever, and the particle's z and rotation left out (frozen at the
/// equilibrium indentation, no rolling).
#[test]
fn eq17_rows_equal_the_free_body_diagrams_in_mixed_layouts() {
    let mixed = [
        physics("quasi_static", "dynamic"),
        physics("dynamic", "off").replace("cantilever = \"dynamic\"", "cantilever = \"quasi_static\""),
        physics("dynamic", "dynamic")
            .replace("particle_z = \"dynamic\"", "particle_z = \"off\"")
            .replace("particle_rotation = \"dynamic\"", "particle_rotation = \"off\""),
    ];
    for text in mixed {
        let mut m = model(&text);
        m.drive = drive();
        let x = generic(&m);
        for (label, mode) in every_mode(&m, &x) {
            compare(&format!("{label} ({text:?})"), &m, 1e-4, &x, &mode);
        }
    }
    // Left out, z is frozen where the JKR contact carries the substrate's attraction at contact.
    let frozen = model(&physics("dynamic", "dynamic").replace("particle_z = \"dynamic\"", "particle_z = \"off\""));
    assert_eq!(frozen.layout.particle_z, None);
    let z = frozen.frozen_particle_z();
    let p = &frozen.p;
    let elastic = p.jkr_as.load_from_indentation(-z).unwrap();
    let attraction = -p.interactions.particle_substrate_force(p.interactions.a0);
    assert!(z < -1e-12, "indented into the substrate: {z:e}");
    assert!(
        (elastic - attraction).abs() < 1e-9 * attraction,
        "{elastic:e} vs {attraction:e}"
    );
}
