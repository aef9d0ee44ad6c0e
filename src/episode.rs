//! How an episode ended, as `run --json` and the Python binding report it (`ended`,
//! `terminations`, the final `success`).

use modesuite_engine::prelude::*;

/// How a run's episode ended (`run --json`'s `ended` and `terminations`).
#[derive(Debug, Clone, PartialEq)]
pub enum EpisodeEnd {
    /// Terminated with the task's success.
    Success,
    /// Terminated without success: a failure termination term fired (names of those that did,
    /// from the step's `termination/<name>` values; empty when another system ended it).
    Failure(Vec<String>),
    /// Truncated by the scene's time limit (`episode_steps`).
    TimeLimit,
    /// Ended by an error (physics blow-up, bad action, plugin or policy failure).
    Error,
    /// Still running when the run's `--steps` were done.
    Steps,
}

impl EpisodeEnd {
    /// The end of the step `o` that ended its episode (`terminated` or `truncated`).
    pub fn of(o: &StepOutcome) -> Self {
        Self::from_info(o.terminated, &o.info)
    }

    /// The end of a step that ended its episode, from its `terminated` flag and its info.
    pub fn from_info(terminated: bool, info: &EnvInfo) -> Self {
        if info.error.is_some() {
            EpisodeEnd::Error
        } else if terminated && info.success == Some(true) {
            EpisodeEnd::Success
        } else if terminated {
            EpisodeEnd::Failure(
                info.values
                    .iter()
                    .filter(|(_, v)| **v != 0.0)
                    .filter_map(|(k, _)| k.strip_prefix("termination/").map(str::to_string))
                    .collect(),
            )
        } else {
            EpisodeEnd::TimeLimit
        }
    }

    /// `success`, `failure`, `time_limit`, `error` or `steps`.
    pub fn name(&self) -> &'static str {
        match self {
            EpisodeEnd::Success => "success",
            EpisodeEnd::Failure(_) => "failure",
            EpisodeEnd::TimeLimit => "time_limit",
            EpisodeEnd::Error => "error",
            EpisodeEnd::Steps => "steps",
        }
    }

    /// The failure termination terms that fired (empty for other ends).
    pub fn terminations(&self) -> &[String] {
        match self {
            EpisodeEnd::Failure(t) => t,
            _ => &[],
        }
    }
}

impl std::fmt::Display for EpisodeEnd {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.terminations() {
            [] => f.write_str(self.name()),
            t => write!(f, "{}: {}", self.name(), t.join(", ")),
        }
    }
}

/// An episode's success from its last step: that step's value, except that an episode ended by
/// an error counts as a failure where the task has a success criterion (its earlier steps
/// reported one, `before`); the error step itself measures none.
pub fn final_success(before: Option<bool>, last: Option<bool>, error: bool) -> Option<bool> {
    match (error, last) {
        (true, None) => before.map(|_| false),
        (_, s) => s,
    }
}

#[cfg(test)]
mod tests {
    use super::final_success;

    #[test]
    fn an_errored_episode_of_a_task_with_success_is_a_failure() {
        // the error step measured nothing; earlier steps said "not yet": a failure
        assert_eq!(final_success(Some(false), None, true), Some(false));
        // no success criterion at all: still none
        assert_eq!(final_success(None, None, true), None);
        // a normal end keeps the last step's value
        assert_eq!(final_success(Some(false), Some(true), false), Some(true));
        assert_eq!(final_success(None, None, false), None);
    }
}
