//! Errors of the robots crate. Every error names the file, link or joint concerned.

use std::path::PathBuf;

/// Everything that can go wrong loading, building or driving a robot.
#[derive(Debug, thiserror::Error)]
pub enum RobotError {
    /// The URDF file (or a file it references) could not be read.
    #[error("{path}: cannot read: {message}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's message.
        message: String,
    },
    /// A path resolves outside every asset root.
    #[error("{path}: resolves outside the asset roots ({roots})")]
    OutsideAssetRoots {
        /// The path as written (or resolved).
        path: String,
        /// The asset roots, comma separated.
        roots: String,
    },
    /// A `package://` URI names a package that is not in the asset search path.
    #[error("{file}: unknown package `{package}` in `{uri}` (known: {known})")]
    UnknownPackage {
        /// The URDF file.
        file: String,
        /// The package name.
        package: String,
        /// The whole URI.
        uri: String,
        /// The packages known to the asset search path.
        known: String,
    },
    /// The XML is not a valid URDF.
    #[error("{file}: invalid URDF: {message}")]
    Parse {
        /// The URDF file (or `<string>`).
        file: String,
        /// The parser's message.
        message: String,
    },
    /// A link is invalid (bad inertia, geometry, duplicated name, ...).
    #[error("{file}: link `{link}`: {message}")]
    Link {
        /// The URDF file.
        file: String,
        /// The link name.
        link: String,
        /// What is wrong.
        message: String,
    },
    /// A joint is invalid (bad axis, limits, unsupported type, unknown link, ...).
    #[error("{file}: joint `{joint}`: {message}")]
    Joint {
        /// The URDF file.
        file: String,
        /// The joint name.
        joint: String,
        /// What is wrong.
        message: String,
    },
    /// The link/joint graph is not a tree with one root.
    #[error("{file}: {message}")]
    Structure {
        /// The URDF file.
        file: String,
        /// What is wrong.
        message: String,
    },
    /// A robot description file (`*.robot.ron`) is not valid RON or has an unknown field.
    #[error("{file}:{line}:{col}: {message}")]
    DescriptionSyntax {
        /// The description file.
        file: String,
        /// Line (1-based).
        line: usize,
        /// Column (1-based).
        col: usize,
        /// The parser's message.
        message: String,
    },
    /// A field of a robot description file has a value that is not valid.
    #[error("{file}: {field} = {value}: expected {expected}")]
    Description {
        /// The description file.
        file: String,
        /// The field (`arm[3]`, `gripper.open`, ...).
        field: String,
        /// The value as written.
        value: String,
        /// What is valid.
        expected: String,
    },
    /// A name given by the caller (joint, frame, home pose entry) does not exist in the robot.
    #[error("robot `{robot}`: unknown {what} `{name}`")]
    UnknownName {
        /// The robot.
        robot: String,
        /// "joint", "frame", ...
        what: &'static str,
        /// The name.
        name: String,
    },
    /// A value given by the caller is invalid (wrong length, not finite, outside the limits).
    #[error("robot `{robot}`: {message}")]
    InvalidInput {
        /// The robot.
        robot: String,
        /// What is wrong.
        message: String,
    },
    /// The robot's rapier objects were removed or changed under it.
    #[error("robot `{robot}`: {message}")]
    Stale {
        /// The robot.
        robot: String,
        /// What is missing.
        message: String,
    },
}
