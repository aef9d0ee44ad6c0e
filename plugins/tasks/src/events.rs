//! Task events registered by name: a plugin adds its own reset, startup or interval event
//! (`register_task_event`), and a task section uses it as
//! `Event(event: "acme.gust", params: (...))`, alone or inside `Startup(...)` and
//! `Interval(...)`, like the built-in events. The event is configured once when the scene
//! compiles (its parameter errors are located there) and applied through an [`EventCtx`]: the
//! env's random stream, pushes, rigid moves of deformables and friction, by object name.
//! Engine events ([`modesuite_engine::events`], which compiled plugins declare through the C
//! ABI) run the same way: [`EventCtx`] is their [`EventWorld`].

use std::sync::Arc;

use modesuite_engine::events::{ConfiguredEvent, EventWorld};
use modesuite_engine::registry::{TermEntry, TermKind};
use modesuite_engine::SimApp;
use nalgebra::{Isometry3, Vector3};

use crate::terms::Configure;

/// What an event may change (implemented by the task systems' world access).
pub(crate) trait EventOps {
    /// A uniform number in `[lo, hi)` from the env's random stream.
    fn uniform(&mut self, lo: f64, hi: f64) -> f64;
    /// Adds a velocity to a deformable's nodes or to a free rigid body.
    fn push(&mut self, event: &str, object: &str, dv: Vector3<f64>) -> Result<(), String>;
    /// Moves a deformable rigidly.
    fn move_object(
        &mut self,
        event: &str,
        object: &str,
        iso: &Isometry3<f64>,
    ) -> Result<(), String>;
    /// Sets the friction coefficient of every collider of a rigid object.
    fn set_friction(&mut self, object: &str, friction: f64) -> Result<(), String>;
}

/// What an event gets when it runs in one env.
pub struct EventCtx<'a> {
    pub(crate) ops: &'a mut dyn EventOps,
    pub(crate) event: &'a str,
    pub(crate) robot: &'a str,
}

impl EventCtx<'_> {
    /// A uniform number in `[lo, hi)` from the env's random stream (the startup stream for
    /// `Startup` events): draw everything from here so episodes stay reproducible.
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.ops.uniform(lo, hi)
    }

    /// Adds `dv` (m/s, world frame) to every free node of a deformable object or to a free
    /// dynamic rigid body.
    pub fn push(&mut self, object: &str, dv: Vector3<f64>) -> Result<(), String> {
        self.ops.push(self.event, object, dv)
    }

    /// Moves a deformable object rigidly by `iso` (world frame).
    pub fn move_object(&mut self, object: &str, iso: &Isometry3<f64>) -> Result<(), String> {
        self.ops.move_object(self.event, object, iso)
    }

    /// Sets the friction coefficient of every collider of a rigid object.
    pub fn set_friction(&mut self, object: &str, friction: f64) -> Result<(), String> {
        self.ops.set_friction(object, friction)
    }

    /// The key of this event in the task's `events` map.
    pub fn name(&self) -> &str {
        self.event
    }

    /// The task's robot.
    pub fn robot(&self) -> &str {
        self.robot
    }
}

/// An engine event ([`modesuite_engine::events`]: a compiled plugin's, or one registered with
/// `TermEntry::event`) run as a task event: it acts through the same [`EventCtx`].
pub(crate) struct EngineEvent(pub(crate) Arc<dyn ConfiguredEvent>);

impl TaskEvent for EngineEvent {
    fn interval_safe(&self) -> bool {
        self.0.interval_safe()
    }

    fn apply(&self, ctx: &mut EventCtx) -> Result<(), String> {
        let name = ctx.event.to_string();
        self.0.apply(&name, ctx)
    }
}

impl EventWorld for EventCtx<'_> {
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        EventCtx::uniform(self, lo, hi)
    }
    fn push(&mut self, object: &str, dv: Vector3<f64>) -> Result<(), String> {
        EventCtx::push(self, object, dv)
    }
    fn move_object(&mut self, object: &str, iso: &Isometry3<f64>) -> Result<(), String> {
        EventCtx::move_object(self, object, iso)
    }
    fn set_friction(&mut self, object: &str, friction: f64) -> Result<(), String> {
        EventCtx::set_friction(self, object, friction)
    }
}

/// A configured event (immutable, shared by every env).
pub trait TaskEvent: Send + Sync + 'static {
    /// True when it moves no body (no teleport), so it may also run during episodes
    /// (`Interval`). Default false.
    fn interval_safe(&self) -> bool {
        false
    }
    /// Applies the event to one env; an error ends the episode with it.
    fn apply(&self, ctx: &mut EventCtx) -> Result<(), String>;
}

/// A registered event: validates its parameters and returns the configured event.
pub trait TaskEventFactory: Send + Sync + 'static {
    /// Configures from RON parameters (`()` when none were given); `cfg` checks object names.
    fn configure(&self, params: &str, cfg: &Configure) -> Result<Arc<dyn TaskEvent>, String>;
}

/// The registry payload of a task event.
#[derive(Clone)]
pub struct TaskEventEntry(pub Arc<dyn TaskEventFactory>);

/// Registers a task event under `name` (shown by `modesuite list terms`, kind `event`); a
/// second registration of the name is refused like any other term's.
pub fn register_task_event(
    app: &mut SimApp,
    name: &str,
    description: &str,
    factory: Arc<dyn TaskEventFactory>,
) {
    app.register_term(TermEntry {
        name: name.to_string(),
        kind: TermKind::Event,
        description: description.to_string(),
        payload: Arc::new(TaskEventEntry(factory)),
    });
}
