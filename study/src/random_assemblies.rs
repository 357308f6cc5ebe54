//! Random assemblies nobody tuned: a seeded generator scatters 4-40 of the shipped assembly
//! scene's particles (0.5 µm gold-coated latex) over its stage and draws a pattern of 3-25
//! sites (a line, a grid or a ring, at a random place, angle and spacing); in one case in three
//! some particles are dropped inside the pattern's area, where order and routes matter. Each is
//! assembled as `nanopush assemble` assembles ([`nanopush_instrument::assembly::assemble`]) and
//! checked against the truth: a site reported filled must truly hold a particle within its
//! tolerance, no pushed particle may go through another, and every refusal must say why.

use nanopush_instrument::afm::Afm;
use nanopush_instrument::assembly::{AssemblyOptions, AssemblyRun, Outcome, Pattern, assemble};
use nanopush_instrument::scene::Scene;
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

/// The shipped assembly scene (`scenes/assembly-latex.toml`): the physics and the instrument of
/// every case.
pub const ASSEMBLY_SCENE: &str = include_str!("../../scenes/assembly-latex.toml");

/// One random case.
#[derive(Debug, Clone)]
pub struct RandomAssembly {
    /// The seed it was drawn from.
    pub seed: u64,
    /// The scene, with its particles where the case put them.
    pub scene: Scene,
    /// The pattern's generator text.
    pub spec: String,
    /// The pattern.
    pub pattern: Pattern,
    /// Particles dropped inside the pattern's area.
    pub inside: usize,
    /// The pattern's centre (µm).
    pub centre_um: (f64, f64),
}

impl RandomAssembly {
    /// The case's scene as a file whose header says how to assemble it by hand, as the
    /// campaign does.
    pub fn scene_text(&self) -> Result<String, toml::ser::Error> {
        Ok(format!(
            "# Random assembly case {seed}: {n} particles, and the pattern {spec} centred at ({x}, {y}) µm.\n\
             # Assemble it as `nanopush assemble --random 1 --seed {seed}` does:\n\
             #   nanopush assemble --scene seed-{seed}.toml --pattern '{spec}' --at-um {x},{y}\n\
             # (the campaign's tip starts at the stage's corner, as that command's does).\n\n{}",
            toml::to_string(&self.scene.file)?,
            seed = self.seed,
            n = self.scene.file.particles.len(),
            spec = self.spec,
            x = self.centre_um.0,
            y = self.centre_um.1,
        ))
    }
}

/// The case of `seed`.
pub fn random_assembly(seed: u64) -> RandomAssembly {
    let base = Scene::parse("assembly-latex", ASSEMBLY_SCENE).expect("the shipped assembly scene is valid (tested)");
    let mut rng = SmallRng::seed_from_u64(seed);
    let range = base.file.stage.range_um;
    // The pattern first: a shape and its size, drawn until it fits well inside the stage (its
    // sites within 40 µm of its centre), then a place that keeps it on the stage.
    let (spec, reach) = loop {
        let n_sites = rng.random_range(3..=25usize);
        let spacing = rng.random_range(2.5..=6.0f64);
        let angle = rng.random_range(0.0..180.0f64);
        let shape = match rng.random_range(0..3) {
            0 => format!("line:n={n_sites},spacing_um={spacing:.2}"),
            1 => {
                let cols = (n_sites as f64).sqrt().ceil() as usize;
                let rows = n_sites.div_ceil(cols);
                format!("grid:rows={rows},cols={cols},spacing_um={spacing:.2}")
            }
            _ => {
                let radius = (spacing * n_sites as f64 / std::f64::consts::TAU).max(spacing);
                format!("ring:n={n_sites},radius_um={radius:.2}")
            }
        };
        let spec = format!("{shape},angle_deg={angle:.0}");
        // How far its sites reach from its centre (µm).
        let reach = Pattern::generate(&spec, (0.0, 0.0))
            .expect("a valid generator")
            .sites
            .iter()
            .map(|s| s.x.hypot(s.y) * 1e6)
            .fold(0.0, f64::max);
        if reach <= 40.0 {
            break (spec, reach);
        }
    };
    let margin = reach + 3.0;
    let centre = (
        rng.random_range(margin..=(range - margin).max(margin)),
        rng.random_range(margin..=(range - margin).max(margin)),
    );
    let pattern = Pattern::generate(&spec, (centre.0 * 1e-6, centre.1 * 1e-6)).expect("a valid generator");
    // The particles: a few more than the sites, at least 4, at most 40; in one case in three,
    // some inside the pattern's circle.
    let n_sites = pattern.sites.len();
    let n = rng.random_range(n_sites.max(4)..=(n_sites + 10).clamp(4, 40));
    let inside_wanted = if rng.random_bool(1.0 / 3.0) {
        rng.random_range(1..=3usize)
    } else {
        0
    };
    let template = base.file.particles[0].clone();
    let mut at: Vec<(f64, f64)> = Vec::new();
    let mut inside = 0;
    let r = template.radius_nm * 1e-3;
    let mut tries = 0;
    while at.len() < n && tries < 100_000 {
        tries += 1;
        let p = if inside < inside_wanted {
            let a = rng.random_range(0.0..std::f64::consts::TAU);
            let d = rng.random_range(0.0..reach.max(1.0));
            (centre.0 + d * a.cos(), centre.1 + d * a.sin())
        } else {
            (rng.random_range(2.0..=range - 2.0), rng.random_range(2.0..=range - 2.0))
        };
        // Apart by two radii and a micrometre: a particle the clearance already holds is not
        // one the assembly could have avoided.
        let free = at.iter().all(|q| (q.0 - p.0).hypot(q.1 - p.1) >= 2.0 * r + 1.0);
        let on = p.0 >= 1.0 && p.1 >= 1.0 && p.0 <= range - 1.0 && p.1 <= range - 1.0;
        if free && on {
            if inside < inside_wanted {
                inside += 1;
            }
            at.push(p);
        }
    }
    let mut file = base.file.clone();
    file.name = format!("random-assembly-{seed}");
    file.particles = at
        .iter()
        .enumerate()
        .map(|(k, &(x, y))| {
            let mut p = template.clone();
            p.id = k as u32 + 1;
            p.x_um = (x * 1000.0).round() / 1000.0;
            p.y_um = (y * 1000.0).round() / 1000.0;
            p
        })
        .collect();
    file.push.particle_id = 1;
    let text = toml::to_string(&file).expect("a scene file serializes");
    let scene = Scene::parse(&file.name, &text).expect("a random assembly's scene is valid");
    RandomAssembly {
        seed,
        scene,
        spec,
        pattern,
        inside,
        centre_um: centre,
    }
}

/// A case assembled and checked.
#[derive(Debug, Clone)]
pub struct JudgedAssembly {
    /// The case.
    pub seed: u64,
    /// Its pattern's generator.
    pub spec: String,
    /// Particles, sites, and particles dropped inside the pattern.
    pub particles: usize,
    /// Sites.
    pub sites: usize,
    /// Particles inside the pattern's area at the start.
    pub inside: usize,
    /// `filled`, `incomplete`, `refused`.
    pub outcome: &'static str,
    /// Sites reported filled.
    pub reported_filled: usize,
    /// Sites truly within their tolerance.
    pub truly_filled: usize,
    /// Sites by status: unreachable, refused, missed.
    pub open: Vec<(String, usize)>,
    /// What the truth says went wrong: a site reported filled that is not, a particle pushed
    /// through another, a refusal without a reason.
    pub violations: Vec<String>,
    /// Why it was refused.
    pub refusal: Option<String>,
    /// Moves made.
    pub moves: usize,
    /// Wall time (s), simulated push and scan time (s).
    pub wall_time: f64,
    /// Simulated time of the pushes (s).
    pub push_time: f64,
    /// Simulated time of the scans (s).
    pub scan_time: f64,
}

/// Assembles case `seed` and checks it against the truth.
pub fn run_random_assembly(seed: u64) -> JudgedAssembly {
    run_case(&random_assembly(seed))
}

/// Assembles `case` and checks it against the truth.
pub fn run_case(case: &RandomAssembly) -> JudgedAssembly {
    let mut afm = Afm::from_scene(&case.scene, 0.0, 0.0, 1e-3);
    let run = assemble(
        &case.scene,
        &mut afm,
        &case.pattern,
        &AssemblyOptions::default(),
        &mut |_| {},
        &|| false,
    );
    judge(case, &run)
}

fn judge(case: &RandomAssembly, run: &AssemblyRun) -> JudgedAssembly {
    let mut violations = run.violations.clone();
    let mut truly = 0;
    let mut open: Vec<(String, usize)> = Vec::new();
    for (i, s) in run.sites.iter().enumerate() {
        let true_ok = s.error.is_some_and(|e| e <= s.tolerance);
        if true_ok {
            truly += 1;
        }
        if s.status == "filled" && !true_ok {
            violations.push(format!(
                "site {i} reported filled, truly {}",
                s.error.map_or("without a particle".to_string(), |e| format!(
                    "{:.1} nm from it",
                    e * 1e9
                ))
            ));
        }
        if s.status != "filled" {
            if s.reason.as_deref().is_none_or(str::is_empty) {
                violations.push(format!("site {i} is {} without a reason", s.status));
            }
            match open.iter_mut().find(|(k, _)| k == s.status) {
                Some((_, n)) => *n += 1,
                None => open.push((s.status.to_string(), 1)),
            }
        }
    }
    if run.outcome == Outcome::Refused && run.refusal.as_deref().is_none_or(str::is_empty) {
        violations.push("refused without a reason".into());
    }
    JudgedAssembly {
        seed: case.seed,
        spec: case.spec.clone(),
        particles: case.scene.file.particles.len(),
        sites: case.pattern.sites.len(),
        inside: case.inside,
        outcome: run.outcome.code(),
        reported_filled: run.sites.iter().filter(|s| s.status == "filled").count(),
        truly_filled: truly,
        open,
        violations,
        refusal: run.refusal.clone(),
        moves: run.moves.len(),
        wall_time: run.wall_time,
        push_time: run.push_time,
        scan_time: run.scan_time,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_generator_is_seeded_and_gives_valid_layouts_and_patterns() {
        for seed in 0..40 {
            let a = random_assembly(seed);
            let b = random_assembly(seed);
            assert_eq!(a.scene.file, b.scene.file);
            assert_eq!(a.spec, b.spec);
            let (n, s) = (a.scene.file.particles.len(), a.pattern.sites.len());
            assert!(
                (4..=40).contains(&n) && (3..=25).contains(&s),
                "seed {seed}: {n} particles, {s} sites"
            );
            assert!(n >= s, "seed {seed}");
            let range = a.scene.file.stage.range_um * 1e-6;
            for site in &a.pattern.sites {
                assert!(
                    site.x > 0.0 && site.x < range && site.y > 0.0 && site.y < range,
                    "seed {seed}"
                );
            }
        }
        // Some cases drop particles inside the pattern, some do not.
        let inside = (0..40).filter(|&s| random_assembly(s).inside > 0).count();
        assert!((5..=30).contains(&inside), "{inside} of 40");
    }
}
