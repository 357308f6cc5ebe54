//! The derived quantities of a scene (`nanopush model`) and its force curve (`--force-curve`).

use nanopush_proto::model::{ForceCurvePoint, ForceCurveReport, ModelReport, SteadyStateReport};

use nanopush_instrument::physics::force_curve::CurvePoint;
use nanopush_instrument::physics::friction;
use nanopush_instrument::physics::pushing::{PushModel, SteadyInputs, steady_state};
use nanopush_instrument::physics::shearing::StaticPhase;
use nanopush_instrument::scene::Scene;

/// Everything `nanopush model` prints, computed from a validated scene.
pub fn model_report(scene: &Scene) -> ModelReport {
    let p = scene.push_params();
    let c = &p.cantilever;
    let a_as = p.paper_adhesion_as();
    let a_ta = p.paper_adhesion_ta();
    let static_phase = |adhesion| {
        StaticPhase {
            k_y: c.k_y(),
            k_z: c.k_z(),
            alpha: c.tilt,
            mu_s: p.mu_as_s,
            adhesion,
        }
        .shearing_point()
    };
    let fz = friction::feasibility(p.mu_as_s, p.r_a, p.r_t, p.beta, c.k_y(), c.k_z(), c.tilt);
    let model = PushModel::new(p);
    let r1 = p
        .interactions
        .tip_particle
        .capillary
        .map_or(0.0, |cap| cap.kelvin_radius);
    let steady = steady_state(&SteadyInputs::from_params(&p), &p.jkr_as);
    ModelReport {
        schema: "nanopush.model".into(),
        version: nanopush_proto::VERSION,
        scene: scene.file.name.clone(),
        c1: c.c1(),
        c2: c.c2(),
        c3: c.c3(),
        k_y: c.k_y(),
        k_z: c.k_z(),
        k_yz: c.k_yz(),
        m_c: c.effective_mass(),
        b_y: c.damping(),
        k_as: p.k_as_t,
        a_as,
        a_ta,
        a_as_model: p.adhesion_as(),
        a_ta_model: p.adhesion_ta(),
        r_eff: p.r_eff(),
        r1,
        meniscus_formation_gap: 2.0 * r1,
        meniscus_breaking_length: p.jkr_ta.meniscus_breaking_length(p.gamma_l),
        y_star: static_phase(a_as),
        y_star_model: static_phase(p.adhesion_as()),
        mu_lower_bound: fz.lower,
        mu_upper_bound: fz.upper.is_finite().then_some(fz.upper),
        mu_as_static: p.mu_as_s,
        mu_feasible: fz.satisfied,
        no_sticking_to_tip: friction::no_sticking_to_tip(p.r_a, p.r_eff(), p.beta),
        particle_mass: p.m_a,
        contact_period: 2.0 * std::f64::consts::PI * (p.m_a / p.k_as_t).sqrt(),
        cantilever_period: 1.0 / c.f_r,
        stage_period: 1.0 / p.stage.f_y,
        state_dimension: model.len(),
        states: model.layout.names().into_iter().map(String::from).collect(),
        steady_state: steady.as_ref().ok().map(|s| SteadyStateReport {
            normal_ta: s.normal_ta,
            friction_ta: s.friction_ta,
            y: s.y,
            zeta_y: s.zeta_y,
            zeta_z: s.zeta_z,
            beta_tilde: s.beta_tilde,
            z: s.z,
        }),
        steady_state_error: steady.err().map(|e| e.to_string()),
        warnings: scene.warnings.iter().map(|w| w.to_string()).collect(),
    }
}

/// The Fig 3 force curve of the scene's tip on its bare substrate: approach from 3 L_t (at
/// least 10 nm) to a repulsive load of twice the adhesion, and back out until the adhesion has
/// let go (1.5 adhesion/k_c beyond the start).
pub fn force_curve_report(scene: &Scene, steps: usize) -> ForceCurveReport {
    let ts = scene.tip_sample();
    let lt = ts.long_range.capillary.map_or(0.0, |c| c.formation_gap);
    let d_far = (3.0 * lt).max(10e-9);
    // Enough travel into the sample to reach a repulsive load above the adhesion scale.
    let adhesion = ts.adhesion();
    let d_near = -(2.0 * adhesion.max(1e-9) / ts.k_c);
    // Out again far enough for the adhesion to let go: its deflection is adhesion/k_c.
    let d_retract = d_far + 1.5 * adhesion.max(1e-9) / ts.k_c;
    let c = ts.curve(d_far, d_near, d_retract, steps);
    let conv = |p: &CurvePoint| ForceCurvePoint {
        distance: p.distance,
        gap: p.gap,
        deflection: p.deflection,
        force: p.force,
        meniscus: p.meniscus,
        contact: p.contact,
    };
    ForceCurveReport {
        schema: "nanopush.force_curve".into(),
        version: nanopush_proto::VERSION,
        scene: scene.file.name.clone(),
        k_c: ts.k_c,
        tip_radius: ts.r_t,
        snap_in_distance: c.snap_in_distance,
        pull_off_force: c.pull_off_force,
        pull_off_distance: c.pull_off_distance,
        approach: c.approach.iter().map(conv).collect(),
        retraction: c.retraction.iter().map(conv).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// With μ_as exactly at the Eq 16 bound `model` reports the push infeasible, not feasible with
    /// a y* of 1.5·10⁷ m (the warning is checked in the scene's tests).
    #[test]
    fn mu_at_the_eq16_bound_is_reported_infeasible() {
        let s = Scene::default_scene();
        let c = s.cantilever();
        let upper = nanopush_instrument::physics::friction::mu_upper_bound(c.k_y(), c.k_z(), c.tilt);
        let text = nanopush_instrument::scene::DEFAULT_SCENE.replacen(
            "particle_substrate_static = 0.3",
            &format!("particle_substrate_static = {upper:.17}"),
            1,
        );
        let at = Scene::parse("test.toml", &text).unwrap();
        let r = model_report(&at);
        assert!(!r.mu_feasible, "at the bound");
        assert!(r.y_star.is_none_or(|y| y < 1e-3), "y* {:?}", r.y_star);
    }

    #[test]
    fn paper_figures_in_the_report() {
        let r = model_report(&Scene::default_scene());
        assert!((r.k_y - 1427.0).abs() < 1.0);
        assert!((r.k_yz - 123.4).abs() < 0.1);
        assert!((r.a_as - 904.8e-9).abs() < 0.1e-9);
        assert!((r.y_star.unwrap() - 0.2215e-9).abs() < 0.001e-9);
        assert!((r.mu_upper_bound.unwrap() - 3.75).abs() < 0.01);
        assert!(r.mu_feasible);
        assert!((r.r1 - 1.7e-9).abs() < 0.02e-9);
        assert_eq!(r.state_dimension, 7);
        assert!(r.steady_state.is_some());
    }

    /// docs/model.md's force curve of the default scene (`nanopush model --force-curve`;
    /// "`nanopush model`"): snap-in at 3.60 nm, pull-off −55.09 nN at 7.05 nm, the same at any
    /// `--steps` (root-finding, not the grid). The pull-off is the closed form of a Hertz contact
    /// leaving at zero indentation: the meniscus `4πRₜγ_L` (27 nN) plus van der Waals at contact
    /// `HRₜ/(6a₀²)` with the scene's combined Hamaker constant; it lets go at `d = a₀ + |F|/k_c`.
    /// The retraction runs out to 1.5 adhesion/k_c beyond the start.
    #[test]
    fn the_default_force_curves_snap_in_and_pull_off_are_as_documented() {
        use nanopush_instrument::physics::forces::vdw::sphere_plane_force;
        let scene = Scene::default_scene();
        let ts = scene.tip_sample();
        let meniscus = 4.0 * std::f64::consts::PI * ts.r_t * scene.file.environment.surface_tension_mj_per_m2 * 1e-3;
        assert!((meniscus - 27e-9).abs() < 0.5e-9, "meniscus {meniscus:e} N");
        let closed_form = -meniscus + sphere_plane_force(ts.long_range.hamaker.unwrap(), ts.r_t, ts.a0, ts.a0);
        for steps in [20, 200, 2000] {
            let r = force_curve_report(&scene, steps);
            let snap_in = r.snap_in_distance.unwrap();
            let pull_off = r.pull_off_distance.unwrap();
            assert!(
                (snap_in - 3.60e-9).abs() < 0.005e-9,
                "{steps} steps: snap-in {snap_in:e} m"
            );
            assert!(
                (r.pull_off_force + 55.09e-9).abs() < 0.005e-9,
                "{steps} steps: pull-off {:e} N",
                r.pull_off_force
            );
            assert!((r.pull_off_force / closed_form - 1.0).abs() < 1e-9, "{steps} steps");
            assert!(
                (pull_off - 7.05e-9).abs() < 0.005e-9,
                "{steps} steps: at {pull_off:e} m"
            );
            assert!((pull_off - (ts.a0 - r.pull_off_force / ts.k_c)).abs() < 1e-15);
            let start = r.approach[0].distance;
            let end = r.retraction.last().unwrap().distance;
            assert!(
                (end - start - 1.5 * ts.adhesion() / ts.k_c).abs() < 1e-15,
                "{steps} steps"
            );
        }
    }

    /// docs/model.md's time scale of the particle's contacts in the default scene ("The pushing
    /// dynamics (Eq 17)"): `nanopush model`'s `contact_period`, the substrate contact's tangential
    /// spring `k_as* = 8RₐG*` against the particle's mass, `2π√(m_a/k_as*)` = 5.4 ns.
    #[test]
    fn the_default_scenes_contact_period_is_as_documented() {
        let r = model_report(&Scene::default_scene());
        assert!((r.contact_period - 5.4e-9).abs() < 0.05e-9, "{:e} s", r.contact_period);
        let by_hand = 2.0 * std::f64::consts::PI * (r.particle_mass / r.k_as).sqrt();
        assert!((r.contact_period / by_hand - 1.0).abs() < 1e-12);
    }

    #[test]
    fn force_curve_has_hysteresis() {
        let r = force_curve_report(&Scene::default_scene(), 300);
        assert!(r.snap_in_distance.is_some() && r.pull_off_distance.is_some());
        assert!(r.pull_off_force < 0.0);
        assert!(r.pull_off_distance.unwrap() > r.snap_in_distance.unwrap());
    }
}
