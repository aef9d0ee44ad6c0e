//! # modesuite-plugin-abi
//!
//! The small, versioned `#[repr(C)]` ABI through which compiled third-party plugins are loaded
//! at run time (`modesuite run --plugin PATH`).
//!
//! Status: empty. Filled by the plugin-ABI issue; until then `--plugin` answers with a clear
//! "not implemented yet" error.
