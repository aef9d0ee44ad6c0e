//! The trot gait's parameters ([`TrotParams`]): data a robot file and a scene write, checked
//! here; the controller that uses them is [`crate::locomotion::TrotController`].

/// Parameters of [`TrotController`](crate::locomotion::TrotController); a robot's `gait` in a
/// scene (any subset of the fields, the rest at their defaults, e.g.
/// `gait: (period: 0.35, kp: 900.0)`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrotParams {
    /// Gait period (one full cycle, both pairs stepping), s.
    pub period: f64,
    /// Fraction of the period a leg swings (< 0.5 leaves a four-foot support between the pairs).
    pub swing_fraction: f64,
    /// Swing foot lift, m.
    pub step_height: f64,
    /// Body height: base origin above the ground, m.
    pub body_height: f64,
    /// Raibert feedback gain on the velocity error (measured - commanded), s.
    pub raibert_gain: f64,
    /// Largest horizontal distance of a foot target from its nominal place, m.
    pub max_foot_offset: f64,
    /// Command limits |vx|, |vy| (m/s), |wz| (rad/s).
    pub max_command: [f64; 3],
    /// Acceleration limits of the tracked command, m/s^2 and rad/s^2.
    pub max_acceleration: [f64; 3],
    /// Integral gain of the velocity loop (commanded - measured body velocity and yaw rate,
    /// added to the stance feet's velocity), 1/s.
    pub velocity_integral_gain: f64,
    /// Bounds of the velocity loop's correction (m/s, m/s, rad/s).
    pub velocity_integral_limit: [f64; 3],
    /// Gain on each hip's height error due to roll and pitch (1: legs keep their length).
    pub attitude_gain: f64,
    /// Damping on each hip's vertical velocity due to the body's angular velocity, s.
    pub attitude_damping: f64,
    /// How level the body the stance legs' inverse kinematics assumes while stepping: 0 solves
    /// with the measured roll and pitch (the legs follow the body's tilt), 1 with a level body
    /// (the leg joints pull a tilted body back to level: with the hips close to the roll axis,
    /// the hip height term of `attitude_gain` alone hardly resists roll). Standing uses 0.
    pub stance_level: f64,
    /// Integral gain on the body height error, 1/s.
    pub height_integral_gain: f64,
    /// Bound of the height integral, m.
    pub height_integral_limit: f64,
    /// Leg joint position gain while this controller drives them, N m/rad.
    pub kp: f64,
    /// Leg joint velocity gain, N m s/rad.
    pub kd: f64,
    /// The velocity feed-forward makes up for the damping of rapier's implicit spring motor
    /// (`kp h` over a rigid step `h`) as well as for `kd` (default true; see
    /// [`TrotController::write`](crate::locomotion::TrotController::write)). Without it, Spot at
    /// 1/120 s substeps side-steps 17 % slow and drifts off its circles. `false` keeps the lead of the scenes tuned before it (Spot
    /// Cover, whose expert fails with it).
    pub implicit_damping_lead: bool,
}

impl Default for TrotParams {
    fn default() -> Self {
        Self {
            period: 0.3,
            swing_fraction: 0.45,
            step_height: 0.08,
            body_height: 0.55,
            raibert_gain: 0.25,
            max_foot_offset: 0.18,
            max_command: [0.5, 0.5, 1.0],
            max_acceleration: [1.5, 1.5, 3.0],
            velocity_integral_gain: 2.0,
            velocity_integral_limit: [0.25, 0.25, 0.5],
            attitude_gain: 1.0,
            attitude_damping: 0.05,
            stance_level: 1.0,
            height_integral_gain: 1.0,
            height_integral_limit: 0.05,
            kp: 800.0,
            kd: 15.0,
            implicit_damping_lead: true,
        }
    }
}

impl TrotParams {
    /// Checks the ranges: every number finite and >= 0; period, kp and body height > 0;
    /// `stance_level` in [0, 1]; `swing_fraction` in [0.05, 0.5].
    pub fn check(&self) -> Result<(), String> {
        let all = [
            self.period,
            self.swing_fraction,
            self.step_height,
            self.body_height,
            self.raibert_gain,
            self.max_foot_offset,
            self.velocity_integral_gain,
            self.attitude_gain,
            self.attitude_damping,
            self.stance_level,
            self.height_integral_gain,
            self.height_integral_limit,
            self.kp,
            self.kd,
        ];
        if all
            .iter()
            .chain(&self.max_command)
            .chain(&self.max_acceleration)
            .chain(&self.velocity_integral_limit)
            .any(|v| !v.is_finite() || *v < 0.0)
        {
            return Err("trot parameters must be finite and >= 0".into());
        }
        if self.period <= 0.0 || self.kp <= 0.0 || self.body_height <= 0.0 {
            return Err("trot period, kp and body height must be > 0".into());
        }
        if self.stance_level > 1.0 {
            return Err(format!(
                "stance level must be in [0, 1], got {}",
                self.stance_level
            ));
        }
        if !(0.05..=0.5).contains(&self.swing_fraction) {
            return Err(format!(
                "swing fraction must be in [0.05, 0.5], got {}",
                self.swing_fraction
            ));
        }
        Ok(())
    }
}
