//! Events that plugins register in the engine's registry, for task sections to run at reset,
//! at startup or on an interval (`Event(event: "acme.nudge", params: (...))`).
//!
//! The engine defines what an event may do to one environment ([`EventWorld`]: the env's random
//! stream, pushes, rigid moves of deformables, friction) and how it is configured and applied
//! ([`EventFactory`], [`ConfiguredEvent`]); the tasks plugin, which owns the task section,
//! implements [`EventWorld`] over its world access and runs these events beside its own.
//! Static plugins register one with [`TermEntry::event`]; compiled (C ABI) plugins declare them
//! in their declaration ([`crate::dynamic`]).

use std::sync::Arc;

use nalgebra::{Isometry3, Vector3};

use crate::registry::{TermEntry, TermKind};

/// What an event may do to one environment.
pub trait EventWorld {
    /// A uniform number in `[lo, hi)` from the env's random stream (the startup stream for
    /// startup events): draw everything from here so that episodes stay reproducible.
    fn uniform(&mut self, lo: f64, hi: f64) -> f64;
    /// Adds `dv` (m/s, world frame) to every free node of a deformable object or to a free
    /// dynamic rigid body.
    fn push(&mut self, object: &str, dv: Vector3<f64>) -> Result<(), String>;
    /// Moves a deformable object rigidly by `iso` (world frame).
    fn move_object(&mut self, object: &str, iso: &Isometry3<f64>) -> Result<(), String>;
    /// Sets the friction coefficient of every collider of a rigid object.
    fn set_friction(&mut self, object: &str, friction: f64) -> Result<(), String>;
}

/// A configured event (immutable, shared by every env).
pub trait ConfiguredEvent: Send + Sync + 'static {
    /// True when it moves no body (no teleport), so it may also run during episodes.
    fn interval_safe(&self) -> bool;
    /// Applies the event to one env; `name` is its key in the task's `events` map. An error
    /// ends the episode with it.
    fn apply(&self, name: &str, world: &mut dyn EventWorld) -> Result<(), String>;
}

/// A registered event: validates its RON parameters (`()` when none were given) when the scene
/// compiles and returns the configured event.
pub trait EventFactory: Send + Sync + 'static {
    /// Configures the event; the error is a message for the scene author.
    fn configure(&self, params_ron: &str) -> Result<Arc<dyn ConfiguredEvent>, String>;
}

/// The registry payload of an engine event (a [`TermEntry`] of kind [`TermKind::Event`]).
#[derive(Clone)]
pub struct EventEntry(pub Arc<dyn EventFactory>);

impl TermEntry {
    /// An entry for an event (usable in task sections' `Event(event: name, ...)`).
    pub fn event(
        name: impl Into<String>,
        description: impl Into<String>,
        factory: Arc<dyn EventFactory>,
    ) -> Self {
        TermEntry {
            name: name.into(),
            kind: TermKind::Event,
            description: description.into(),
            payload: Arc::new(EventEntry(factory)),
        }
    }
}
