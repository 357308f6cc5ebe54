//! The simulated AFM behind the instrument interface: its clock is the tick, a reading comes every
//! tick (1 kHz), Z is held where the caller puts it (the force loop is the strategy's, not the
//! controller's), and a scan images the particles where they are now.

use super::Afm;
use super::microscope::{Capabilities, Limits, Microscope, MicroscopeError, Sample, ScanFrame};
use crate::scan::{HeightImage, ScanParams, Tip, scan};
use crate::scene::Scene;

/// The simulated AFM as a [`Microscope`].
#[derive(Debug)]
pub struct SimulatedMicroscope {
    afm: Afm,
    scan: ScanParams,
    tip: Tip,
    /// Height of the withdrawn tip above the substrate (m).
    withdraw_height: f64,
    /// The motion in progress: target (x, y) and speed (m/s).
    motion: Option<([f64; 2], f64)>,
}

impl SimulatedMicroscope {
    /// The scene's instrument, the tip withdrawn over `(x, y)` (m).
    pub fn from_scene(scene: &Scene, x: f64, y: f64, tick: f64) -> SimulatedMicroscope {
        let f = &scene.file;
        SimulatedMicroscope {
            afm: Afm::from_scene(scene, x, y, tick),
            scan: ScanParams::from_scene(scene),
            tip: Tip::from_scene(scene),
            withdraw_height: f.strategy.start_height_um * 1e-6,
            motion: None,
        }
    }

    /// The simulated instrument underneath (its truth is for tests and traces).
    pub fn afm(&self) -> &Afm {
        &self.afm
    }

    fn sample(&mut self) -> Sample {
        let r = self.afm.read();
        Sample {
            t: r.t,
            tip: r.stage,
            normal: r.volts,
            lateral: None,
        }
    }

    fn fail(e: impl std::fmt::Display) -> MicroscopeError {
        MicroscopeError::Simulation(e.to_string())
    }
}

impl Microscope for SimulatedMicroscope {
    fn capabilities(&self) -> Capabilities {
        Capabilities {
            backend: "simulated AFM".into(),
            feed_rate_hz: 1.0 / self.afm.tick(),
            z_closed_locally: false,
            scan_engine: true,
            read_only: false,
        }
    }

    fn limits(&mut self) -> Result<Limits, MicroscopeError> {
        let range = self.afm.range();
        Ok(Limits {
            x: [0.0, range],
            y: [0.0, range],
            z: [f64::NEG_INFINITY, f64::INFINITY],
            // The fastest the scene ever moves the stage, as the instrument's guard bounds it.
            max_speed: self.afm.speed_bound(),
        })
    }

    fn start_move(&mut self, x: f64, y: f64, speed: f64) -> Result<(), MicroscopeError> {
        let limits = self.limits()?;
        if !(speed.is_finite() && speed > 0.0 && speed <= limits.max_speed * (1.0 + 1e-9)) {
            return Err(MicroscopeError::OutOfLimits {
                what: format!("speed {:.3} µm/s", speed * 1e6),
                allowed: format!("(0, {:.3}] µm/s", limits.max_speed * 1e6),
            });
        }
        if !(x.is_finite() && y.is_finite() && limits.contains_xy(x, y)) {
            return Err(MicroscopeError::OutOfLimits {
                what: format!("move to ({:.3}, {:.3}) µm", x * 1e6, y * 1e6),
                allowed: format!("x and y in [0, {:.3}] µm", limits.x[1] * 1e6),
            });
        }
        self.motion = Some(([x, y], speed));
        Ok(())
    }

    fn stop_move(&mut self) -> Result<(), MicroscopeError> {
        self.motion = None;
        Ok(())
    }

    fn poll(&mut self) -> Result<(Sample, bool), MicroscopeError> {
        let [x, y, z] = self.afm.stage();
        let Some(([tx, ty], speed)) = self.motion else {
            self.afm.step([x, y, z]).map_err(Self::fail)?;
            return Ok((self.sample(), true));
        };
        let (dx, dy) = (tx - x, ty - y);
        let left = dx.hypot(dy);
        let reach = speed * self.afm.tick();
        let arrived = left <= reach;
        let target = if arrived {
            [tx, ty, z]
        } else {
            [x + dx / left * reach, y + dy / left * reach, z]
        };
        self.afm.step(target).map_err(Self::fail)?;
        if let Some(fault) = self.afm.take_fault() {
            return Err(Self::fail(format!(
                "the push model left physics: {} = {:e}, limit {:e}",
                fault.what, fault.value, fault.limit
            )));
        }
        if arrived {
            self.motion = None;
        }
        Ok((self.sample(), arrived))
    }

    fn hold_force(&mut self, _setpoint: f64) -> Result<(), MicroscopeError> {
        Err(MicroscopeError::Unsupported {
            backend: "the simulated AFM".into(),
            what: "hold the force with a Z feedback of its own (the strategy closes the loop at 1 kHz)".into(),
        })
    }

    fn scan(&mut self, frame: Option<&ScanFrame>) -> Result<HeightImage, MicroscopeError> {
        let mut p = self.scan;
        if let Some(f) = frame {
            if f.width != f.height || f.pixels != f.lines {
                return Err(MicroscopeError::OutOfLimits {
                    what: format!(
                        "a {:.3} × {:.3} µm frame of {} × {} pixels",
                        f.width * 1e6,
                        f.height * 1e6,
                        f.pixels,
                        f.lines
                    ),
                    allowed: "square frames of square pixels (the simulated scanner's)".into(),
                });
            }
            p.centre_x = f.centre_x;
            p.centre_y = f.centre_y;
            p.size = f.width;
            p.pixels = f.pixels;
        }
        Ok(scan(&self.afm.surface(), self.tip, p))
    }

    fn current_frame(&mut self) -> Result<ScanFrame, MicroscopeError> {
        Ok(ScanFrame {
            centre_x: self.scan.centre_x,
            centre_y: self.scan.centre_y,
            width: self.scan.size,
            height: self.scan.size,
            pixels: self.scan.pixels,
            lines: self.scan.pixels,
        })
    }

    fn withdraw(&mut self) -> Result<(), MicroscopeError> {
        self.motion = None;
        let [x, y, _] = self.afm.stage();
        let z = self.afm.topography().height(x, y) + self.withdraw_height;
        self.afm.step([x, y, z]).map_err(Self::fail)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn microscope() -> SimulatedMicroscope {
        SimulatedMicroscope::from_scene(&Scene::default_scene(), 20e-6, 20e-6, 1e-3)
    }

    #[test]
    fn it_feeds_a_reading_every_tick_and_holds_z_itself_nowhere() {
        let m = microscope();
        let c = m.capabilities();
        assert_eq!(c.feed_rate_hz, 1000.0);
        assert!(!c.z_closed_locally && c.scan_engine && !c.read_only);
    }

    #[test]
    fn a_move_arrives_at_its_speed() {
        let mut m = microscope();
        m.start_move(21e-6, 20e-6, 10e-6).unwrap();
        let mut polls = 0;
        loop {
            polls += 1;
            let (s, arrived) = m.poll().unwrap();
            if arrived {
                assert!((s.tip[0] - 21e-6).abs() < 1e-12, "{:?}", s.tip);
                break;
            }
            assert!(polls < 1000, "1 µm at 10 µm/s takes 100 ticks");
        }
        assert_eq!(polls, 100);
    }

    #[test]
    fn a_move_outside_the_stage_or_too_fast_is_refused_before_anything_moves() {
        let mut m = microscope();
        let e = m.start_move(1.0, 20e-6, 1e-6).unwrap_err().to_string();
        assert!(e.contains("outside the limits") && e.contains("µm"), "{e}");
        let e = m.start_move(21e-6, 20e-6, 1.0).unwrap_err().to_string();
        assert!(e.contains("speed 1000000.000 µm/s"), "{e}");
        assert_eq!(m.afm().stage()[0], 20e-6);
    }

    #[test]
    fn the_force_is_not_held_by_a_controller_it_does_not_have() {
        let e = microscope().hold_force(0.1).unwrap_err();
        assert!(matches!(e, MicroscopeError::Unsupported { .. }), "{e}");
    }

    #[test]
    fn a_scan_of_its_own_frame_matches_the_scene_scan() {
        let scene = Scene::default_scene();
        let mut m = microscope();
        let frame = ScanFrame {
            pixels: 32,
            lines: 32,
            ..m.current_frame().unwrap()
        };
        let img = m.scan(Some(&frame)).unwrap();
        let mut p = ScanParams::from_scene(&scene);
        p.pixels = 32;
        let direct = scan(&crate::scan::Surface::from_scene(&scene), Tip::from_scene(&scene), p);
        assert_eq!(img, direct);
    }

    #[test]
    fn withdraw_lifts_the_tip_to_the_start_height() {
        let mut m = microscope();
        m.withdraw().unwrap();
        let s = m.afm().stage();
        let ground = m.afm().topography().height(s[0], s[1]);
        assert!((s[2] - ground - 3e-6).abs() < 1e-12);
    }
}
