//! The pushing mechanism of Sec 2.5: parameters, state layout, the Eq 17 dynamics and the Eq 18
//! steady state.

pub mod layout;
pub mod model;
pub mod params;
pub mod simulation;
pub mod steady;
pub mod trace;

pub use layout::{Layout, MAX_STATES};
pub use model::{Drive, FrictionPhase, Mode, Probe, PushModel, SwitchKind, Switching, Tangential};
pub use params::{Dof, Dofs, Interactions, LongRange, PushParams};
pub use simulation::{Advance, RELEASE_GAP, Simulation, SimulationError, TickReport};
pub use steady::{SteadyInputs, SteadyState, steady_state};

/// The scene sections that drive the pushing model (Eq 17), named by an error of a push
/// simulation or of the estimator's prediction so that the user knows where to look.
pub const MODEL_FIELDS: &str = "the pushing model of Eq 17 is driven by the scene's [friction], [cantilever], [particles], [environment], [push] and [physics] fields";

/// The field to change when the model's integrator cannot follow a push (a strategy plan's
/// `model` refusal): a limit of the simulation, not of the instrument, named as such.
pub const MODEL_REFUSAL_FIELD: &str = "one of the model's inputs ([friction], [cantilever], [particles], [environment] or [push]): its stiff solver could not follow this push, a limit of the simulation rather than of the instrument";

/// The field to change when the model's push loses its particle (a strategy plan's `escapes`
/// refusal): the tip's push leaves the friction cones that hold the particle, so it slides or
/// rolls ahead of the tip. A steeper contact angle turns the push down into the substrate,
/// higher static friction widens the cones, an adhesive force loads the contacts beyond the
/// tip's push.
pub const ESCAPE_FIELD: &str = "push.contact_angle_deg (steeper), friction.particle_substrate_static or friction.tip_particle_static (higher), or an adhesive force (physics.van_der_waals, physics.capillary): the tip's push leaves the particle's friction cones and it slides or rolls away";
