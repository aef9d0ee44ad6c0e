//! Gymnasium conventions for the Python binding (and any other front end that speaks
//! Gymnasium): the observation and action layouts users see ([`layout`]) and the `info` dicts
//! of single and vector envs ([`info`]). Pure Rust, so `cargo test` checks them without Python.

pub mod info;
pub mod layout;
