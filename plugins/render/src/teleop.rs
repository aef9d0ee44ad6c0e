//! Keyboard teleoperation: the 14 discrete MoDeSuite actions, their key bindings, the resource
//! the robots plugin reads, and episode recordings (seed + actions).
//!
//! The viewer publishes the pressed action as [`TeleopCommand`] in the env's world before each
//! step. When the env's action space is `Discrete(n)` with `n >= 14`, the action index is also the
//! env's action (one env step per key press); otherwise the simulation runs on with zero actions
//! and the command is only published (robots consume it once they exist) and recorded.

use std::path::Path;

use bevy_ecs::prelude::*;
use serde::{Deserialize, Serialize};

use crate::RenderError;

/// The 14 discrete teleoperation actions: the robots' [`DiscreteKey`](modesuite_robots::DiscreteKey)
/// (one definition of the action map and its index order).
pub use modesuite_robots::DiscreteKey as TeleopAction;

/// Keyboard bindings of the 14 discrete actions.
pub trait TeleopKeys: Sized {
    /// The key bound to this action (a lowercase letter).
    fn key(self) -> char;
    /// The action bound to a key (case-insensitive).
    fn from_key(c: char) -> Option<Self>;
    /// Human-readable name, e.g. `hand up`.
    fn label(self) -> String;
}

impl TeleopKeys for TeleopAction {
    fn key(self) -> char {
        match self {
            TeleopAction::BodyForward => 'w',
            TeleopAction::BodyLeft => 'a',
            TeleopAction::BodyRight => 'd',
            TeleopAction::BodyBack => 's',
            TeleopAction::TurnLeft => 'q',
            TeleopAction::TurnRight => 'e',
            TeleopAction::HandForward => 'i',
            TeleopAction::HandBack => 'k',
            TeleopAction::HandLeft => 'j',
            TeleopAction::HandRight => 'l',
            TeleopAction::HandUp => 'u',
            TeleopAction::HandDown => 'o',
            TeleopAction::Grasp => 'g',
            TeleopAction::Release => 'h',
        }
    }

    fn from_key(c: char) -> Option<Self> {
        let c = c.to_ascii_lowercase();
        Self::ALL.iter().copied().find(|a| a.key() == c)
    }

    fn label(self) -> String {
        self.name().replace('_', " ")
    }
}

/// The teleoperation command of the current env step (the robots plugin's controllers read it).
#[derive(Resource, Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TeleopCommand {
    /// The action for this step, if a key was pressed.
    pub action: Option<TeleopAction>,
    /// How many commands have been issued so far (lets a consumer see repeats).
    pub count: u64,
}

/// One recorded action.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct RecordedAction {
    /// Env step (within the episode) the action was applied at.
    pub step: u64,
    /// Action index (0..14).
    pub action: u32,
    /// Its name.
    pub name: TeleopAction,
}

/// One recorded episode.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RecordedEpisode {
    /// Seed the episode was reset with.
    pub seed: u64,
    /// Actions in order.
    pub actions: Vec<RecordedAction>,
    /// Env steps taken.
    pub length: u64,
}

/// A teleoperation recording (`modesuite.teleop.v1` JSON; the dataset format of the learning
/// issue will read it).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Recording {
    /// Format tag.
    pub format: String,
    /// Scene file or task id.
    pub scene: String,
    /// Episodes in order (the last one may be unfinished).
    pub episodes: Vec<RecordedEpisode>,
}

impl Recording {
    /// An empty recording of `scene`.
    pub fn new(scene: &str) -> Self {
        Self {
            format: "modesuite.teleop.v1".into(),
            scene: scene.into(),
            episodes: Vec::new(),
        }
    }

    /// Starts an episode with `seed`.
    pub fn start_episode(&mut self, seed: u64) {
        self.episodes.push(RecordedEpisode {
            seed,
            actions: Vec::new(),
            length: 0,
        });
    }

    /// Records `action` at env step `step` of the current episode.
    pub fn record(&mut self, step: u64, action: TeleopAction) {
        if self.episodes.is_empty() {
            self.start_episode(0);
        }
        if let Some(ep) = self.episodes.last_mut() {
            ep.actions.push(RecordedAction {
                step,
                action: action.index() as u32,
                name: action,
            });
        }
    }

    /// Sets the length of the current episode.
    pub fn set_length(&mut self, length: u64) {
        if let Some(ep) = self.episodes.last_mut() {
            ep.length = length;
        }
    }

    /// Writes the recording as pretty JSON, atomically (a temporary file, synced, renamed over
    /// `path`): a crash or a full disk leaves the previous file whole.
    pub fn save(&self, path: &Path) -> Result<(), RenderError> {
        let text = serde_json::to_string_pretty(self)
            .map_err(|e| RenderError::Output(format!("{}: {e}", path.display())))?;
        modesuite_engine::fsio::write_atomic(path, text.as_bytes())
            .map_err(|e| RenderError::Output(format!("{}: {e}", path.display())))
    }

    /// Reads a recording.
    pub fn load(path: &Path) -> Result<Self, RenderError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| RenderError::Output(format!("{}: {e}", path.display())))?;
        serde_json::from_str(&text)
            .map_err(|e| RenderError::Output(format!("{}: {e}", path.display())))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fourteen_actions_with_unique_keys() {
        assert_eq!(TeleopAction::ALL.len(), 14);
        for (i, a) in TeleopAction::ALL.iter().enumerate() {
            assert_eq!(a.index(), i);
            assert_eq!(TeleopAction::from_index(i), Some(*a));
            assert_eq!(TeleopAction::from_key(a.key()), Some(*a), "key of {a:?}");
        }
        assert_eq!(TeleopAction::HandUp.label(), "hand up");
        assert_eq!(TeleopAction::from_index(14), None);
    }

    #[test]
    fn recording_round_trip() {
        let mut r = Recording::new("s.scene.ron");
        r.start_episode(7);
        r.record(3, TeleopAction::Grasp);
        r.set_length(10);
        let path =
            std::env::temp_dir().join(format!("modesuite-teleop-{}.json", std::process::id()));
        r.save(&path).expect("save");
        assert_eq!(Recording::load(&path).expect("load"), r);
        let _ = std::fs::remove_file(&path);
    }
}
