//! Registries: named capabilities that plugins add and scene files refer to by name.
//!
//! Nothing in the engine is a closed enum of kinds: body kinds (`fem.solid`, `pbd.cloth`),
//! shape generators (`acme.trefoil`), task terms, robots and sensors are looked up here by name,
//! so a static plugin, a dynamic (C ABI) plugin and the engine itself extend the same lists.

use std::any::Any;
use std::collections::BTreeMap;
use std::sync::Arc;

use bevy_ecs::prelude::*;

use crate::scene::{ObjectDesc, SceneError};
use crate::shapes::{GeneratedMesh, MeshKind, ShapeContext};
use crate::SimApp;

/// Compiled, immutable data of one plugin-owned body (shared between envs through `Arc`).
pub type CompiledBody = Arc<dyn Any + Send + Sync>;

/// What a body kind needs to compile one object.
pub struct BodyCompileContext<'a> {
    /// The object as written in the scene.
    pub object: &'a ObjectDesc,
    /// Path of the object for error messages, e.g. `objects[2] "rod"`.
    pub path: String,
    /// The plugin-owned parameters, as RON text (the `params:` of `Kind(...)`).
    pub params_ron: &'a str,
    /// Where mesh files resolve and which generators exist.
    pub shapes: &'a ShapeContext<'a>,
    /// Gravity and timing of the scene.
    pub settings: &'a crate::SimSettings,
    /// Friction/restitution/density of the object's material.
    pub material: &'a crate::scene::MaterialDesc,
    /// Where the scene came from (to turn parameter errors into file positions with
    /// [`crate::scene::plugin_params_error`]).
    pub source: &'a crate::scene::SceneSource,
}

impl BodyCompileContext<'_> {
    /// Parses the object's `params` into the plugin's type with the scene's RON options; errors
    /// name `objects[i] "name".body.params` and, when the text can be found in the scene file,
    /// its line and column.
    pub fn parse_params<T: serde::de::DeserializeOwned>(&self) -> Result<T, SceneError> {
        crate::scene::ron_options()
            .from_str(self.params_ron)
            .map_err(|e| {
                crate::scene::plugin_params_error(
                    self.source,
                    self.params_ron,
                    &format!("{}.body.params", self.path),
                    &e,
                )
            })
    }
}

/// A kind of body provided by a plugin (FEM solid, cloth, ...).
pub trait BodyKind: Send + Sync + 'static {
    /// Registry name, e.g. `fem.solid`.
    fn name(&self) -> &str;
    /// One line for `modesuite list`.
    fn description(&self) -> &str;
    /// Parses and validates the object's parameters and builds the immutable compiled body.
    fn compile(&self, ctx: &BodyCompileContext) -> Result<CompiledBody, SceneError>;
    /// Adds the compiled body to an env's world; `entity` already carries `Object` and `Pose`.
    fn spawn(
        &self,
        app: &mut SimApp,
        entity: Entity,
        body: &CompiledBody,
    ) -> Result<(), SceneError>;
    /// For a deformable kind: the triangles of the body's surface, as indices into its nodes
    /// (the [`DeformableNodes`](crate::components::DeformableNodes) order), outward-facing and
    /// as fine as the nodes allow. Renderers draw it and tasks measure it (covered areas), so a
    /// new solver is drawn and measured without either knowing its types. `None` (the default)
    /// for kinds without nodes.
    fn surface_triangles(&self, body: &CompiledBody) -> Option<Vec<[u32; 3]>> {
        let _ = body;
        None
    }
}

/// Compiled, immutable data of one plugin-owned scene section (shared between envs).
pub type CompiledSection = Arc<dyn Any + Send + Sync>;

/// What a scene section handler needs to compile its section of `extensions: { "key": ... }`.
pub struct SectionCompileContext<'a> {
    /// The section's key in `extensions`.
    pub key: &'a str,
    /// The section as RON text.
    pub ron: &'a str,
    /// Gravity and timing of the scene.
    pub settings: &'a crate::SimSettings,
    /// The scene's compiled objects (sections compile after the objects).
    pub objects: &'a [ObjectModel],
    /// Named frames and targets of the scene.
    pub frames: &'a BTreeMap<String, nalgebra::Isometry3<f64>>,
    /// Where the scene came from (errors map into the file).
    pub source: &'a crate::scene::SceneSource,
    /// The app's registries (terms, robots, sensors other plugins registered).
    pub registry: &'a Registry,
    /// Every section of the scene as written, by key (a section may read another's settings,
    /// e.g. the task section the cameras of the render section).
    pub extensions: &'a BTreeMap<String, Box<ron::value::RawValue>>,
    /// The cameras that the sections compiled before this one bring ([`SceneSection::cameras`];
    /// sections compile in key order, so the task section sees the robots').
    pub mounted_cameras: &'a [CameraMount],
}

impl SectionCompileContext<'_> {
    /// The RON text of another section of the scene, if it has one.
    pub fn extension(&self, key: &str) -> Option<&str> {
        self.extensions.get(key).map(|r| r.get_ron())
    }

    /// Path of the section for error messages: `extensions["key"]`.
    pub fn path(&self) -> String {
        format!("extensions[\"{}\"]", self.key)
    }

    /// Parses the section into the handler's type with the scene's RON options; errors name
    /// `extensions["key"]` and, when the text can be found in the scene file, its line and column.
    pub fn parse<T: serde::de::DeserializeOwned>(&self) -> Result<T, SceneError> {
        crate::scene::ron_options()
            .from_str(self.ron)
            .map_err(|e| crate::scene::plugin_params_error(self.source, self.ron, &self.path(), &e))
    }
}

/// A handler of one plugin-owned scene section (`extensions: { "robots": (...) }`): validated at
/// compile time like the rest of the scene, spawned into every env after the objects. A scene
/// section no handler claims is an error, so a typo never passes silently.
pub trait SceneSection: Send + Sync + 'static {
    /// The key it handles, e.g. `robots`.
    fn name(&self) -> &str;
    /// One line for `modesuite list`.
    fn description(&self) -> &str;
    /// Parses and validates the section.
    fn compile(&self, ctx: &SectionCompileContext) -> Result<CompiledSection, SceneError>;
    /// Adds the section's content to an env's world (the scene's objects already exist).
    fn spawn(&self, app: &mut SimApp, compiled: &CompiledSection) -> Result<(), SceneError>;
    /// Cameras that come with what the section spawns (a robot file's cameras), which
    /// renderers add to the scene's own; none by default.
    fn cameras(&self, _compiled: &CompiledSection) -> Vec<CameraMount> {
        Vec::new()
    }
}

/// A camera a scene section brings with what it spawns ([`SceneSection::cameras`]), such as a
/// camera a robot file mounts on one of its links. Renderers add it to the cameras of the
/// scene's render section, which wins where both name a camera alike.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraMount {
    /// Camera name, unique in the scene (a robot's are `<robot name>/<camera name>`).
    pub name: String,
    /// What it moves with: a scene object, or a robot link as `<robot name>/<link>`.
    pub attach: String,
    /// `parent_from_camera` (optical frame: x right, y down, z forward).
    pub pose: crate::scene::PoseDesc,
    /// Aim the camera at this point of the parent frame (up = parent +z) instead of `pose`'s
    /// rotation.
    pub look_at: Option<[f64; 3]>,
    /// Image width, px.
    pub width: u32,
    /// Image height, px.
    pub height: u32,
    /// Vertical field of view, degrees.
    pub fov_y_deg: f64,
}

/// A named shape generator (RON: `Gen(name: "acme.trefoil", params: (...))`).
pub trait ShapeGenerator: Send + Sync + 'static {
    /// Registry name.
    fn name(&self) -> &str;
    /// One line for `modesuite list`.
    fn description(&self) -> &str;
    /// Builds a surface or volume mesh from the RON parameters; errors are messages for the user.
    fn generate(&self, params_ron: &str, want: MeshKind) -> Result<GeneratedMesh, String>;
}

/// What a task term computes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum TermKind {
    /// Turns part of the raw action into controller inputs.
    Action,
    /// Writes part of an observation group.
    Observation,
    /// Contributes to the reward.
    Reward,
    /// Ends an episode (terminated or truncated).
    Termination,
    /// Runs at startup, reset or on an interval (randomisation).
    Event,
}

/// A named task term. The payload is owned by the plugin that defines the term protocol; terms
/// made with [`TermEntry::new`] carry an engine [`Term`](crate::terms::Term), which scene term
/// sections and the tasks plugin evaluate.
#[derive(Clone)]
pub struct TermEntry {
    /// Registry name, e.g. `distance_xy`.
    pub name: String,
    /// What the term computes.
    pub kind: TermKind,
    /// One line for `modesuite list`.
    pub description: String,
    /// The term's implementation, type-erased.
    pub payload: Arc<dyn Any + Send + Sync>,
}

impl TermEntry {
    /// An entry whose payload is an engine [`Term`](crate::terms::Term) (usable in the scene's
    /// `rewards`, `terminations` and `observations` sections).
    pub fn new(
        name: impl Into<String>,
        kind: TermKind,
        description: impl Into<String>,
        term: Arc<dyn crate::terms::Term>,
    ) -> Self {
        Self {
            name: name.into(),
            kind,
            description: description.into(),
            payload: Arc::new(term),
        }
    }

    /// The engine term of this entry, when its payload is one (see [`TermEntry::new`]).
    pub fn term(&self) -> Option<&Arc<dyn crate::terms::Term>> {
        self.payload.downcast_ref::<Arc<dyn crate::terms::Term>>()
    }
}

/// A named robot (model + controllers), type-erased payload owned by the robots plugin.
#[derive(Clone)]
pub struct RobotEntry {
    /// Registry name, e.g. `franka`.
    pub name: String,
    /// One line for `modesuite list`.
    pub description: String,
    /// The robot definition, type-erased.
    pub payload: Arc<dyn Any + Send + Sync>,
}

/// A named sensor type, type-erased payload owned by the plugin that provides it.
#[derive(Clone)]
pub struct SensorEntry {
    /// Registry name, e.g. `camera.rgbd`.
    pub name: String,
    /// One line for `modesuite list`.
    pub description: String,
    /// The sensor definition, type-erased.
    pub payload: Arc<dyn Any + Send + Sync>,
}

/// All registries of one app. Ordered maps, so listings and iteration are deterministic.
#[derive(Resource, Default, Clone)]
pub struct Registry {
    /// Shape generators by name.
    pub shapes: BTreeMap<String, Arc<dyn ShapeGenerator>>,
    /// Body kinds by name (the built-in rigid kinds `Static`, `Dynamic`, `Kinematic` are not here).
    pub body_kinds: BTreeMap<String, Arc<dyn BodyKind>>,
    /// Task terms by name.
    pub terms: BTreeMap<String, TermEntry>,
    /// Robots by name.
    pub robots: BTreeMap<String, RobotEntry>,
    /// Sensors by name.
    pub sensors: BTreeMap<String, SensorEntry>,
    /// Scene section handlers by key.
    pub sections: BTreeMap<String, Arc<dyn SceneSection>>,
    /// Passive forces on deformables by name.
    pub forces: BTreeMap<String, Arc<dyn crate::terms::PassiveForce>>,
}

/// Inserts `value` under `name` unless the name is taken; whether it was inserted (a second
/// registration is refused and the first stays; see `SimApp::report_duplicate`).
pub fn insert_unique<T>(map: &mut BTreeMap<String, T>, name: String, value: T) -> bool {
    match map.entry(name) {
        std::collections::btree_map::Entry::Vacant(slot) => {
            slot.insert(value);
            true
        }
        std::collections::btree_map::Entry::Occupied(_) => false,
    }
}

impl Registry {
    /// Which registry already uses `name`, if any (shapes, body kinds, terms, robots, sensors,
    /// passive forces), to refuse a second registration from a compiled plugin.
    pub fn name_in_use(&self, name: &str) -> Option<&'static str> {
        if self.shapes.contains_key(name) {
            Some("shape generator")
        } else if self.body_kinds.contains_key(name) {
            Some("body kind")
        } else if self.terms.contains_key(name) {
            Some("term")
        } else if self.robots.contains_key(name) {
            Some("robot")
        } else if self.sensors.contains_key(name) {
            Some("sensor")
        } else if self.forces.contains_key(name) {
            Some("passive force")
        } else if self.sections.contains_key(name) {
            Some("scene section")
        } else {
            None
        }
    }
}

impl crate::shapes::ShapeGenerators for Registry {
    fn generate(
        &self,
        name: &str,
        params_ron: &str,
        want: MeshKind,
    ) -> Result<GeneratedMesh, String> {
        match self.shapes.get(name) {
            Some(g) => g.generate(params_ron, want),
            None => Err(format!(
                "unknown shape generator \"{name}\"; registered: [{}]; a generator from a compiled plugin needs `--plugin PATH`",
                self.shapes.keys().cloned().collect::<Vec<_>>().join(", ")
            )),
        }
    }
    fn names(&self) -> Vec<String> {
        self.shapes.keys().cloned().collect()
    }
}

/// A compiled body: rigid (engine) or owned by a plugin body kind.
#[derive(Clone)]
pub enum BodyModel {
    /// Simulated by the rigid plugin (rapier).
    Rigid(crate::scene::RigidModel),
    /// Simulated by a plugin.
    Plugin {
        /// The body kind that compiled it and spawns it.
        kind: Arc<dyn BodyKind>,
        /// Its compiled data.
        compiled: CompiledBody,
    },
}

/// One compiled object.
#[derive(Clone)]
pub struct ObjectModel {
    /// Unique name.
    pub name: String,
    /// Initial `world_from_body`.
    pub pose: nalgebra::Isometry3<f64>,
    /// Resolved material.
    pub material: crate::scene::MaterialDesc,
    /// Display colour.
    pub color: Option<[f32; 3]>,
    /// The shape as written (renderers mesh it as they need).
    pub shape: crate::shapes::ShapeDesc,
    /// Body.
    pub body: BodyModel,
    /// Whether a deformable body touches other deformables.
    pub collide: bool,
    /// A deformable's collision group (members do not touch each other).
    pub collision_group: Option<String>,
}

/// The registry verbs of [`SimApp`] (here, beside the registry, so that the application layer
/// does not depend on what plugins register). The registry is a world resource, inserted on the
/// first registration.
impl SimApp {
    /// The registry of named capabilities.
    pub fn registry(&self) -> &Registry {
        self.world
            .get_resource::<Registry>()
            .unwrap_or_else(|| empty_registry())
    }

    /// Mutable access to the registry (the `register_*` verbs below are shorthands).
    pub fn registry_mut(&mut self) -> Mut<'_, Registry> {
        self.world.get_resource_or_insert_with(Registry::default)
    }

    /// Inserts `value` under `name` into one of the registry's maps unless the name is taken
    /// there; a second registration is refused (the first stays) and reported.
    fn register_unique<T>(
        &mut self,
        what: &str,
        name: String,
        value: T,
        map: fn(&mut Registry) -> &mut std::collections::BTreeMap<String, T>,
    ) -> &mut Self {
        if !insert_unique(map(&mut self.registry_mut()), name.clone(), value) {
            self.report_duplicate(what, &name);
        }
        self
    }

    /// Registers a shape generator under its name (RON: `Gen(name: "...", params: ...)`).
    pub fn register_shape(&mut self, generator: Arc<dyn ShapeGenerator>) -> &mut Self {
        let name = generator.name().to_string();
        self.register_unique("shape generator", name, generator, |r| &mut r.shapes)
    }

    /// Registers a body kind (RON: `body: Kind(kind: "fem.solid", params: ...)`).
    pub fn register_body_kind(&mut self, kind: Arc<dyn BodyKind>) -> &mut Self {
        let name = kind.name().to_string();
        self.register_unique("body kind", name, kind, |r| &mut r.body_kinds)
    }

    /// Registers a task term (observation, reward, termination, event) under its name.
    pub fn register_term(&mut self, term: TermEntry) -> &mut Self {
        let name = term.name.clone();
        self.register_unique("term", name, term, |r| &mut r.terms)
    }

    /// Registers a passive force on deformables (RON: `passive_forces: [(force: "...", ...)]`).
    pub fn register_passive_force(
        &mut self,
        force: Arc<dyn crate::terms::PassiveForce>,
    ) -> &mut Self {
        let name = force.name().to_string();
        self.register_unique("passive force", name, force, |r| &mut r.forces)
    }

    /// Registers a robot under its name.
    pub fn register_robot(&mut self, robot: RobotEntry) -> &mut Self {
        let name = robot.name.clone();
        self.register_unique("robot", name, robot, |r| &mut r.robots)
    }

    /// Registers the handler of a plugin-owned scene section (`extensions: { "key": ... }`).
    pub fn register_section(&mut self, section: impl SceneSection) -> &mut Self {
        let section: Arc<dyn SceneSection> = Arc::new(section);
        let name = section.name().to_string();
        self.register_unique("scene section", name, section, |r| &mut r.sections)
    }

    /// Registers a sensor type under its name.
    pub fn register_sensor(&mut self, sensor: SensorEntry) -> &mut Self {
        let name = sensor.name.clone();
        self.register_unique("sensor", name, sensor, |r| &mut r.sensors)
    }
}

/// The registry of an app in which nothing was registered.
fn empty_registry() -> &'static Registry {
    static EMPTY: std::sync::OnceLock<Registry> = std::sync::OnceLock::new();
    EMPTY.get_or_init(Registry::default)
}
