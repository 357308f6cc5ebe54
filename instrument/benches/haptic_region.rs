//! The haptic z-control's renderable region and transparency, printed, not timed:
//!
//! ```text
//! cargo bench -p nanopush-instrument --bench haptic_region
//! ```
//!
//! 1. the Z-width of the simulated device (it declares 2 kN/m at 1 kHz: a port damping of
//!    3 N·s/m) at device rates 1 and 4 kHz with the loop's 1 ms round trip: the largest stiffness
//!    rendered passively with each virtual damping, `K_max(B) = (b − |B|)/(T/2 + T_d)`
//!    (`nanopush_proto::haptic::region`);
//! 2. the transparency at each accepted setting (`nm_per_mm` × `pull_off_at_hand_n`, the ends
//!    and the grid's values), at 1 and 4 kHz: the felt stiffness, measured in the closed loop
//!    (the hand set-point goes slowly into the surface; the slope of the rendered force against
//!    the handle's position while the tip presses), divided by the scaled contact stiffness
//!    asked, `g_f k_z g_p`. Where the surface lies beyond the handle's travel (100 nm of parking
//!    gap at under 2.9 nm/mm) nothing can be felt; the cell shows `—`.

#[path = "../tests/haptic_rig/mod.rs"]
mod haptic_rig;

use haptic_rig::closed_loop;
use nanopush_haptic::grid::{GRID_NM_PER_MM, GRID_OPERATORS, GRID_PULL_OFF_N, TIP_CONTACT, judge_at};
use nanopush_haptic::operator::Script;
use nanopush_instrument::scene::Scene;
use nanopush_proto::haptic::region::{edge, limit_force_gain, max_stiffness, port_damping};

/// The simulated device's declared limit (N/m at 1 kHz) and the loop's round trip (s).
const K_SPEC: f64 = 2000.0;
const DELAY: f64 = 1e-3;
const NM_PER_MM: [f64; 6] = [0.01, 1.0, 10.0, 100.0, 300.0, 1000.0];
const PULL_OFF_N: [f64; 5] = [0.01, 0.1, 1.0, 2.5, 10.0];

fn main() {
    let b = port_damping(K_SPEC, 1000.0);
    println!(
        "## Z-width of the simulated device (port damping {b} N·s/m, round trip {} ms)\n",
        DELAY * 1e3
    );
    println!("| virtual damping B (N·s/m) | K_max at 1 kHz (N/m) | K_max at 4 kHz (N/m) |");
    println!("|---|---|---|");
    for damping in [0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0] {
        println!(
            "| {damping} | {:.0} | {:.0} |",
            max_stiffness(b, damping, 1000.0, DELAY),
            max_stiffness(b, damping, 4000.0, DELAY)
        );
    }
    let scene = Scene::default_scene();
    let (k_z, adhesion) = (scene.tip_sample().k_c, scene.tip_sample().adhesion());
    for per_tick in [1u32, 4] {
        let rate = 1000.0 * f64::from(per_tick);
        // The simulated handle renders dampers up to m/T (50 g).
        let k_max = edge(K_SPEC, 1000.0, rate, DELAY, 0.05 * rate);
        println!(
            "\n## Transparency at {} kHz: felt ÷ asked contact stiffness (the felt stiffness, N/m); region edge {k_max:.0} N/m\n",
            per_tick
        );
        print!("| nm/mm \\ pull-off |");
        for f in PULL_OFF_N {
            print!(" {f} N |");
        }
        println!();
        println!("|---|{}", "---|".repeat(PULL_OFF_N.len()));
        for g in NM_PER_MM {
            print!("| {g} |");
            for f in PULL_OFF_N {
                let g_p = g * 1e-6;
                let asked = f / adhesion * k_z * g_p;
                let (g_f, _) = limit_force_gain(f / adhesion, g_p, k_z, k_max);
                match felt_stiffness(g, f, per_tick, g_f * k_z * g_p, g_f * adhesion) {
                    Some(k) => print!(" {:.3} ({k:.0}) |", k / asked),
                    None => print!(" — |"),
                }
            }
            println!();
        }
    }
    grid_summary();
}

/// The haptic grid in one process at 1 and 4 kHz (the measures on 1 ms samples, the energy from
/// every device cycle): per rate, the cells that pass, the lowest closed-cycle energy, the most
/// chatter and the largest tip swing.
fn grid_summary() {
    println!(
        "\n## The grid in one process (80 cells: {GRID_OPERATORS:?} × nm/mm {GRID_NM_PER_MM:?} × N {GRID_PULL_OFF_N:?})\n"
    );
    println!(
        "| device rate | cells passing | lowest energy of a cell that touched (J) | most chatter | largest tip swing |"
    );
    println!("|---|---|---|---|---|");
    for per_tick in [1usize, 4] {
        let (mut pass, mut e_min, mut chatter, mut swing) = (0, f64::INFINITY, 0, 0.0f64);
        for op in GRID_OPERATORS {
            for g in GRID_NM_PER_MM {
                for f in GRID_PULL_OFF_N {
                    let (rows, _) =
                        closed_loop(Script::parse(op).expect("a grid script"), g, f, per_tick as u32, 30_000);
                    let v = judge_at(&rows, per_tick, 2.5);
                    pass += usize::from(v.passes());
                    // The lowest energy of the cells that reached the surface (at 1 nm/mm it is
                    // 100 mm of handle away: those cells feel nothing).
                    if v.max_force > 0.1 {
                        e_min = e_min.min(v.energy);
                    }
                    chatter = chatter.max(v.chatter);
                    swing = swing.max(v.tip_swing);
                    if !v.passes() {
                        println!("<!-- {op} {g} nm/mm {f} N at {per_tick} kHz: {v} -->");
                    }
                }
            }
        }
        println!("| {per_tick} kHz | {pass}/80 | {e_min:+.2e} | {chatter} | {swing:.3} |");
    }
}

/// The felt stiffness at `nm_per_mm` and `pull_off_n` (N/m), measured going slowly into the
/// surface, or `None` when the surface lies beyond the handle's travel. `expected` (N/m) and the
/// pull-off in force `held` (N: the adhesion bends the lever down by as much before the contact
/// pushes back) size how deep the hand goes, to feel about 0.8 N.
fn felt_stiffness(nm_per_mm: f64, pull_off_n: f64, per_tick: u32, expected: f64, held: f64) -> Option<f64> {
    let g_p = nm_per_mm * 1e-6;
    let surface = -100e-9 / g_p;
    if surface < -0.035 {
        return None;
    }
    // At most half the tip's speed limit (1 µm/s), at most the press's 3 mm/s.
    let speed = (0.5e-6 / g_p).min(3e-3);
    let end = surface - ((0.8 + held) / expected.max(1e-9)).min(0.035 + surface);
    let t_end = -end / speed;
    let script = Script::File(vec![(0.0, 0.0), (t_end, end), (t_end + 0.5, end)]);
    let (rows, _) = closed_loop(script, nm_per_mm, pull_off_n, per_tick, 120_000);
    let top = rows.iter().map(|r| r.force).fold(0.0, f64::max);
    let pressed: Vec<(f64, f64)> = rows
        .iter()
        .filter(|r| r.tip_force > TIP_CONTACT && r.force > 0.2 * top && r.force < 0.8 * top)
        .map(|r| (r.handle, r.force))
        .collect();
    if pressed.len() < 20 {
        return None;
    }
    // Least squares F = a + s x; the felt stiffness is −s.
    let n = pressed.len() as f64;
    let (mx, mf) = pressed.iter().fold((0.0, 0.0), |(a, b), (x, f)| (a + x / n, b + f / n));
    let (sxf, sxx) = pressed.iter().fold((0.0, 0.0), |(a, b), (x, f)| {
        (a + (x - mx) * (f - mf), b + (x - mx) * (x - mx))
    });
    Some(-sxf / sxx)
}
