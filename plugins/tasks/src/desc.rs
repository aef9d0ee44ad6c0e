//! The `task` scene section as written (serde), and `extends`.
//!
//! ```ron
//! extensions: {
//!     "task": (
//!         id: "MoDe-Franka-Place-v0",
//!         extends: "place.task.ron",            // a file with a partial section, merged under this one
//!         points: {"rod_end": Nodes(object: "rod", select: Box(min: (0.40, -1, -1), max: (0.42, 1, 1)))},
//!         targets: {"table": (pos: (1.5, 1.5, 0.83), range: (0.05, 0.05, 0.0))},
//!         rewards: {"end_to_table": (term: "distance", weight: -1.0, params: (a: Point("rod_end"), b: Target("table")))},
//!         success: {"end_on_table": (term: "in_box", params: (point: Point("rod_end"), center: Target("table"), min: (-0.56, -0.4, 0.0), max: (0.56, 0.4, 0.15)))},
//!         success_bonus: 20.0,
//!         observations: {"policy": (terms: [(term: "base_xy"), (term: "tracked", params: (object: "rod", k: 4))])},
//!         events: {"start": RobotPose(xy: 0.1, yaw: 0.1, carry: ["rod"])},
//!     ),
//! }
//! ```
//! Every map is keyed by a name: a section that `extends` another replaces the parent's entries
//! of the same name and adds the others; scalar fields replace the parent's when given.

use std::collections::BTreeMap;

use modesuite_engine::scene::NodeSelect;
use ron::value::RawValue;
use serde::Deserialize;

/// A point of the task, as terms refer to it.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub enum PointRef {
    /// A named point of the section's `points`.
    Point(String),
    /// A target of the section's `targets` (its randomised position).
    Target(String),
    /// The robot's base frame origin (on the floor).
    Base,
    /// The robot's end-effector (tool centre point).
    Ee,
    /// The origin of a scene object (rigid bodies, robot links `robot/link`).
    Object(String),
    /// The centroid of a deformable object's nodes.
    Centroid(String),
    /// The centroid of the nodes of a deformable object selected in its rest (object) frame.
    Nodes {
        /// Object name.
        object: String,
        /// Selection in the object frame at spawn.
        select: NodeSelect,
    },
    /// Tracked point `i` of `k` of a deformable: the node nearest to station `i` of `k` spread
    /// uniformly along the longest axis of its rest shape (`i = 0` at the low end).
    Tracked {
        /// Object name.
        object: String,
        /// Station, `0..k`.
        i: usize,
        /// Number of stations (>= 1).
        k: usize,
    },
    /// A fixed world point.
    Const((f64, f64, f64)),
    /// Staged goals: the first of `stages` that the point `by` has not yet come within `reach`
    /// (m, in x and y) of, in order; the last once all are reached. Progress belongs to the
    /// episode (reset at every reset, saved in snapshots).
    Stages {
        /// The goals in order.
        stages: Vec<PointRef>,
        /// The point that has to reach them.
        by: Box<PointRef>,
        /// Planar distance that counts as reached, m.
        reach: f64,
    },
}

/// A target: a world point randomised uniformly within `pos +- range` at every reset.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TargetDesc {
    /// Nominal position, m.
    pub pos: (f64, f64, f64),
    /// Half-width of the uniform randomisation per axis, m.
    #[serde(default)]
    pub range: (f64, f64, f64),
}

/// A configured term: a registered term name and its RON parameters.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TermDesc {
    /// Registered task term (`modesuite list` shows them).
    pub term: String,
    /// Its parameters (default: none, `()`).
    #[serde(default)]
    pub params: Option<Box<RawValue>>,
}

/// A reward term: `weight x value` (x the env step length when `dt_scaled`).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RewardDesc {
    /// Registered task term.
    pub term: String,
    /// Its parameters.
    #[serde(default)]
    pub params: Option<Box<RawValue>>,
    /// Weight.
    pub weight: f64,
    /// Multiply by the env step length, s (Isaac Lab's convention).
    #[serde(default)]
    pub dt_scaled: bool,
    /// The reward counts only on steps where this term is non-zero (e.g. an `in_box` of the
    /// base: a shaping term dropped once the robot is past a point); 0 on other steps.
    #[serde(default)]
    pub when: Option<TermDesc>,
}

/// One observation term of a group, with its post-processing (scale, then clip).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObsTermDesc {
    /// Registered task term.
    pub term: String,
    /// Its parameters.
    #[serde(default)]
    pub params: Option<Box<RawValue>>,
    /// Multiplies every value.
    #[serde(default)]
    pub scale: Option<f64>,
    /// Clips every (scaled) value to `[lo, hi]`.
    #[serde(default)]
    pub clip: Option<(f64, f64)>,
}

/// What a camera observation term holds per pixel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
pub enum CameraChannels {
    /// Red, green, blue in [0, 1].
    Rgb,
    /// Depth along the optical axis, m (0 where nothing was hit).
    Depth,
    /// Red, green, blue in [0, 1], then depth in m.
    #[default]
    Rgbd,
}

impl CameraChannels {
    /// Values per pixel.
    pub fn count(self) -> usize {
        match self {
            CameraChannels::Rgb => 3,
            CameraChannels::Depth => 1,
            CameraChannels::Rgbd => 4,
        }
    }

    /// Lower-case name (`rgb`, `depth`, `rgbd`).
    pub fn name(self) -> &'static str {
        match self {
            CameraChannels::Rgb => "rgb",
            CameraChannels::Depth => "depth",
            CameraChannels::Rgbd => "rgbd",
        }
    }
}

/// An image observation: a camera of the scene's render section (`extensions["render"]`).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraObsDesc {
    /// Camera name.
    pub camera: String,
    /// Channels (default `Rgbd`).
    #[serde(default)]
    pub channels: CameraChannels,
}

/// An observation group: its terms concatenated, optional noise and history.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GroupDesc {
    /// Terms in order.
    pub terms: Vec<ObsTermDesc>,
    /// Uniform noise `+- noise` added to every value (after scale and clip), from the env's RNG.
    #[serde(default)]
    pub noise: f64,
    /// Number of most recent frames stacked, newest last (>= 1).
    #[serde(default = "one")]
    pub history: usize,
}

fn one() -> usize {
    1
}

/// An event (randomisation or disturbance). An entry of `events` runs at every reset, unless it
/// is wrapped in `Startup(...)` (once per env) or `Interval(...)` (during episodes):
///
/// ```ron
/// events: {
///     "start": RobotPose(xy: 0.1, yaw: 0.1),                                  // every reset
///     "floor": Startup(Friction(object: "floor", range: (0.4, 1.0))),         // once per env
///     "gust": Interval(every: (1.0, 3.0), event: Push(object: "cloth", velocity: (0.5, 0.5, 0.2))),
/// }
/// ```
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub enum EventDesc {
    /// Runs the event once per env, at its first reset, with values drawn from a stream derived
    /// from that reset's seed; they are re-applied after every later reset (a reset restores
    /// the scene's initial state), so they hold for the env's whole life.
    Startup(Box<EventDesc>),
    /// Runs the event during episodes: first after a gap drawn uniformly from `every` (seconds
    /// of episode time, drawn at reset), then again after each new gap, at most once per env
    /// step, before the physics of that step. Only events that do not teleport objects
    /// (`Friction`, `Material`, `Push`) can run at intervals.
    Interval {
        /// (shortest, longest) gap between two runs, s (0 < shortest <= longest).
        every: (f64, f64),
        /// The event.
        event: Box<EventDesc>,
    },
    /// Adds a velocity drawn uniformly in `+- velocity` (per axis, world frame, m/s) to a
    /// deformable object (every free node or particle) or to a free rigid body: a push.
    Push {
        /// Object name (`fem.solid`, `pbd.cloth` or a dynamic rigid body).
        object: String,
        /// Half-widths of the velocity change per axis, m/s.
        velocity: (f64, f64, f64),
    },
    /// Moves the robot's holonomic base by a uniform offset (`+- xy` m, `+- yaw` rad about the
    /// base origin) and the `carry` deformables with it (an object held in the gripper).
    RobotPose {
        /// Half-width of the x and y offset, m.
        xy: f64,
        /// Half-width of the yaw offset, rad.
        yaw: f64,
        /// Deformable objects moved rigidly with the base.
        #[serde(default)]
        carry: Vec<String>,
    },
    /// Sets the friction coefficient of every collider of a rigid object (robot links by their
    /// `robot/link` names) to a uniform value in `range`.
    Friction {
        /// Object name.
        object: String,
        /// (lowest, highest) friction coefficient.
        range: (f64, f64),
    },
    /// Translates a deformable object by a uniform offset `+- xy` in x and y.
    ObjectOffset {
        /// Object name.
        object: String,
        /// Half-width, m.
        xy: f64,
    },
    /// Sets the Young's modulus of a `fem.solid` object to a uniform value in `youngs_modulus`
    /// (Pa; Poisson ratio and density stay the scene's): material randomisation.
    Material {
        /// Object name (a `fem.solid`).
        object: String,
        /// (lowest, highest) Young's modulus, Pa.
        youngs_modulus: (f64, f64),
    },
    /// An event registered by a plugin under `event` (`modesuite list terms`, kind `event`;
    /// [`crate::events::register_task_event`]), configured from `params` when the scene
    /// compiles: `Event(event: "acme.gust", params: (object: "cloth", speed: 0.5))`.
    Event {
        /// Registered name.
        event: String,
        /// Its RON parameters (default `()`).
        #[serde(default)]
        params: Option<Box<ron::value::RawValue>>,
    },
}

/// A deformable held by the robot from the start: the selected nodes (object frame, at spawn)
/// are attached to the body carrying the gripper (the precursor's rod in hand).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HeldDesc {
    /// A `fem.solid` object.
    pub object: String,
    /// The held nodes.
    pub select: NodeSelect,
    /// `false` (default): a kinematic attachment that never lets go. `true`: a grasp of the
    /// robot's gripper (force-limited, the robot's `grasp_force_limit`), released when the
    /// gripper opens; the robot must start with `start_closed: true`.
    #[serde(default)]
    pub grasp: bool,
}

/// One leg of the `route` expert: drive the base to a pose while the hand moves to a target.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RouteStep {
    /// Base goal: x, y (m, world frame) and heading (degrees).
    pub base: (f64, f64, f64),
    /// Hand goal in the base frame, m (default: stay where the hand's target is). With
    /// `hand_at` it is an offset (base frame) from that point.
    #[serde(default)]
    pub hand: Option<(f64, f64, f64)>,
    /// The hand goes to a named task point (`points` or `targets`, e.g. a cloth's handle), read
    /// at every step of the leg, plus the `hand` offset (base frame).
    #[serde(default)]
    pub hand_at: Option<String>,
    /// Hand orientation goal in the base frame: roll, pitch, yaw in degrees (default: keep the
    /// orientation); it turns at up to the arm's angular speed and is held on later legs.
    #[serde(default)]
    pub hand_rpy: Option<(f64, f64, f64)>,
    /// The leg ends only once the measured hand (tool centre point) is within this distance of
    /// the hand goal, m (default: the hand target within 2 cm is enough).
    #[serde(default)]
    pub hand_tolerance: Option<f64>,
    /// Gripper state from this leg on (default: as on the leg before; open at the start).
    #[serde(default)]
    pub closed: Option<bool>,
    /// Base speed limit on this leg, m/s (default 0.4).
    #[serde(default)]
    pub speed: Option<f64>,
    /// Hand speed limit on this leg (its target's speed in the base frame), m/s (default 0.25).
    #[serde(default)]
    pub hand_speed: Option<f64>,
    /// The leg ends when the base is within this distance (m) of its goal and within 3 degrees
    /// of its heading, and the hand within 2 cm of its goal (default 0.05 m).
    #[serde(default)]
    pub tolerance: Option<f64>,
}

/// The `task` section.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TaskDesc {
    /// Environment id, `MoDe-<Robot>-<Task>-v0`.
    #[serde(default)]
    pub id: Option<String>,
    /// A `*.task.ron` file (relative to the scene file) whose section this one extends.
    #[serde(default)]
    pub extends: Option<String>,
    /// The robot the task observes and the expert drives (default `robot`).
    #[serde(default)]
    pub robot: Option<String>,
    /// Name of the scripted expert (see `modesuite list`).
    #[serde(default)]
    pub expert: Option<String>,
    /// Named points.
    #[serde(default)]
    pub points: BTreeMap<String, PointRef>,
    /// Targets (randomised at reset).
    #[serde(default)]
    pub targets: BTreeMap<String, TargetDesc>,
    /// Reward terms.
    #[serde(default)]
    pub rewards: BTreeMap<String, RewardDesc>,
    /// Success terms: the task succeeds when every one is non-zero (this ends the episode).
    #[serde(default)]
    pub success: BTreeMap<String, TermDesc>,
    /// Reward added on the step of success.
    #[serde(default)]
    pub success_bonus: Option<f64>,
    /// Failure terms: a non-zero value ends the episode (terminated, not a success).
    #[serde(default)]
    pub terminations: BTreeMap<String, TermDesc>,
    /// Observation groups; the env's observation is the group `policy`.
    #[serde(default)]
    pub observations: BTreeMap<String, GroupDesc>,
    /// Events, in name order: reset events (randomisation), `Startup(...)` and `Interval(...)`.
    #[serde(default)]
    pub events: BTreeMap<String, EventDesc>,
    /// A deformable in the robot's hand from the start.
    #[serde(default)]
    pub held: Option<HeldDesc>,
    /// Legs of the `route` expert, in order (a section that gives any replaces the parent's).
    #[serde(default)]
    pub route: Vec<RouteStep>,
    /// An image of this camera appended to the `policy` group (a `camera` term): RGB-D
    /// observations without restating the group's state terms (`run --rgbd`).
    #[serde(default)]
    pub camera_observation: Option<CameraObsDesc>,
}

impl TaskDesc {
    /// Lays `self` over `parent`: scalars given here win, maps merge by key (entries here win).
    pub fn over(self, parent: TaskDesc) -> TaskDesc {
        fn merge<V>(
            mut base: BTreeMap<String, V>,
            top: BTreeMap<String, V>,
        ) -> BTreeMap<String, V> {
            base.extend(top);
            base
        }
        TaskDesc {
            id: self.id.or(parent.id),
            extends: None,
            robot: self.robot.or(parent.robot),
            expert: self.expert.or(parent.expert),
            points: merge(parent.points, self.points),
            targets: merge(parent.targets, self.targets),
            rewards: merge(parent.rewards, self.rewards),
            success: merge(parent.success, self.success),
            success_bonus: self.success_bonus.or(parent.success_bonus),
            terminations: merge(parent.terminations, self.terminations),
            observations: merge(parent.observations, self.observations),
            events: merge(parent.events, self.events),
            held: self.held.or(parent.held),
            route: if self.route.is_empty() {
                parent.route
            } else {
                self.route
            },
            camera_observation: self.camera_observation.or(parent.camera_observation),
        }
    }
}
