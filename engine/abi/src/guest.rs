//! The plugin author's side: safe Rust descriptions of a plugin, turned into the C declarations
//! by [`Exported`] (which [`declare_plugin!`](crate::declare_plugin) calls).
//!
//! Authors write plain functions over safe views ([`World`], [`Object`], [`TermContext`],
//! [`ForceContext`], [`EventContext`]); the callbacks exported to the host catch panics, check UTF-8 and lengths,
//! and report errors as messages.

use std::ffi::c_void;
use std::panic::{catch_unwind, AssertUnwindSafe};

use crate::{
    caps, AbiStr, EventCall, EventDecl, EventHost, ForceCall, ForceDecl, MeshSink, ObjectView,
    PluginDecl, ShapeDecl, TermCall, TermDecl, TextSink, WorldView, ABI_VERSION, MESH_SURFACE,
    MESH_VOLUME, STATUS_ERROR, STATUS_OK, STATUS_PANIC, TERM_OBSERVATION, TERM_REWARD,
    TERM_TERMINATION,
};

/// Which mesh the host asks a generator for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MeshWant {
    /// A triangle surface (a volume is also accepted: its boundary is used).
    Surface,
    /// A tetrahedral volume.
    Volume,
}

/// A mesh returned by a generator (shape frame, metres).
#[derive(Debug, Clone, PartialEq)]
pub enum Mesh {
    /// A closed or open triangle surface, counter-clockwise seen from outside.
    Surface {
        /// Vertex positions.
        positions: Vec<[f64; 3]>,
        /// Vertex indices per triangle.
        triangles: Vec<[u32; 3]>,
    },
    /// A tetrahedral volume, positively oriented tetrahedra.
    Volume {
        /// Node positions.
        nodes: Vec<[f64; 3]>,
        /// Node indices per tetrahedron.
        tets: Vec<[u32; 4]>,
    },
}

/// What a term computes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TermKind {
    /// Observation values.
    Observation,
    /// One reward value (the scene multiplies it by its weight).
    Reward,
    /// One value; non-zero ends the episode (terminated).
    Termination,
}

/// A shape generator: `generate(params_ron, want)`.
pub struct ShapeDef {
    /// Registry name, e.g. `acme.trefoil`.
    pub name: &'static str,
    /// One line for `modesuite list`.
    pub description: &'static str,
    /// Builds the mesh; errors are messages for the scene author (name the parameter).
    pub generate: fn(params: &str, want: MeshWant) -> Result<Mesh, String>,
}

/// An observation, reward or termination term.
pub struct TermDef {
    /// Registry name.
    pub name: &'static str,
    /// One line for `modesuite list`.
    pub description: &'static str,
    /// What it computes.
    pub kind: TermKind,
    /// Validates the RON parameters when the scene is compiled and returns the number of values
    /// (must be 1 for rewards and terminations).
    pub configure: fn(params: &str) -> Result<usize, String>,
    /// Writes the values into `ctx.out`.
    pub evaluate: fn(ctx: &mut TermContext) -> Result<(), String>,
}

impl TermDef {
    /// A term writing one value whose parameters are not checked beyond being present.
    pub fn scalar(
        name: &'static str,
        description: &'static str,
        kind: TermKind,
        evaluate: fn(&mut TermContext) -> Result<(), String>,
    ) -> Self {
        Self {
            name,
            description,
            kind,
            configure: |_| Ok(1),
            evaluate,
        }
    }
}

/// A passive force on deformable nodes.
pub struct ForceDef {
    /// Registry name.
    pub name: &'static str,
    /// One line for `modesuite list`.
    pub description: &'static str,
    /// Validates the RON parameters when the scene is compiled.
    pub configure: fn(params: &str) -> Result<(), String>,
    /// Adds forces into `ctx.forces`.
    pub apply: fn(ctx: &mut ForceContext) -> Result<(), String>,
}

/// A task event: `Event(event: "name", params: (...))` in a task section.
pub struct EventDef {
    /// Registry name.
    pub name: &'static str,
    /// One line for `modesuite list`.
    pub description: &'static str,
    /// Validates the RON parameters when the scene is compiled; returns whether the event
    /// moves no body (then a task may also run it during episodes, `Interval`).
    pub configure: fn(params: &str) -> Result<bool, String>,
    /// Applies the event to one environment.
    pub apply: fn(ctx: &mut EventContext) -> Result<(), String>,
}

/// What an event's `apply` gets: its parameters and what it may do to the environment.
pub struct EventContext<'a> {
    /// The event's RON parameters from the task section (validated by `configure`).
    pub params: &'a str,
    /// The event's key in the task's `events` map.
    pub name: &'a str,
    host: &'a EventHost,
}

impl EventContext<'_> {
    /// A uniform number in `[lo, hi)` from the environment's random stream: draw everything
    /// from here so that episodes stay reproducible.
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        (self.host.uniform)(self.host.ctx, lo, hi)
    }

    /// Adds `dv` (m/s, world frame) to every free node of a deformable object or to a free
    /// dynamic rigid body.
    pub fn push(&mut self, object: &str, dv: [f64; 3]) -> Result<(), String> {
        let mut msg = String::new();
        let status = (self.host.push)(
            self.host.ctx,
            AbiStr::new(object),
            dv.as_ptr(),
            &message_sink(&mut msg),
        );
        host_result(status, msg)
    }

    /// Moves a deformable object rigidly: translation (m) and unit quaternion (x, y, z, w),
    /// world frame.
    pub fn move_object(
        &mut self,
        object: &str,
        translation: [f64; 3],
        rotation: [f64; 4],
    ) -> Result<(), String> {
        let [x, y, z] = translation;
        let [qx, qy, qz, qw] = rotation;
        let pose = [x, y, z, qx, qy, qz, qw];
        let mut msg = String::new();
        let status = (self.host.move_object)(
            self.host.ctx,
            AbiStr::new(object),
            pose.as_ptr(),
            &message_sink(&mut msg),
        );
        host_result(status, msg)
    }

    /// Sets the friction coefficient of every collider of a rigid object.
    pub fn set_friction(&mut self, object: &str, friction: f64) -> Result<(), String> {
        let mut msg = String::new();
        let status = (self.host.set_friction)(
            self.host.ctx,
            AbiStr::new(object),
            friction,
            &message_sink(&mut msg),
        );
        host_result(status, msg)
    }
}

extern "C" fn append_message(ctx: *mut c_void, text: AbiStr) {
    if ctx.is_null() {
        return;
    }
    // SAFETY: `ctx` is the `String` `message_sink` borrowed for the host call.
    let out = unsafe { &mut *ctx.cast::<String>() };
    // SAFETY: the host passes a string valid during this call.
    if let Ok(t) = unsafe { text.as_str() } {
        out.push_str(t);
    }
}

/// A sink appending the host's message to `out` (valid while `out` is borrowed).
fn message_sink(out: &mut String) -> TextSink {
    TextSink {
        ctx: (out as *mut String).cast(),
        write: append_message,
    }
}

fn host_result(status: i32, message: String) -> Result<(), String> {
    if status == STATUS_OK {
        Ok(())
    } else if message.is_empty() {
        Err(format!("the host refused (status {status})"))
    } else {
        Err(message)
    }
}

/// A whole plugin.
pub struct PluginDef {
    /// Plugin name, unique among loaded plugins (prefix of its registry names by convention).
    pub name: &'static str,
    /// One line for `modesuite list`.
    pub description: &'static str,
    /// Number of `f64` state slots per environment (zero at the start of every episode).
    pub state_len: usize,
    /// Shape generators.
    pub shapes: Vec<ShapeDef>,
    /// Terms.
    pub terms: Vec<TermDef>,
    /// Passive forces.
    pub forces: Vec<ForceDef>,
    /// Task events.
    pub events: Vec<EventDef>,
}

/// One object of the world (read-only).
#[derive(Clone, Copy)]
pub struct Object<'a> {
    raw: &'a ObjectView,
}

impl<'a> Object<'a> {
    /// Unique name.
    pub fn name(&self) -> &'a str {
        // SAFETY: the host passes UTF-8 names valid for the call ('a).
        unsafe { self.raw.name.as_str() }.unwrap_or("")
    }
    /// Body kind (`static`, `dynamic`, `kinematic`, `fem.solid`, ...).
    pub fn kind(&self) -> &'a str {
        // SAFETY: as for `name`.
        unsafe { self.raw.kind.as_str() }.unwrap_or("")
    }
    /// Position of the body frame, m, world frame.
    pub fn position(&self) -> [f64; 3] {
        self.raw.position
    }
    /// Orientation, unit quaternion (x, y, z, w).
    pub fn orientation(&self) -> [f64; 4] {
        self.raw.orientation
    }
    /// Linear velocity, m/s.
    pub fn linear_velocity(&self) -> [f64; 3] {
        self.raw.linear_velocity
    }
    /// Angular velocity, rad/s.
    pub fn angular_velocity(&self) -> [f64; 3] {
        self.raw.angular_velocity
    }
    /// Deformable node positions, m, world frame (empty for rigid bodies).
    pub fn nodes(&self) -> &'a [[f64; 3]] {
        // SAFETY: the host passes `3 * n_nodes` f64 at `nodes`, valid for the call.
        unsafe { slice(self.raw.nodes.cast::<[f64; 3]>(), self.raw.n_nodes) }
    }
    /// Joint positions (empty for objects without joints).
    pub fn joint_positions(&self) -> &'a [f64] {
        // SAFETY: the host passes `n_joints` f64 at `joint_positions`, valid for the call.
        unsafe { slice(self.raw.joint_positions, self.raw.n_joints) }
    }
    /// Joint velocities (empty for objects without joints).
    pub fn joint_velocities(&self) -> &'a [f64] {
        // SAFETY: as for `joint_positions`.
        unsafe { slice(self.raw.joint_velocities, self.raw.n_joints) }
    }
    /// Mean of the node positions for deformables, the body position otherwise.
    pub fn centroid(&self) -> [f64; 3] {
        let nodes = self.nodes();
        if nodes.is_empty() {
            return self.position();
        }
        let mut c = [0.0; 3];
        for p in nodes {
            for k in 0..3 {
                c[k] += p[k];
            }
        }
        c.map(|x| x / nodes.len() as f64)
    }
}

/// The read-only world of a term call.
#[derive(Clone, Copy)]
pub struct World<'a> {
    raw: &'a WorldView,
}

impl<'a> World<'a> {
    /// Simulated time since the episode started, s.
    pub fn time(&self) -> f64 {
        self.raw.time
    }
    /// Length of one env step, s.
    pub fn step_dt(&self) -> f64 {
        self.raw.step_dt
    }
    /// Env steps since the episode started.
    pub fn episode_steps(&self) -> u64 {
        self.raw.episode_steps
    }
    /// Every object, in scene order.
    pub fn objects(&self) -> impl Iterator<Item = Object<'a>> + 'a {
        // SAFETY: the host passes `n_objects` views at `objects`, valid for the call.
        let views = unsafe { slice(self.raw.objects, self.raw.n_objects) };
        views.iter().map(|raw| Object { raw })
    }
    /// The object of this name.
    pub fn object(&self, name: &str) -> Option<Object<'a>> {
        self.objects().find(|o| o.name() == name)
    }
}

/// What a term's `evaluate` gets.
pub struct TermContext<'a> {
    /// The world.
    pub world: World<'a>,
    /// The term's RON parameters from the scene (already validated by `configure`).
    pub params: &'a str,
    /// The plugin's state slots in this environment.
    pub state: &'a mut [f64],
    /// The values to write (zeroed; `dim` long, 1 for rewards and terminations).
    pub out: &'a mut [f64],
}

/// What a passive force's `apply` gets.
pub struct ForceContext<'a> {
    /// The deformable object's name.
    pub object: &'a str,
    /// Time at the start of the substep, s.
    pub time: f64,
    /// Substep length, s.
    pub dt: f64,
    /// Current node positions, m, world frame.
    pub nodes: &'a [[f64; 3]],
    /// Current node velocities, m/s (`None` when the solver does not expose them).
    pub velocities: Option<&'a [[f64; 3]]>,
    /// The force's RON parameters from the scene.
    pub params: &'a str,
    /// The plugin's state slots in this environment.
    pub state: &'a mut [f64],
    /// Forces to add to, N, world frame, one per node.
    pub forces: &'a mut [[f64; 3]],
}

/// Builds a shared slice from a host pointer; empty when `len` is 0 or `ptr` is null.
///
/// # Safety
/// Unless `len` is 0 or `ptr` is null, `ptr` must point to `len` valid values for `'a`.
unsafe fn slice<'a, T>(ptr: *const T, len: usize) -> &'a [T] {
    if len == 0 || ptr.is_null() {
        return &[];
    }
    // SAFETY: guaranteed by the caller.
    unsafe { std::slice::from_raw_parts(ptr, len) }
}

/// Builds a mutable slice from a host pointer; empty when `len` is 0 or `ptr` is null.
///
/// # Safety
/// Unless `len` is 0 or `ptr` is null, `ptr` must point to `len` valid values for `'a`, not
/// aliased by anything else during `'a`.
unsafe fn slice_mut<'a, T>(ptr: *mut T, len: usize) -> &'a mut [T] {
    if len == 0 || ptr.is_null() {
        return &mut [];
    }
    // SAFETY: guaranteed by the caller.
    unsafe { std::slice::from_raw_parts_mut(ptr, len) }
}

fn write_error(sink: *const TextSink, message: &str) {
    if sink.is_null() {
        return;
    }
    // SAFETY: a non-null sink comes from the host and is valid during the call.
    let sink = unsafe { &*sink };
    (sink.write)(sink.ctx, AbiStr::new(message));
}

fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "(non-string panic payload)".to_string()
    }
}

/// Runs the author's code: `Ok` -> [`STATUS_OK`], `Err` -> [`STATUS_ERROR`] with the message, a
/// panic -> [`STATUS_PANIC`] with the panic message. Nothing unwinds past this function.
fn guarded(error: *const TextSink, f: impl FnOnce() -> Result<(), String>) -> i32 {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(Ok(())) => STATUS_OK,
        Ok(Err(message)) => {
            write_error(error, &message);
            STATUS_ERROR
        }
        Err(payload) => {
            write_error(
                error,
                &format!("panicked: {}", panic_message(payload.as_ref())),
            );
            STATUS_PANIC
        }
    }
}

fn text<'a>(s: AbiStr, what: &str) -> Result<&'a str, String> {
    // SAFETY: strings passed by the host are valid during the call.
    unsafe { s.as_str() }.map_err(|e| format!("{what} are not UTF-8: {e}"))
}

extern "C" fn shape_generate(
    user: *const c_void,
    params: AbiStr,
    want: u32,
    mesh: *const MeshSink,
    error: *const TextSink,
) -> i32 {
    guarded(error, || {
        // SAFETY: `user` was set by `Exported::new` to a `ShapeDef` leaked for the process.
        let def = unsafe { &*user.cast::<ShapeDef>() };
        let params = text(params, "parameters")?;
        let want = match want {
            MESH_SURFACE => MeshWant::Surface,
            MESH_VOLUME => MeshWant::Volume,
            other => return Err(format!("unknown mesh kind {other}")),
        };
        let out = (def.generate)(params, want)?;
        if mesh.is_null() {
            return Err("no mesh sink".into());
        }
        // SAFETY: a non-null sink comes from the host and is valid during the call.
        let sink = unsafe { &*mesh };
        match &out {
            Mesh::Surface {
                positions,
                triangles,
            } => (sink.surface)(
                sink.ctx,
                positions.as_ptr().cast(),
                positions.len(),
                triangles.as_ptr().cast(),
                triangles.len(),
            ),
            Mesh::Volume { nodes, tets } => (sink.volume)(
                sink.ctx,
                nodes.as_ptr().cast(),
                nodes.len(),
                tets.as_ptr().cast(),
                tets.len(),
            ),
        }
        Ok(())
    })
}

extern "C" fn term_configure(
    user: *const c_void,
    params: AbiStr,
    dim: *mut usize,
    error: *const TextSink,
) -> i32 {
    guarded(error, || {
        // SAFETY: `user` was set by `Exported::new` to a `TermDef` leaked for the process.
        let def = unsafe { &*user.cast::<TermDef>() };
        let n = (def.configure)(text(params, "parameters")?)?;
        if def.kind != TermKind::Observation && n != 1 {
            return Err(format!(
                "configure returned {n} values; reward and termination terms have exactly 1"
            ));
        }
        if dim.is_null() {
            return Err("no place for the dimension".into());
        }
        // SAFETY: a non-null `dim` comes from the host and is writable during the call.
        unsafe { *dim = n };
        Ok(())
    })
}

extern "C" fn term_evaluate(user: *const c_void, call: *const TermCall) -> i32 {
    if call.is_null() {
        return STATUS_ERROR;
    }
    // SAFETY: a non-null call comes from the host and is valid during the call.
    let call = unsafe { &*call };
    guarded(&call.error, || {
        // SAFETY: `user` was set by `Exported::new` to a `TermDef` leaked for the process.
        let def = unsafe { &*user.cast::<TermDef>() };
        if call.world.is_null() {
            return Err("no world view".into());
        }
        let mut ctx = TermContext {
            // SAFETY: the host's world view is valid during the call.
            world: World {
                raw: unsafe { &*call.world },
            },
            params: text(call.params, "parameters")?,
            // SAFETY: the host passes `state_len` exclusive slots, valid during the call.
            state: unsafe { slice_mut(call.state, call.state_len) },
            // SAFETY: the host passes `out_len` exclusive values, valid during the call.
            out: unsafe { slice_mut(call.out, call.out_len) },
        };
        (def.evaluate)(&mut ctx)
    })
}

extern "C" fn force_configure(user: *const c_void, params: AbiStr, error: *const TextSink) -> i32 {
    guarded(error, || {
        // SAFETY: `user` was set by `Exported::new` to a `ForceDef` leaked for the process.
        let def = unsafe { &*user.cast::<ForceDef>() };
        (def.configure)(text(params, "parameters")?)
    })
}

extern "C" fn force_apply(user: *const c_void, call: *const ForceCall) -> i32 {
    if call.is_null() {
        return STATUS_ERROR;
    }
    // SAFETY: a non-null call comes from the host and is valid during the call.
    let call = unsafe { &*call };
    guarded(&call.error, || {
        // SAFETY: `user` was set by `Exported::new` to a `ForceDef` leaked for the process.
        let def = unsafe { &*user.cast::<ForceDef>() };
        let n = call.n_nodes;
        let velocities = if call.velocities.is_null() {
            None
        } else {
            // SAFETY: a non-null velocity array holds `3 * n_nodes` f64 during the call.
            Some(unsafe { slice(call.velocities.cast::<[f64; 3]>(), n) })
        };
        let mut ctx = ForceContext {
            object: text(call.object, "object name")?,
            time: call.time,
            dt: call.dt,
            // SAFETY: the host passes `3 * n_nodes` f64 positions, valid during the call.
            nodes: unsafe { slice(call.nodes.cast::<[f64; 3]>(), n) },
            velocities,
            params: text(call.params, "parameters")?,
            // SAFETY: the host passes `state_len` exclusive slots, valid during the call.
            state: unsafe { slice_mut(call.state, call.state_len) },
            // SAFETY: the host passes `3 * n_nodes` exclusive f64, valid during the call.
            forces: unsafe { slice_mut(call.forces.cast::<[f64; 3]>(), n) },
        };
        (def.apply)(&mut ctx)
    })
}

extern "C" fn event_configure(
    user: *const c_void,
    params: AbiStr,
    interval_safe: *mut u32,
    error: *const TextSink,
) -> i32 {
    guarded(error, || {
        // SAFETY: `user` was set by `Exported::new` to an `EventDef` leaked for the process.
        let def = unsafe { &*user.cast::<EventDef>() };
        let safe = (def.configure)(text(params, "parameters")?)?;
        if interval_safe.is_null() {
            return Err("no place for interval_safe".into());
        }
        // SAFETY: a non-null pointer comes from the host and is writable during the call.
        unsafe { *interval_safe = u32::from(safe) };
        Ok(())
    })
}

extern "C" fn event_apply(user: *const c_void, call: *const EventCall) -> i32 {
    if call.is_null() {
        return STATUS_ERROR;
    }
    // SAFETY: a non-null call comes from the host and is valid during the call.
    let call = unsafe { &*call };
    guarded(&call.error, || {
        // SAFETY: `user` was set by `Exported::new` to an `EventDef` leaked for the process.
        let def = unsafe { &*user.cast::<EventDef>() };
        if call.host.is_null() {
            return Err("no event host".into());
        }
        let mut ctx = EventContext {
            params: text(call.params, "parameters")?,
            name: text(call.name, "event name")?,
            // SAFETY: the host's functions are valid during the call.
            host: unsafe { &*call.host },
        };
        (def.apply)(&mut ctx)
    })
}

/// A plugin turned into its C declaration, kept for the life of the process.
///
/// Holds the address of a leaked [`PluginDecl`] (as an integer, so the value can live in a
/// `static`); 0 when building the plugin panicked.
pub struct Exported(usize);

impl Exported {
    /// Runs `make` (catching panics) and leaks the plugin and its declaration.
    pub fn new(make: fn() -> PluginDef) -> Self {
        match catch_unwind(make) {
            Ok(def) => Self(export(def) as usize),
            Err(_) => Self(0),
        }
    }

    /// The declaration (null when building the plugin failed).
    pub fn decl(&self) -> *const PluginDecl {
        self.0 as *const PluginDecl
    }
}

fn leak_slice<T: 'static>(v: Vec<T>) -> (*const T, usize) {
    let s: &'static [T] = Vec::leak(v);
    (s.as_ptr(), s.len())
}

fn export(def: PluginDef) -> *const PluginDecl {
    let def: &'static PluginDef = Box::leak(Box::new(def));
    let mut capabilities = 0;
    if !def.shapes.is_empty() {
        capabilities |= caps::SHAPE_GENERATOR;
    }
    if !def.forces.is_empty() {
        capabilities |= caps::PASSIVE_FORCE;
    }
    if !def.events.is_empty() {
        capabilities |= caps::EVENT;
    }
    for t in &def.terms {
        capabilities |= match t.kind {
            TermKind::Observation => caps::OBSERVATION_TERM,
            TermKind::Reward => caps::REWARD_TERM,
            TermKind::Termination => caps::TERMINATION_TERM,
        };
    }
    let shapes: Vec<ShapeDecl> = def
        .shapes
        .iter()
        .map(|s| ShapeDecl {
            name: AbiStr::new(s.name),
            description: AbiStr::new(s.description),
            user: (s as *const ShapeDef).cast(),
            generate: Some(shape_generate),
        })
        .collect();
    let terms: Vec<TermDecl> = def
        .terms
        .iter()
        .map(|t| TermDecl {
            name: AbiStr::new(t.name),
            description: AbiStr::new(t.description),
            kind: match t.kind {
                TermKind::Observation => TERM_OBSERVATION,
                TermKind::Reward => TERM_REWARD,
                TermKind::Termination => TERM_TERMINATION,
            },
            user: (t as *const TermDef).cast(),
            configure: Some(term_configure),
            evaluate: Some(term_evaluate),
        })
        .collect();
    let forces: Vec<ForceDecl> = def
        .forces
        .iter()
        .map(|f| ForceDecl {
            name: AbiStr::new(f.name),
            description: AbiStr::new(f.description),
            user: (f as *const ForceDef).cast(),
            configure: Some(force_configure),
            apply: Some(force_apply),
        })
        .collect();
    let events: Vec<EventDecl> = def
        .events
        .iter()
        .map(|e| EventDecl {
            name: AbiStr::new(e.name),
            description: AbiStr::new(e.description),
            user: (e as *const EventDef).cast(),
            configure: Some(event_configure),
            apply: Some(event_apply),
        })
        .collect();
    let (shapes, n_shapes) = leak_slice(shapes);
    let (events, n_events) = leak_slice(events);
    let (terms, n_terms) = leak_slice(terms);
    let (forces, n_forces) = leak_slice(forces);
    Box::leak(Box::new(PluginDecl {
        abi_version: ABI_VERSION,
        name: AbiStr::new(def.name),
        description: AbiStr::new(def.description),
        capabilities,
        state_len: def.state_len,
        shapes,
        n_shapes,
        terms,
        n_terms,
        forces,
        n_forces,
        events,
        n_events,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    extern "C" fn collect(ctx: *mut c_void, text: AbiStr) {
        // SAFETY: the tests pass a `String` as context and a valid string.
        let out = unsafe { &mut *ctx.cast::<String>() };
        out.push_str(unsafe { text.as_str() }.unwrap());
    }

    fn boom(_: &mut TermContext) -> Result<(), String> {
        panic!("boom")
    }

    fn count(ctx: &mut TermContext) -> Result<(), String> {
        ctx.state[0] += 1.0;
        ctx.out[0] = ctx.state[0] * ctx.world.time();
        Ok(())
    }

    fn plugin() -> PluginDef {
        PluginDef {
            name: "t",
            description: "test",
            state_len: 1,
            shapes: vec![],
            terms: vec![
                TermDef::scalar("t.boom", "panics", TermKind::Reward, boom),
                TermDef::scalar("t.count", "counts", TermKind::Termination, count),
            ],
            forces: vec![],
            events: vec![],
        }
    }

    fn call(decl: &TermDecl, state: &mut [f64], out: &mut [f64], msg: &mut String) -> i32 {
        let world = WorldView {
            time: 2.0,
            step_dt: 0.1,
            episode_steps: 20,
            objects: std::ptr::null(),
            n_objects: 0,
        };
        let c = TermCall {
            world: &world,
            params: AbiStr::new("()"),
            state: state.as_mut_ptr(),
            state_len: state.len(),
            out: out.as_mut_ptr(),
            out_len: out.len(),
            error: TextSink {
                ctx: (msg as *mut String).cast(),
                write: collect,
            },
        };
        (decl.evaluate.unwrap())(decl.user, &c)
    }

    #[test]
    fn exported_callbacks_run_the_terms_and_catch_panics() {
        let e = Exported::new(plugin);
        // SAFETY: the declaration was just built and is leaked.
        let decl = unsafe { &*e.decl() };
        assert_eq!(decl.abi_version, ABI_VERSION);
        assert_eq!(
            decl.capabilities,
            caps::REWARD_TERM | caps::TERMINATION_TERM
        );
        // SAFETY: `terms` holds `n_terms` declarations.
        let terms = unsafe { std::slice::from_raw_parts(decl.terms, decl.n_terms) };
        let (mut state, mut out, mut msg) = (vec![0.0], vec![0.0], String::new());
        assert_eq!(call(&terms[1], &mut state, &mut out, &mut msg), STATUS_OK);
        assert_eq!(call(&terms[1], &mut state, &mut out, &mut msg), STATUS_OK);
        assert_eq!((state[0], out[0]), (2.0, 4.0));
        let prev = std::panic::take_hook();
        std::panic::set_hook(Box::new(|_| {}));
        let status = call(&terms[0], &mut state, &mut out, &mut msg);
        std::panic::set_hook(prev);
        assert_eq!(status, STATUS_PANIC);
        assert_eq!(msg, "panicked: boom");
    }
}
