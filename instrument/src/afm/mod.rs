//! The simulated instrument (stage, cantilever, substrate, particles) behind the controller, and
//! the instrument interface ([`Microscope`]) it shares with a real controller.

mod microscope;
mod sim_microscope;
mod simulated;

pub use microscope::{Capabilities, Limits, Microscope, MicroscopeError, Sample, ScanFrame};
pub use sim_microscope::SimulatedMicroscope;
pub use simulated::{Afm, AfmError, Particle, RELEASE_GAP, Reading, Truth, Unphysical};

use crate::scan::{Sphere, Surface};
use crate::scene::Scene;

impl Afm {
    /// The sample as it is now, for scans (tapping never moves it).
    pub fn surface(&self) -> Surface {
        Surface {
            topography: self.topography().clone(),
            spheres: self
                .particles()
                .iter()
                .map(|p| Sphere {
                    x: p.x,
                    y: p.y,
                    r: p.radius,
                })
                .collect(),
        }
    }

    /// The instrument of a scene: every particle with its own pushing parameters, the tip at
    /// `(x, y)` (m) and the strategy's start height above the substrate there, ticking at
    /// `tick` seconds.
    pub fn from_scene(scene: &Scene, x: f64, y: f64, tick: f64) -> Afm {
        let f = &scene.file;
        let topography = scene.topography();
        let z = topography.height(x, y) + f.strategy.start_height_um * 1e-6;
        let particles = f
            .particles
            .iter()
            .map(|p| {
                (
                    Particle {
                        id: p.id,
                        x: p.x_um * 1e-6,
                        y: p.y_um * 1e-6,
                        radius: p.radius_nm * 1e-9,
                    },
                    scene.push_params_for(p),
                )
            })
            .collect();
        let mut afm = Afm::new(
            scene.tip_sample(),
            scene.readout(),
            topography,
            particles,
            [x, y, z],
            f.stage.range_um * 1e-6,
            tick,
        );
        let st = &f.strategy;
        let fastest = f
            .push
            .speed_um_per_s
            .max(st.travel_speed_um_per_s)
            .max(st.approach_speed_um_per_s);
        afm.set_speed_bound(fastest * 1e-6);
        afm
    }
}
