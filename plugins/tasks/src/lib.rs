//! # modesuite-tasks
//!
//! The MoDeSuite tasks: managers (actions, observations, rewards, terminations, events,
//! success), the term library and the 16 `MoDe-<Robot>-<Task>-v0` environments with their
//! scripted experts.
//!
//! Status: empty. The engine foundation landed first; this crate is filled by the tasks issue.
//! `modesuite run MoDe-...` answers with a clear "not implemented yet" error until then.
