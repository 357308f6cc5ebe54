use nanopush_instrument::afm::Afm;
use nanopush_instrument::assembly::*;
use nanopush_instrument::scene::Scene;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let scene = Scene::from_path(std::path::Path::new(&args[1])).unwrap();
    let spec = &args[2];
    let at: Vec<f64> = args[3].split(',').map(|v| v.parse::<f64>().unwrap() * 1e-6).collect();
    let pattern = Pattern::generate(spec, (at[0], at[1])).unwrap();
    let p0 = scene.pushed_particle();
    let mut afm = Afm::from_scene(&scene, 5e-6, 5e-6, 1e-3);
    let _ = p0;
    let t = std::time::Instant::now();
    {
        use nanopush_instrument::scan::*;
        let t0 = std::time::Instant::now();
        let tip = Tip::from_scene(&scene);
        let base = ScanParams::from_scene(&scene);
        let surf = afm.surface();
        let ts = std::time::Instant::now();
        let mut acc = 0.0;
        for i in 0..512 {
            for j in 0..512 {
                acc += substrate_image(&surf.topography, &tip, j as f64 * 0.2e-6, i as f64 * 0.2e-6);
            }
        }
        eprintln!("substrate only {:.2}s ({acc:e})", ts.elapsed().as_secs_f64());
        let ts = std::time::Instant::now();
        let mut acc = 0.0;
        for i in 0..512 {
            for j in 0..512 {
                for sp in &surf.spheres {
                    acc += sphere_image(&tip, sp, surf.centre_z(sp), j as f64 * 0.2e-6, i as f64 * 0.2e-6);
                }
            }
        }
        eprintln!("spheres only {:.2}s ({acc:e})", ts.elapsed().as_secs_f64());
        let img = scan(&afm.surface(), tip, base);
        let t1 = t0.elapsed().as_secs_f64();
        let found = find_particles(&img, &tip);
        eprintln!(
            "scan {:.2}s find {:.2}s ({} found)",
            t1,
            t0.elapsed().as_secs_f64() - t1,
            found.len()
        );
        let seen: Vec<Seen> = found
            .iter()
            .map(|l| Seen {
                x: l.x,
                y: l.y,
                radius: l.radius,
            })
            .collect();
        let t2 = std::time::Instant::now();
        let pl = plan(
            &seen,
            &pattern,
            &PlanSettings::from_scene(&scene, 25e-9),
            &Constraints::default(),
        );
        eprintln!("plan {:.4}s ({} moves)", t2.elapsed().as_secs_f64(), pl.moves.len());
    }
    let run = assemble(
        &scene,
        &mut afm,
        &pattern,
        &AssemblyOptions::default(),
        &mut |e| match e {
            Event::Planned { plan, .. } => eprintln!(
                "planned: {} moves, {} fillable, {:.2}s",
                plan.moves.len(),
                plan.fillable(),
                t.elapsed().as_secs_f64()
            ),
            Event::MoveStarted { number, of, planned } => eprintln!(
                "move {number}/{of}: {:?} ({:.2},{:.2}) -> ({:.2},{:.2}) legs {}",
                planned.purpose,
                planned.from.0 * 1e6,
                planned.from.1 * 1e6,
                planned.to.0 * 1e6,
                planned.to.1 * 1e6,
                planned.legs.len()
            ),
            Event::MoveEnded { record, .. } => eprintln!(
                "  {} err {:?} pushes {} push_time {:.1}s wall {:.1}s",
                record.outcome,
                record.error.map(|e| e * 1e9),
                record.pushes,
                record.push_time,
                t.elapsed().as_secs_f64()
            ),
            Event::SiteFilled { site } => eprintln!("  site {site} filled"),
            Event::Replanned { plan, .. } => eprintln!("  replanned: {} moves left", plan.moves.len()),
        },
        &|| false,
    );
    eprintln!(
        "outcome {:?} refusal {:?} wall {:.1} push {:.1} scan {:.1} violations {:?}",
        run.outcome, run.refusal, run.wall_time, run.push_time, run.scan_time, run.violations
    );
    for (i, s) in run.sites.iter().enumerate() {
        eprintln!(
            "site {i}: {} particle {:?} err {:?} {:?}",
            s.status,
            s.particle,
            s.error.map(|e| e * 1e9),
            s.reason
        );
    }
}
