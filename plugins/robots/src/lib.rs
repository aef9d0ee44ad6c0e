//! # modesuite-robots
//!
//! Robots for modesuite: URDF loading into rapier multibodies, the Franka-on-Ridgeback and
//! Spot-with-arm models, joint/IK/base/legged controllers and the robot registry.
//!
//! Status: empty. The engine foundation landed first; this crate is filled by the robots issue.
//! Nothing here is registered yet, so `modesuite list robots` shows none.
