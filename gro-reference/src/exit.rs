//! # Exit codes of every binary of the workspace, chosen from the error's type
//!
//! Why here: `sim-harness`, `ground-tool` and the `tests` binaries answer a script the same
//! way (README "Exit codes", docs/reliability.md): 0 success, 1 runtime failure, 2 bad or
//! insufficient input. A bad input is an [`InputError`] anywhere in the error's chain; the
//! code is never chosen by searching the message text.

/// A bad input (scenario, run folder, table file, option): the CLI exits with code 2.
#[derive(Debug, thiserror::Error)]
#[error("{0:#}")]
pub struct InputError(pub anyhow::Error);

impl From<anyhow::Error> for InputError {
    fn from(e: anyhow::Error) -> Self {
        Self(e)
    }
}

impl InputError {
    /// An input error from a message.
    pub fn msg(m: impl std::fmt::Display) -> Self {
        Self(anyhow::anyhow!("{m}"))
    }
}

/// Success.
pub const OK: u8 = 0;
/// A runtime failure: I/O while writing, another writer busy, an internal error.
pub const FAILURE: u8 = 1;
/// Bad or insufficient input: the message names the file, field or option and the cause.
pub const BAD_INPUT: u8 = 2;

/// The exit code for an error: [`BAD_INPUT`] when it (or one of its causes) is an
/// [`InputError`], else [`FAILURE`]. Chosen from the error's type, never its text.
#[must_use]
pub fn exit_code(e: &anyhow::Error) -> u8 {
    if is_input_error(e) {
        BAD_INPUT
    } else {
        FAILURE
    }
}

/// The error (or one of its causes) is an [`InputError`].
#[must_use]
pub fn is_input_error(e: &anyhow::Error) -> bool {
    e.downcast_ref::<InputError>().is_some()
        || e.chain().any(|c| c.downcast_ref::<InputError>().is_some())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_code_follows_the_type_not_the_text() {
        let bad: anyhow::Error = InputError::msg("no such file").into();
        assert_eq!(exit_code(&bad), BAD_INPUT);
        assert_eq!(exit_code(&bad.context("while reading the run")), BAD_INPUT);
        assert_eq!(
            exit_code(&anyhow::anyhow!("bad input: no such file")),
            FAILURE
        );
    }
}
