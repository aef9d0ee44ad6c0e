//! # modesuite-plugin-abi
//!
//! The small, versioned `#[repr(C)]` ABI through which compiled third-party plugins are loaded
//! at run time (`modesuite run --plugin PATH`, or `SimApp::load_plugin`).
//!
//! Rust-ABI dylibs are unsound across compiler and crate versions, so the boundary between the
//! simulator and a plugin is plain C: fixed-layout structs, function pointers, UTF-8 strings as
//! pointer + length, and integer status codes. This crate has no dependencies.
//!
//! ## What a plugin exports
//!
//! Two symbols (both written by [`declare_plugin!`]):
//! - [`VERSION_SYMBOL`] (`MODESUITE_PLUGIN_ABI_VERSION`), a `u32` static holding the
//!   [`ABI_VERSION`] the plugin was built against. The host **reads** it (no plugin code runs) and
//!   refuses the library when it differs from its own version, before anything else.
//! - [`ENTRY_SYMBOL`] (`modesuite_plugin_entry`), an `extern "C" fn() -> *const PluginDecl`
//!   returning the plugin's declaration: its name, [capability bits](caps), the number of `f64`
//!   state slots it keeps per environment, and its shape generators, terms and passive forces.
//!
//! ## Capabilities
//!
//! - **Shape generator** ([`ShapeDecl`]): RON parameters in (UTF-8), a surface or volume mesh
//!   out. The plugin hands the mesh to a host-provided [`MeshSink`], which copies it during the
//!   call: no memory ever changes owner across the boundary, so the two sides may use different
//!   allocators.
//! - **Observation, reward and termination terms** ([`TermDecl`]): `configure` validates the
//!   parameters once (when the scene is compiled) and says how many values the term writes;
//!   `evaluate` reads a [`WorldView`] (object poses and velocities, deformable node arrays, joint
//!   state) and writes into a host-owned `f64` buffer. A termination ends the episode when its
//!   value is non-zero; a reward is multiplied by its weight.
//! - **Passive force on deformables** ([`ForceDecl`]): called every substep for each deformable
//!   object the scene applies it to, with the object's current nodes (and velocities when the
//!   solver has them); it adds forces (N, world frame) into a zeroed host buffer.
//! - **Task events** ([`EventDecl`], since version 2): a task section runs them at reset, at
//!   startup or on an interval; they draw from the environment's random stream and push, move
//!   or re-rub objects through host functions ([`EventHost`]).
//!
//! ## State, errors, panics
//!
//! A plugin that keeps state declares `state_len`; each environment gets that many `f64`
//! slots (zero at the start), passed to every term and force call. The host owns the slots and
//! saves them in the environment's snapshot, so reset and determinism checks cover them: a
//! plugin must keep **all** of its mutable state there (no globals). Callbacks are called from
//! several threads at once (one environment per thread) and must be thread-safe.
//!
//! Every callback returns [`STATUS_OK`], [`STATUS_ERROR`] or [`STATUS_PANIC`] and reports a
//! message through the host's [`TextSink`]. A panic must never unwind across `extern "C"` (that
//! aborts the process): the callbacks written by [`declare_plugin!`] run the author's code inside
//! `catch_unwind` and turn a panic into [`STATUS_PANIC`]. The host then ends the episode with an
//! error; the process goes on. Plugins built with `panic = "abort"` abort instead.
//!
//! ## Writing a plugin in Rust
//!
//! Make a `cdylib` crate depending on this one, describe the plugin with the safe types of
//! [`guest`] and export it with [`declare_plugin!`]:
//!
//! ```
//! use modesuite_plugin_abi::guest::{PluginDef, TermDef, TermKind, TermContext};
//!
//! fn height(ctx: &mut TermContext) -> Result<(), String> {
//!     let object = ctx.world.object("box").ok_or("no object named \"box\"")?;
//!     ctx.out[0] = object.position()[2];
//!     Ok(())
//! }
//!
//! fn plugin() -> PluginDef {
//!     PluginDef {
//!         name: "acme",
//!         description: "example",
//!         state_len: 0,
//!         shapes: vec![],
//!         terms: vec![TermDef::scalar("acme.height", "height of the box, m", TermKind::Reward, height)],
//!         forces: vec![],
//!         events: vec![],
//!     }
//! }
//!
//! modesuite_plugin_abi::declare_plugin!(plugin);
//! # fn main() {}
//! ```
//!
//! Versioning: [`ABI_VERSION`] changes whenever a type or a rule of this crate changes in a way
//! that an older plugin or host would misread; there is no partial compatibility.
#![warn(missing_docs)]

use std::ffi::c_void;

pub mod guest;

/// The version of this ABI. A host loads only plugins built against the same number.
pub const ABI_VERSION: u32 = 2;

/// Name of the `u32` static holding the plugin's ABI version (read before anything else).
pub const VERSION_SYMBOL: &str = "MODESUITE_PLUGIN_ABI_VERSION";

/// Name of the entry function: `extern "C" fn() -> *const PluginDecl`.
pub const ENTRY_SYMBOL: &str = "modesuite_plugin_entry";

/// The entry function's type.
pub type EntryFn = extern "C" fn() -> *const PluginDecl;

/// Capability bits of [`PluginDecl::capabilities`]; a host refuses bits it does not know.
pub mod caps {
    /// The plugin declares shape generators.
    pub const SHAPE_GENERATOR: u64 = 1 << 0;
    /// The plugin declares observation terms.
    pub const OBSERVATION_TERM: u64 = 1 << 1;
    /// The plugin declares reward terms.
    pub const REWARD_TERM: u64 = 1 << 2;
    /// The plugin declares termination terms.
    pub const TERMINATION_TERM: u64 = 1 << 3;
    /// The plugin declares passive forces on deformables.
    pub const PASSIVE_FORCE: u64 = 1 << 4;
    /// The plugin declares task events (since version 2).
    pub const EVENT: u64 = 1 << 5;
    /// Every bit this version knows.
    pub const ALL: u64 =
        SHAPE_GENERATOR | OBSERVATION_TERM | REWARD_TERM | TERMINATION_TERM | PASSIVE_FORCE | EVENT;
}

/// The call succeeded.
pub const STATUS_OK: i32 = 0;
/// The call failed; the message went to the error sink.
pub const STATUS_ERROR: i32 = 1;
/// The plugin's code panicked (caught on the plugin side); the message went to the error sink.
pub const STATUS_PANIC: i32 = 2;

/// [`ShapeDecl::generate`]'s `want`: a triangle surface is asked for.
pub const MESH_SURFACE: u32 = 0;
/// [`ShapeDecl::generate`]'s `want`: a tetrahedral volume is asked for.
pub const MESH_VOLUME: u32 = 1;

/// [`TermDecl::kind`]: an observation term (writes `dim` values).
pub const TERM_OBSERVATION: u32 = 1;
/// [`TermDecl::kind`]: a reward term (writes one value).
pub const TERM_REWARD: u32 = 2;
/// [`TermDecl::kind`]: a termination term (writes one value; non-zero ends the episode).
pub const TERM_TERMINATION: u32 = 3;

/// A borrowed UTF-8 string: pointer and length in bytes (not NUL-terminated).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct AbiStr {
    /// First byte (may dangle when `len` is 0).
    pub ptr: *const u8,
    /// Length in bytes.
    pub len: usize,
}

impl AbiStr {
    /// Borrows a Rust string (valid as long as `s` is).
    pub const fn new(s: &str) -> Self {
        Self {
            ptr: s.as_ptr(),
            len: s.len(),
        }
    }

    /// Reads the string.
    ///
    /// # Safety
    /// `ptr` must point to `len` readable bytes that stay valid and unchanged for `'a`
    /// (or `len` must be 0).
    pub unsafe fn as_str<'a>(self) -> Result<&'a str, std::str::Utf8Error> {
        if self.len == 0 {
            return Ok("");
        }
        // SAFETY: the caller guarantees `len` readable bytes at `ptr` for `'a`.
        let bytes = unsafe { std::slice::from_raw_parts(self.ptr, self.len) };
        std::str::from_utf8(bytes)
    }
}

/// Where a callback writes a message (errors). Provided by the host, valid during the call.
#[repr(C)]
pub struct TextSink {
    /// Host context, passed back to `write`.
    pub ctx: *mut c_void,
    /// Appends text (copied by the host during the call).
    pub write: extern "C" fn(ctx: *mut c_void, text: AbiStr),
}

/// Where a shape generator puts its mesh. Provided by the host, valid during the call; the
/// host copies the arrays before the function returns.
#[repr(C)]
pub struct MeshSink {
    /// Host context, passed back to the functions.
    pub ctx: *mut c_void,
    /// A triangle surface: `positions` is `3 * n_vertices` f64 (x, y, z; m; shape frame),
    /// `triangles` is `3 * n_triangles` vertex indices, counter-clockwise seen from outside.
    pub surface: extern "C" fn(
        ctx: *mut c_void,
        positions: *const f64,
        n_vertices: usize,
        triangles: *const u32,
        n_triangles: usize,
    ),
    /// A tetrahedral volume: `nodes` is `3 * n_nodes` f64, `tets` is `4 * n_tets` node indices,
    /// positively oriented (`det[x1 - x0, x2 - x0, x3 - x0] > 0`).
    pub volume: extern "C" fn(
        ctx: *mut c_void,
        nodes: *const f64,
        n_nodes: usize,
        tets: *const u32,
        n_tets: usize,
    ),
}

/// One object of the scene, as a plugin sees it (read-only, valid during the call).
#[repr(C)]
pub struct ObjectView {
    /// Unique name from the scene.
    pub name: AbiStr,
    /// Body kind: `static`, `dynamic`, `kinematic` or a plugin kind such as `fem.solid`.
    pub kind: AbiStr,
    /// Position of the body frame, m, world frame (for deformables: where they were spawned).
    pub position: [f64; 3],
    /// Orientation of the body frame, unit quaternion (x, y, z, w).
    pub orientation: [f64; 4],
    /// Linear velocity, m/s, world frame (zero for bodies without one).
    pub linear_velocity: [f64; 3],
    /// Angular velocity, rad/s, world frame (zero for bodies without one).
    pub angular_velocity: [f64; 3],
    /// Deformable node positions: `3 * n_nodes` f64, m, world frame (null when `n_nodes` is 0).
    pub nodes: *const f64,
    /// Number of deformable nodes (0 for rigid bodies).
    pub n_nodes: usize,
    /// Joint positions (rad or m): `n_joints` f64 (null when `n_joints` is 0).
    pub joint_positions: *const f64,
    /// Joint velocities: `n_joints` f64 (null when `n_joints` is 0).
    pub joint_velocities: *const f64,
    /// Number of joints (0 for objects that are not articulated).
    pub n_joints: usize,
}

/// The read-only world a term evaluates on (valid during the call).
#[repr(C)]
pub struct WorldView {
    /// Simulated time since the episode started, s.
    pub time: f64,
    /// Length of one env step, s (physics dt x decimation).
    pub step_dt: f64,
    /// Env steps since the episode started.
    pub episode_steps: u64,
    /// The objects, in scene order.
    pub objects: *const ObjectView,
    /// Number of objects.
    pub n_objects: usize,
}

/// Arguments of [`TermDecl::evaluate`] (valid during the call).
#[repr(C)]
pub struct TermCall {
    /// The world.
    pub world: *const WorldView,
    /// The term's parameters from the scene, RON text.
    pub params: AbiStr,
    /// The plugin's state slots in this environment (read-write).
    pub state: *mut f64,
    /// Number of state slots (the plugin's `state_len`).
    pub state_len: usize,
    /// Where the term writes its values (zeroed by the host).
    pub out: *mut f64,
    /// Number of values: the `dim` returned by `configure` (1 for rewards and terminations).
    pub out_len: usize,
    /// Where an error message goes.
    pub error: TextSink,
}

/// Arguments of [`ForceDecl::apply`] (valid during the call).
#[repr(C)]
pub struct ForceCall {
    /// The deformable object's name.
    pub object: AbiStr,
    /// Simulated time at the start of this substep, s.
    pub time: f64,
    /// Length of the substep, s.
    pub dt: f64,
    /// Current node positions: `3 * n_nodes` f64, m, world frame.
    pub nodes: *const f64,
    /// Current node velocities: `3 * n_nodes` f64, m/s, or null when the solver has none.
    pub velocities: *const f64,
    /// Number of nodes.
    pub n_nodes: usize,
    /// The force's parameters from the scene, RON text.
    pub params: AbiStr,
    /// The plugin's state slots in this environment (read-write).
    pub state: *mut f64,
    /// Number of state slots.
    pub state_len: usize,
    /// Forces to add to: `3 * n_nodes` f64, N, world frame (zeroed by the host, shared by every
    /// force on this object in scene order).
    pub forces: *mut f64,
    /// Where an error message goes.
    pub error: TextSink,
}

/// A shape generator (RON `Gen(name: "...", params: (...))`).
#[repr(C)]
pub struct ShapeDecl {
    /// Registry name, e.g. `acme.trefoil`.
    pub name: AbiStr,
    /// One line for `modesuite list`.
    pub description: AbiStr,
    /// Plugin context, passed back to `generate`.
    pub user: *const c_void,
    /// Builds the mesh from RON `params`; `want` is [`MESH_SURFACE`] or [`MESH_VOLUME`]
    /// (a volume is fine when a surface is wanted: its boundary is used).
    pub generate: Option<
        extern "C" fn(
            user: *const c_void,
            params: AbiStr,
            want: u32,
            mesh: *const MeshSink,
            error: *const TextSink,
        ) -> i32,
    >,
}

/// An observation, reward or termination term.
#[repr(C)]
pub struct TermDecl {
    /// Registry name, e.g. `acme.tube_height`.
    pub name: AbiStr,
    /// One line for `modesuite list`.
    pub description: AbiStr,
    /// [`TERM_OBSERVATION`], [`TERM_REWARD`] or [`TERM_TERMINATION`].
    pub kind: u32,
    /// Plugin context, passed back to the functions.
    pub user: *const c_void,
    /// Validates the parameters (once, when a scene is compiled) and writes the number of values
    /// the term produces to `dim` (must be 1 for rewards and terminations).
    pub configure: Option<
        extern "C" fn(
            user: *const c_void,
            params: AbiStr,
            dim: *mut usize,
            error: *const TextSink,
        ) -> i32,
    >,
    /// Evaluates the term.
    pub evaluate: Option<extern "C" fn(user: *const c_void, call: *const TermCall) -> i32>,
}

/// A passive force on deformable nodes.
#[repr(C)]
pub struct ForceDecl {
    /// Registry name, e.g. `acme.wind`.
    pub name: AbiStr,
    /// One line for `modesuite list`.
    pub description: AbiStr,
    /// Plugin context, passed back to the functions.
    pub user: *const c_void,
    /// Validates the parameters (once, when a scene is compiled).
    pub configure:
        Option<extern "C" fn(user: *const c_void, params: AbiStr, error: *const TextSink) -> i32>,
    /// Adds forces for one object and one substep.
    pub apply: Option<extern "C" fn(user: *const c_void, call: *const ForceCall) -> i32>,
}

/// What an event may do to one environment: host functions, valid during the call. Every
/// function that can fail returns a status and writes its message to `error`.
#[repr(C)]
pub struct EventHost {
    /// Host context, passed back to the functions.
    pub ctx: *mut c_void,
    /// A uniform number in `[lo, hi)` from the environment's random stream (draw everything
    /// from here, so episodes stay reproducible).
    pub uniform: extern "C" fn(ctx: *mut c_void, lo: f64, hi: f64) -> f64,
    /// Adds the velocity `dv` (3 f64, m/s, world frame) to every free node of a deformable
    /// object, or to a free dynamic rigid body.
    pub push: extern "C" fn(
        ctx: *mut c_void,
        object: AbiStr,
        dv: *const f64,
        error: *const TextSink,
    ) -> i32,
    /// Moves a deformable object rigidly by `pose` (7 f64: x, y, z, then the unit quaternion
    /// x, y, z, w; world frame).
    pub move_object: extern "C" fn(
        ctx: *mut c_void,
        object: AbiStr,
        pose: *const f64,
        error: *const TextSink,
    ) -> i32,
    /// Sets the friction coefficient of every collider of a rigid object.
    pub set_friction: extern "C" fn(
        ctx: *mut c_void,
        object: AbiStr,
        friction: f64,
        error: *const TextSink,
    ) -> i32,
}

/// Arguments of [`EventDecl::apply`] (valid during the call).
#[repr(C)]
pub struct EventCall {
    /// The event's parameters from the task section, RON text.
    pub params: AbiStr,
    /// The event's key in the task's `events` map.
    pub name: AbiStr,
    /// What the event may do.
    pub host: *const EventHost,
    /// Where an error message goes.
    pub error: TextSink,
}

/// A task event (a task section's `Event(event: "...", params: (...))`, at reset, at startup or
/// on an interval): randomises or perturbs one environment through [`EventHost`].
#[repr(C)]
pub struct EventDecl {
    /// Registry name, e.g. `acme.nudge`.
    pub name: AbiStr,
    /// One line for `modesuite list`.
    pub description: AbiStr,
    /// Plugin context, passed back to the functions.
    pub user: *const c_void,
    /// Validates the parameters (once, when a scene is compiled) and writes to `interval_safe`
    /// 1 when the event moves no body (so a task may also run it during episodes), else 0.
    pub configure: Option<
        extern "C" fn(
            user: *const c_void,
            params: AbiStr,
            interval_safe: *mut u32,
            error: *const TextSink,
        ) -> i32,
    >,
    /// Applies the event to one environment.
    pub apply: Option<extern "C" fn(user: *const c_void, call: *const EventCall) -> i32>,
}

/// What the entry function returns: everything the plugin provides. Must stay valid and
/// unchanged for the life of the process (the host never unloads a plugin).
#[repr(C)]
pub struct PluginDecl {
    /// Must equal [`ABI_VERSION`] (checked again after the version symbol).
    pub abi_version: u32,
    /// Plugin name, unique among loaded plugins, e.g. `acme`.
    pub name: AbiStr,
    /// One line for `modesuite list`.
    pub description: AbiStr,
    /// [`caps`] bits of what the plugin declares below.
    pub capabilities: u64,
    /// Number of `f64` state slots the plugin keeps per environment (0 for none).
    pub state_len: usize,
    /// Shape generators.
    pub shapes: *const ShapeDecl,
    /// Number of shape generators.
    pub n_shapes: usize,
    /// Terms.
    pub terms: *const TermDecl,
    /// Number of terms.
    pub n_terms: usize,
    /// Passive forces.
    pub forces: *const ForceDecl,
    /// Number of passive forces.
    pub n_forces: usize,
    /// Task events (since version 2).
    pub events: *const EventDecl,
    /// Number of task events.
    pub n_events: usize,
}

/// Exports a plugin: `declare_plugin!(make)` where `make` is a `fn() -> guest::PluginDef`.
///
/// Writes the [`VERSION_SYMBOL`] static and the [`ENTRY_SYMBOL`] function. `make` runs once, on
/// the first call of the entry; its result is kept for the life of the process. Every callback
/// runs the author's function inside `catch_unwind` (see [`guest`]).
#[macro_export]
macro_rules! declare_plugin {
    ($make:path) => {
        /// The plugin ABI version this library was built against (read by the host first).
        #[no_mangle]
        pub static MODESUITE_PLUGIN_ABI_VERSION: u32 = $crate::ABI_VERSION;

        /// The plugin's declaration (see `modesuite_plugin_abi::PluginDecl`).
        #[no_mangle]
        pub extern "C" fn modesuite_plugin_entry() -> *const $crate::PluginDecl {
            static DECL: ::std::sync::OnceLock<$crate::guest::Exported> =
                ::std::sync::OnceLock::new();
            DECL.get_or_init(|| $crate::guest::Exported::new($make))
                .decl()
        }
    };
}
