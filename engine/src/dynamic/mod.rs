//! Compiled third-party plugins loaded at run time through the C ABI of
//! [`modesuite_plugin_abi`].
//!
//! Policy:
//! - A library is loaded only by an explicit request: `--plugin PATH` on the command line or
//!   [`SimApp::load_plugin`] / [`DynamicPlugin::load`]. A scene file never loads anything; a scene
//!   that names a generator or term nobody registered fails validation and says which flag would
//!   load it.
//! - The ABI version is checked first, by reading the exported `MODESUITE_PLUGIN_ABI_VERSION`
//!   static: no plugin function runs before the version matches.
//! - The declaration is validated (UTF-8 names, capability bits, function pointers, unique
//!   names) before anything is registered.
//! - Every call goes through a status code; an error or a panic (caught on the plugin side) in a
//!   term or force ends the episode with that error through `SimErrors`; the process goes on.
//!   Generator errors are scene errors.
//! - A loaded library is never unloaded (it is leaked), so every pointer it gave stays valid.
//!
//! Registered capabilities join the same registries as static plugins ([`crate::registry`]):
//! shape generators, terms ([`crate::terms::Term`]), passive forces and task events
//! ([`crate::events`]). The plugin's state slots
//! live in [`crate::state::PluginStates`] under the plugin's name, so snapshots, resets and determinism hashes
//! cover them. Callbacks may run on several threads at once (one per env).

use std::ffi::c_void;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use modesuite_plugin_abi as abi;
use nalgebra::Vector3;

mod call;
mod events;

use call::{status, Text, UserPtr};

use crate::registry::{ShapeGenerator, TermEntry, TermKind};
use crate::shapes::{GeneratedMesh, MeshKind, SurfaceMesh, VolumeMesh, MAX_ELEMENTS};
use crate::terms::{
    ConfiguredForce, ConfiguredTerm, ForceContext, PassiveForce, Term, TermContext,
};
use crate::{Plugin, SimApp};

/// Why a compiled plugin could not be loaded or added.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PluginLoadError {
    /// The file does not exist.
    #[error("plugin {path}: no such file")]
    NotFound {
        /// The path given.
        path: PathBuf,
    },
    /// The file is not a loadable shared library.
    #[error("plugin {path}: not a loadable shared library ({message})")]
    NotALibrary {
        /// The path given.
        path: PathBuf,
        /// The loader's message.
        message: String,
    },
    /// A shared library that is not a modesuite plugin.
    #[error("plugin {path}: not a modesuite plugin: it does not export `{symbol}` (a plugin is a cdylib made with modesuite_plugin_abi::declare_plugin!)")]
    NotAPlugin {
        /// The path given.
        path: PathBuf,
        /// The missing symbol.
        symbol: &'static str,
    },
    /// Built against another ABI version; nothing of it was called.
    #[error("plugin {path}: built for plugin ABI version {found}, but this modesuite expects version {expected}; rebuild the plugin against modesuite-plugin-abi with ABI_VERSION {expected}")]
    VersionMismatch {
        /// The path given.
        path: PathBuf,
        /// The version the plugin declares.
        found: u32,
        /// The host's version.
        expected: u32,
    },
    /// The plugin's declaration breaks a rule of the ABI.
    #[error("plugin {path}: invalid declaration: {message}")]
    Invalid {
        /// The path given.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A name the plugin declares is already in use.
    #[error("plugin {path}: {message}")]
    Conflict {
        /// The path of the plugin.
        path: PathBuf,
        /// Which name and where it is used.
        message: String,
    },
}

/// Copies `n * k` values from a plugin array (bounded by [`MAX_ELEMENTS`]).
fn copy_array<T: Copy>(ptr: *const T, n: usize, k: usize, what: &str) -> Result<Vec<T>, String> {
    if n as u64 > MAX_ELEMENTS {
        return Err(format!("{n} {what}: more than {MAX_ELEMENTS}"));
    }
    if n == 0 {
        return Ok(Vec::new());
    }
    if ptr.is_null() {
        return Err(format!("{n} {what} but a null pointer"));
    }
    // SAFETY: the plugin passes `n * k` values at `ptr`, valid during the sink call; `n` is
    // bounded above so the length cannot overflow.
    Ok(unsafe { std::slice::from_raw_parts(ptr, n * k) }.to_vec())
}

/// The mesh sink's host context.
struct MeshOut(Result<Option<GeneratedMesh>, String>);

fn to_vectors(flat: &[f64]) -> Vec<Vector3<f64>> {
    flat.chunks_exact(3)
        .map(|c| Vector3::new(c[0], c[1], c[2]))
        .collect()
}

extern "C" fn sink_surface(
    ctx: *mut c_void,
    positions: *const f64,
    n_vertices: usize,
    triangles: *const u32,
    n_triangles: usize,
) {
    if ctx.is_null() {
        return;
    }
    // SAFETY: `ctx` is the `MeshOut` this module passed for the duration of the call.
    let out = unsafe { &mut *ctx.cast::<MeshOut>() };
    out.0 = copy_array(positions, n_vertices, 3, "vertices").and_then(|p| {
        let t = copy_array(triangles, n_triangles, 3, "triangles")?;
        Ok(Some(GeneratedMesh::Surface(SurfaceMesh {
            positions: to_vectors(&p),
            triangles: t.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        })))
    });
}

extern "C" fn sink_volume(
    ctx: *mut c_void,
    nodes: *const f64,
    n_nodes: usize,
    tets: *const u32,
    n_tets: usize,
) {
    if ctx.is_null() {
        return;
    }
    // SAFETY: `ctx` is the `MeshOut` this module passed for the duration of the call.
    let out = unsafe { &mut *ctx.cast::<MeshOut>() };
    out.0 = copy_array(nodes, n_nodes, 3, "nodes").and_then(|p| {
        let t = copy_array(tets, n_tets, 4, "tetrahedra")?;
        Ok(Some(GeneratedMesh::Volume(VolumeMesh {
            nodes: to_vectors(&p),
            tets: t
                .chunks_exact(4)
                .map(|c| [c[0], c[1], c[2], c[3]])
                .collect(),
        })))
    });
}

type GenerateFn = extern "C" fn(
    *const c_void,
    abi::AbiStr,
    u32,
    *const abi::MeshSink,
    *const abi::TextSink,
) -> i32;
type TermConfigureFn =
    extern "C" fn(*const c_void, abi::AbiStr, *mut usize, *const abi::TextSink) -> i32;
type TermEvaluateFn = extern "C" fn(*const c_void, *const abi::TermCall) -> i32;
type ForceConfigureFn = extern "C" fn(*const c_void, abi::AbiStr, *const abi::TextSink) -> i32;
type ForceApplyFn = extern "C" fn(*const c_void, *const abi::ForceCall) -> i32;

/// A shape generator of a compiled plugin.
struct DynShape {
    plugin: String,
    name: String,
    description: String,
    user: UserPtr,
    generate: GenerateFn,
}

impl ShapeGenerator for DynShape {
    fn name(&self) -> &str {
        &self.name
    }
    fn description(&self) -> &str {
        &self.description
    }
    fn generate(&self, params_ron: &str, want: MeshKind) -> Result<GeneratedMesh, String> {
        let mut out = MeshOut(Ok(None));
        let sink = abi::MeshSink {
            ctx: (&mut out as *mut MeshOut).cast(),
            surface: sink_surface,
            volume: sink_volume,
        };
        let mut text = Text(String::new());
        let error = text.sink();
        let want = match want {
            MeshKind::Surface => abi::MESH_SURFACE,
            MeshKind::Volume => abi::MESH_VOLUME,
        };
        let code = (self.generate)(
            self.user.0,
            abi::AbiStr::new(params_ron),
            want,
            &sink,
            &error,
        );
        status(&self.plugin, "generate", code, text)?;
        out.0?
            .ok_or_else(|| "returned no mesh (the plugin reported success)".to_string())
    }
}

/// The functions of one term of a compiled plugin.
struct DynTerm {
    plugin: String,
    kind: TermKind,
    user: UserPtr,
    configure: TermConfigureFn,
    evaluate: TermEvaluateFn,
}

/// A plugin term with its parameters.
struct DynConfiguredTerm {
    term: Arc<DynTerm>,
    params: String,
    dim: usize,
}

impl Term for Arc<DynTerm> {
    fn configure(&self, params_ron: &str) -> Result<Arc<dyn ConfiguredTerm>, String> {
        let mut dim = 0usize;
        let mut text = Text(String::new());
        let error = text.sink();
        let code = (self.configure)(self.user.0, abi::AbiStr::new(params_ron), &mut dim, &error);
        status(&self.plugin, "configure", code, text)?;
        if self.kind != TermKind::Observation && dim != 1 {
            return Err(format!(
                "the plugin says the term has {dim} values; {:?} terms have exactly 1",
                self.kind
            ));
        }
        if dim as u64 > MAX_ELEMENTS {
            return Err(format!("the plugin says the term has {dim} values"));
        }
        Ok(Arc::new(DynConfiguredTerm {
            term: self.clone(),
            params: params_ron.to_string(),
            dim,
        }))
    }
}

/// The C view of a world: the flat arrays and object views it points into.
struct AbiWorld {
    _nodes: Vec<Vec<f64>>,
    _objects: Vec<abi::ObjectView>,
    view: abi::WorldView,
}

fn quat_xyzw(q: &nalgebra::UnitQuaternion<f64>) -> [f64; 4] {
    let q = q.quaternion();
    [q.i, q.j, q.k, q.w]
}

fn flatten(v: &[Vector3<f64>]) -> Vec<f64> {
    v.iter().flat_map(|p| [p.x, p.y, p.z]).collect()
}

impl AbiWorld {
    fn new(world: &crate::terms::WorldView) -> Self {
        let nodes: Vec<Vec<f64>> = world.objects.iter().map(|o| flatten(o.nodes)).collect();
        let objects: Vec<abi::ObjectView> = world
            .objects
            .iter()
            .zip(&nodes)
            .map(|(o, flat)| {
                let (jp, jv, nj) = match o.joints {
                    Some(j) => {
                        let n = j.positions.len().min(j.velocities.len());
                        (j.positions.as_ptr(), j.velocities.as_ptr(), n)
                    }
                    None => (std::ptr::null(), std::ptr::null(), 0),
                };
                let t = o.pose.translation.vector;
                abi::ObjectView {
                    name: abi::AbiStr::new(o.name),
                    kind: abi::AbiStr::new(o.kind),
                    position: [t.x, t.y, t.z],
                    orientation: quat_xyzw(&o.pose.rotation),
                    linear_velocity: o.linear_velocity.into(),
                    angular_velocity: o.angular_velocity.into(),
                    nodes: if flat.is_empty() {
                        std::ptr::null()
                    } else {
                        flat.as_ptr()
                    },
                    n_nodes: flat.len() / 3,
                    joint_positions: jp,
                    joint_velocities: jv,
                    n_joints: nj,
                }
            })
            .collect();
        // The vectors' heap buffers do not move when the vectors are moved into `Self`.
        let view = abi::WorldView {
            time: world.time,
            step_dt: world.step_dt,
            episode_steps: world.episode_steps,
            objects: objects.as_ptr(),
            n_objects: objects.len(),
        };
        Self {
            _nodes: nodes,
            _objects: objects,
            view,
        }
    }
}

impl ConfiguredTerm for DynConfiguredTerm {
    fn dim(&self) -> usize {
        self.dim
    }
    fn evaluate(&self, ctx: &mut TermContext, out: &mut [f64]) -> Result<(), String> {
        let world = AbiWorld::new(ctx.world);
        let state = ctx.states.get_mut(&self.term.plugin);
        let mut text = Text(String::new());
        let call = abi::TermCall {
            world: &world.view,
            params: abi::AbiStr::new(&self.params),
            state: state.as_mut_ptr(),
            state_len: state.len(),
            out: out.as_mut_ptr(),
            out_len: out.len().min(self.dim),
            error: text.sink(),
        };
        let code = (self.term.evaluate)(self.term.user.0, &call);
        status(&self.term.plugin, "evaluate", code, text)
    }
}

/// A passive force of a compiled plugin.
struct DynForce {
    plugin: String,
    name: String,
    description: String,
    user: UserPtr,
    configure: ForceConfigureFn,
    apply: ForceApplyFn,
}

/// A plugin force with its parameters.
struct DynConfiguredForce {
    force: Arc<DynForce>,
    params: String,
}

impl PassiveForce for Arc<DynForce> {
    fn name(&self) -> &str {
        &self.name
    }
    fn description(&self) -> &str {
        &self.description
    }
    fn configure(&self, params_ron: &str) -> Result<Arc<dyn ConfiguredForce>, String> {
        let mut text = Text(String::new());
        let error = text.sink();
        let code = (self.configure)(self.user.0, abi::AbiStr::new(params_ron), &error);
        status(&self.plugin, "configure", code, text)?;
        Ok(Arc::new(DynConfiguredForce {
            force: self.clone(),
            params: params_ron.to_string(),
        }))
    }
}

impl ConfiguredForce for DynConfiguredForce {
    fn add_forces(
        &self,
        ctx: &mut ForceContext,
        forces: &mut [Vector3<f64>],
    ) -> Result<(), String> {
        let nodes = flatten(ctx.nodes);
        let velocities = ctx.velocities.map(flatten);
        let mut flat = flatten(forces);
        let state = ctx.states.get_mut(&self.force.plugin);
        let mut text = Text(String::new());
        let call = abi::ForceCall {
            object: abi::AbiStr::new(ctx.object),
            time: ctx.time,
            dt: ctx.dt,
            nodes: nodes.as_ptr(),
            velocities: velocities.as_ref().map_or(std::ptr::null(), |v| v.as_ptr()),
            n_nodes: ctx.nodes.len().min(forces.len()),
            params: abi::AbiStr::new(&self.params),
            state: state.as_mut_ptr(),
            state_len: state.len(),
            forces: flat.as_mut_ptr(),
            error: text.sink(),
        };
        let code = (self.force.apply)(self.force.user.0, &call);
        status(&self.force.plugin, "apply", code, text)?;
        for (f, c) in forces.iter_mut().zip(flat.chunks_exact(3)) {
            *f = Vector3::new(c[0], c[1], c[2]);
        }
        Ok(())
    }
}

/// A loaded compiled plugin: its declaration read into host types. Add it to every env's app
/// (it is a [`Plugin`]); loading once and sharing the `Arc` is cheaper than loading per env.
pub struct DynamicPlugin {
    name: String,
    description: String,
    path: PathBuf,
    state_len: usize,
    shapes: Vec<Arc<DynShape>>,
    terms: Vec<(String, String, Arc<DynTerm>)>,
    forces: Vec<Arc<DynForce>>,
    /// Task events: name, description, event.
    events: Vec<(String, String, Arc<events::DynEvent>)>,
}

impl std::fmt::Debug for DynamicPlugin {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DynamicPlugin")
            .field("name", &self.name)
            .field("path", &self.path)
            .field("names", &self.names())
            .field("state_len", &self.state_len)
            .finish()
    }
}

/// Reads a string of the declaration.
fn decl_str(s: abi::AbiStr, what: &str) -> Result<String, String> {
    if s.len > 0 && s.ptr.is_null() {
        return Err(format!("{what}: null pointer"));
    }
    // SAFETY: strings of a declaration stay valid for the life of the (never unloaded) library.
    unsafe { s.as_str() }
        .map(str::to_string)
        .map_err(|e| format!("{what}: not UTF-8 ({e})"))
}

fn decl_name(s: abi::AbiStr, what: &str) -> Result<String, String> {
    let name = decl_str(s, what)?;
    if name.trim().is_empty() || name.chars().any(char::is_whitespace) {
        return Err(format!(
            "{what} = {name:?}: a non-empty name without spaces"
        ));
    }
    Ok(name)
}

/// Reads an array of the declaration.
fn decl_slice<'a, T>(ptr: *const T, n: usize, what: &str) -> Result<&'a [T], String> {
    if n == 0 {
        return Ok(&[]);
    }
    if ptr.is_null() || n > 100_000 {
        return Err(format!("{what}: {n} entries at an invalid address"));
    }
    // SAFETY: arrays of a declaration hold `n` entries and stay valid for the life of the
    // (never unloaded) library.
    Ok(unsafe { std::slice::from_raw_parts(ptr, n) })
}

impl DynamicPlugin {
    /// Loads a compiled plugin: checks the file, reads the ABI version (and refuses a mismatch
    /// before calling anything), calls the entry and validates the declaration. The library is
    /// never unloaded.
    pub fn load(path: impl AsRef<Path>) -> Result<Arc<Self>, PluginLoadError> {
        let path = path.as_ref().to_path_buf();
        if !path.is_file() {
            return Err(PluginLoadError::NotFound { path });
        }
        // SAFETY: loading runs the library's initialisers; we load only a file the user named
        // explicitly (`--plugin PATH` or an API call), never because a scene mentions it.
        let lib = unsafe { libloading::Library::new(&path) }.map_err(|e| {
            PluginLoadError::NotALibrary {
                path: path.clone(),
                message: e.to_string(),
            }
        })?;
        // SAFETY: the symbol, when present, is the `u32` static the ABI defines; reading it runs
        // no plugin code.
        let found = match unsafe { lib.get::<*const u32>(abi::VERSION_SYMBOL) } {
            Ok(sym) if !sym.is_null() => {
                // SAFETY: a non-null address of the exported `u32` static.
                unsafe { std::ptr::read_unaligned(*sym) }
            }
            _ => {
                return Err(PluginLoadError::NotAPlugin {
                    path,
                    symbol: abi::VERSION_SYMBOL,
                })
            }
        };
        if found != abi::ABI_VERSION {
            return Err(PluginLoadError::VersionMismatch {
                path,
                found,
                expected: abi::ABI_VERSION,
            });
        }
        // SAFETY: with a matching version, the entry symbol has the ABI's entry type.
        let entry: abi::EntryFn = match unsafe { lib.get::<abi::EntryFn>(abi::ENTRY_SYMBOL) } {
            Ok(sym) => *sym,
            Err(_) => {
                return Err(PluginLoadError::NotAPlugin {
                    path,
                    symbol: abi::ENTRY_SYMBOL,
                })
            }
        };
        // Never unloaded: every pointer the plugin hands out stays valid for the process.
        std::mem::forget(lib);
        let decl = entry();
        if decl.is_null() {
            return Err(PluginLoadError::Invalid {
                path,
                message: "the entry returned no declaration (building it failed in the plugin)"
                    .into(),
            });
        }
        // SAFETY: a non-null declaration stays valid for the life of the library (never unloaded).
        let decl = unsafe { &*decl };
        Self::from_decl(decl, &path).map_err(|message| PluginLoadError::Invalid {
            path: path.clone(),
            message,
        })
    }

    fn from_decl(decl: &abi::PluginDecl, path: &Path) -> Result<Arc<Self>, String> {
        if decl.abi_version != abi::ABI_VERSION {
            return Err(format!(
                "the declaration says ABI version {}, the version symbol {}",
                decl.abi_version,
                abi::ABI_VERSION
            ));
        }
        let name = decl_name(decl.name, "name")?;
        let description = decl_str(decl.description, "description")?;
        let unknown = decl.capabilities & !abi::caps::ALL;
        if unknown != 0 {
            return Err(format!(
                "capability bits {unknown:#x} are unknown to this modesuite (ABI version {}); it needs a newer modesuite",
                abi::ABI_VERSION
            ));
        }
        if decl.state_len > 1 << 24 {
            return Err(format!(
                "state_len = {}: at most {} slots",
                decl.state_len,
                1 << 24
            ));
        }
        let mut caps = 0u64;
        let mut names = std::collections::BTreeSet::new();
        let mut unique = |n: &str| -> Result<(), String> {
            if names.insert(n.to_string()) {
                Ok(())
            } else {
                Err(format!("the name {n:?} is declared twice"))
            }
        };
        let mut shapes = Vec::new();
        for (i, s) in decl_slice(decl.shapes, decl.n_shapes, "shapes")?
            .iter()
            .enumerate()
        {
            let n = decl_name(s.name, &format!("shapes[{i}].name"))?;
            unique(&n)?;
            caps |= abi::caps::SHAPE_GENERATOR;
            shapes.push(Arc::new(DynShape {
                plugin: name.clone(),
                description: decl_str(s.description, &format!("shapes[{i}].description"))?,
                user: UserPtr(s.user),
                generate: s
                    .generate
                    .ok_or_else(|| format!("shapes[{i}] {n:?}: no generate function"))?,
                name: n,
            }));
        }
        let mut terms = Vec::new();
        for (i, t) in decl_slice(decl.terms, decl.n_terms, "terms")?
            .iter()
            .enumerate()
        {
            let n = decl_name(t.name, &format!("terms[{i}].name"))?;
            unique(&n)?;
            let (kind, bit) = match t.kind {
                abi::TERM_OBSERVATION => (TermKind::Observation, abi::caps::OBSERVATION_TERM),
                abi::TERM_REWARD => (TermKind::Reward, abi::caps::REWARD_TERM),
                abi::TERM_TERMINATION => (TermKind::Termination, abi::caps::TERMINATION_TERM),
                other => return Err(format!("terms[{i}] {n:?}: unknown kind {other}")),
            };
            caps |= bit;
            let term = DynTerm {
                plugin: name.clone(),
                kind,
                user: UserPtr(t.user),
                configure: t
                    .configure
                    .ok_or_else(|| format!("terms[{i}] {n:?}: no configure function"))?,
                evaluate: t
                    .evaluate
                    .ok_or_else(|| format!("terms[{i}] {n:?}: no evaluate function"))?,
            };
            let description = decl_str(t.description, &format!("terms[{i}].description"))?;
            terms.push((n, description, Arc::new(term)));
        }
        let mut forces = Vec::new();
        for (i, f) in decl_slice(decl.forces, decl.n_forces, "forces")?
            .iter()
            .enumerate()
        {
            let n = decl_name(f.name, &format!("forces[{i}].name"))?;
            unique(&n)?;
            caps |= abi::caps::PASSIVE_FORCE;
            forces.push(Arc::new(DynForce {
                plugin: name.clone(),
                description: decl_str(f.description, &format!("forces[{i}].description"))?,
                user: UserPtr(f.user),
                configure: f
                    .configure
                    .ok_or_else(|| format!("forces[{i}] {n:?}: no configure function"))?,
                apply: f
                    .apply
                    .ok_or_else(|| format!("forces[{i}] {n:?}: no apply function"))?,
                name: n,
            }));
        }
        let mut events = Vec::new();
        for (i, e) in decl_slice(decl.events, decl.n_events, "events")?
            .iter()
            .enumerate()
        {
            let n = decl_name(e.name, &format!("events[{i}].name"))?;
            unique(&n)?;
            caps |= abi::caps::EVENT;
            let event = events::DynEvent {
                plugin: name.clone(),
                user: UserPtr(e.user),
                configure: e
                    .configure
                    .ok_or_else(|| format!("events[{i}] {n:?}: no configure function"))?,
                apply: e
                    .apply
                    .ok_or_else(|| format!("events[{i}] {n:?}: no apply function"))?,
            };
            let description = decl_str(e.description, &format!("events[{i}].description"))?;
            events.push((n, description, Arc::new(event)));
        }
        if caps != decl.capabilities {
            return Err(format!(
                "capability bits {:#x} do not match what it declares ({caps:#x})",
                decl.capabilities
            ));
        }
        Ok(Arc::new(Self {
            name,
            description,
            path: path.to_path_buf(),
            state_len: decl.state_len,
            shapes,
            terms,
            forces,
            events,
        }))
    }

    /// The plugin's name.
    pub fn plugin_name(&self) -> &str {
        &self.name
    }

    /// The plugin's one-line description.
    pub fn description(&self) -> &str {
        &self.description
    }

    /// The file it was loaded from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Number of f64 state slots it keeps per env.
    pub fn state_len(&self) -> usize {
        self.state_len
    }

    /// Every registry name it declares (generators, terms, forces, events).
    pub fn names(&self) -> Vec<String> {
        self.shapes
            .iter()
            .map(|s| s.name.clone())
            .chain(self.terms.iter().map(|t| t.0.clone()))
            .chain(self.forces.iter().map(|f| f.name.clone()))
            .chain(self.events.iter().map(|e| e.0.clone()))
            .collect()
    }
}

impl Plugin for DynamicPlugin {
    fn name(&self) -> &str {
        &self.name
    }

    fn build(&self, app: &mut SimApp) {
        if self.state_len > 0 {
            app.declare_plugin_state(&self.name, self.state_len);
        }
        for s in &self.shapes {
            app.register_shape(s.clone());
        }
        for (name, description, term) in &self.terms {
            app.register_term(TermEntry::new(
                name.clone(),
                term.kind,
                description.clone(),
                Arc::new(term.clone()),
            ));
        }
        for f in &self.forces {
            app.register_passive_force(Arc::new(f.clone()));
        }
        for (name, description, event) in &self.events {
            app.register_term(TermEntry::event(
                name.clone(),
                description.clone(),
                Arc::new(event.clone()),
            ));
        }
    }
}

impl SimApp {
    /// Loads a compiled plugin from `path` ([`DynamicPlugin::load`]) and adds it to this app.
    /// To build several envs, load once and call [`SimApp::add_dynamic_plugin`] on each app.
    pub fn load_plugin(
        &mut self,
        path: impl AsRef<Path>,
    ) -> Result<Arc<DynamicPlugin>, PluginLoadError> {
        let plugin = DynamicPlugin::load(path)?;
        self.add_dynamic_plugin(plugin.clone())?;
        Ok(plugin)
    }

    /// Adds a loaded compiled plugin; refuses one whose plugin name or registry names are
    /// already in use (a compiled plugin never replaces what another plugin registered).
    pub fn add_dynamic_plugin(
        &mut self,
        plugin: Arc<DynamicPlugin>,
    ) -> Result<&mut Self, PluginLoadError> {
        let conflict = |message: String| PluginLoadError::Conflict {
            path: plugin.path.clone(),
            message,
        };
        if self.has_plugin(&plugin.name) {
            return Err(conflict(format!(
                "a plugin named \"{}\" is already added",
                plugin.name
            )));
        }
        for n in plugin.names() {
            if let Some(what) = self.registry().name_in_use(&n) {
                return Err(conflict(format!(
                    "\"{n}\" is already registered as a {what} by another plugin"
                )));
            }
        }
        Ok(self.add_plugins(vec![plugin as Arc<dyn Plugin>]))
    }
}
