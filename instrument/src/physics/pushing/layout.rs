//! Where each degree of freedom sits in the state vector. Only what the scene includes is there.

use crate::physics::pushing::params::{Dof, Dofs};

/// Largest state dimension: stage (2) + cantilever (4) + particle y, z, θ (2 each).
pub const MAX_STATES: usize = 12;

/// Index of one mechanical DOF: its position, and its velocity when it is dynamic.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Slot {
    /// Index of the position.
    pub pos: usize,
    /// Index of the velocity (`None` when quasi-static).
    pub vel: Option<usize>,
}

/// The state vector's layout for one scene.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Layout {
    /// Stage displacement `s` (tip base relative to the substrate) and its rate (Eq 13).
    pub stage: Option<Slot>,
    /// Cantilever deflection `ζ_y'` in the cantilever's axes.
    pub zeta_y: Slot,
    /// Cantilever deflection `ζ_z'` (the measured one, Eq 11).
    pub zeta_z: Slot,
    /// Particle position `y` along the push.
    pub particle_y: Slot,
    /// Particle vertical displacement `z` (−indentation).
    pub particle_z: Option<Slot>,
    /// Particle rotation `θ` (positive rolls forward).
    pub rotation: Option<Slot>,
    /// Number of states.
    pub len: usize,
}

impl Layout {
    /// The layout for a set of DOFs. `particle_y` and `cantilever` cannot be `Off` (scene
    /// validation rejects it); they are treated as quasi-static if they are.
    pub fn new(d: &Dofs) -> Layout {
        let mut n = 0;
        let mut slot = |dof: Dof| -> Option<Slot> {
            match dof {
                Dof::Off => None,
                Dof::QuasiStatic => {
                    n += 1;
                    Some(Slot { pos: n - 1, vel: None })
                }
                Dof::Dynamic => {
                    n += 2;
                    Some(Slot {
                        pos: n - 2,
                        vel: Some(n - 1),
                    })
                }
            }
        };
        let stage = match d.stage {
            Dof::Dynamic => slot(Dof::Dynamic),
            _ => None,
        };
        let cant = if d.cantilever == Dof::Off {
            Dof::QuasiStatic
        } else {
            d.cantilever
        };
        let zeta_y = slot(cant).expect("cantilever is present");
        let zeta_z = slot(cant).expect("cantilever is present");
        let py = if d.particle_y == Dof::Off {
            Dof::QuasiStatic
        } else {
            d.particle_y
        };
        let particle_y = slot(py).expect("particle y is present");
        let particle_z = slot(d.particle_z);
        let rotation = slot(d.particle_rotation);
        Layout {
            stage,
            zeta_y,
            zeta_z,
            particle_y,
            particle_z,
            rotation,
            len: n,
        }
    }

    /// The diagonal of the mass matrix `M` in `M x' = f(t, x)`: 1 for a differential row,
    /// 0 for the algebraic (force-balance) row of a quasi-static DOF.
    pub fn mass_diagonal(&self) -> [f64; MAX_STATES] {
        let mut m = [0.0; MAX_STATES];
        let slots = [
            Some(self.zeta_y),
            Some(self.zeta_z),
            Some(self.particle_y),
            self.particle_z,
            self.rotation,
            self.stage,
        ];
        for s in slots.into_iter().flatten() {
            if let Some(v) = s.vel {
                m[s.pos] = 1.0;
                m[v] = 1.0;
            }
        }
        m
    }

    /// Names of the states, in order, for traces and reports.
    pub fn names(&self) -> Vec<&'static str> {
        let mut names = vec![""; self.len];
        let mut put = |s: Option<Slot>, p: &'static str, v: &'static str| {
            if let Some(s) = s {
                names[s.pos] = p;
                if let Some(i) = s.vel {
                    names[i] = v;
                }
            }
        };
        put(self.stage, "stage_s", "stage_v");
        put(Some(self.zeta_y), "zeta_y", "zeta_y_rate");
        put(Some(self.zeta_z), "zeta_z", "zeta_z_rate");
        put(Some(self.particle_y), "particle_y", "particle_vy");
        put(self.particle_z, "particle_z", "particle_vz");
        put(self.rotation, "theta", "omega");
        names
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn left_out_dofs_are_not_in_the_state() {
        let full = Dofs {
            particle_y: Dof::Dynamic,
            particle_z: Dof::Dynamic,
            particle_rotation: Dof::Dynamic,
            cantilever: Dof::Dynamic,
            stage: Dof::Dynamic,
        };
        assert_eq!(Layout::new(&full).len, 12);
        let minimal = Dofs {
            particle_y: Dof::QuasiStatic,
            particle_z: Dof::Off,
            particle_rotation: Dof::Off,
            cantilever: Dof::QuasiStatic,
            stage: Dof::Off,
        };
        let l = Layout::new(&minimal);
        assert_eq!(l.len, 3);
        assert!(l.particle_z.is_none() && l.rotation.is_none() && l.stage.is_none());
        assert_eq!(&l.mass_diagonal()[..3], &[0.0, 0.0, 0.0]);
        assert_eq!(l.names(), vec!["zeta_y", "zeta_z", "particle_y"]);
    }
}
