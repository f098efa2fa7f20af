//! How stages report progress and warnings without printing: the caller (the CLI's bars, a
//! Ray task's log, a test) implements [`Progress`].

/// Receives a stage's progress; every method has a do-nothing default.
pub trait Progress: Sync {
    /// A phase of `len` items called `unit` (views, photos) begins, named `what`.
    fn start(&self, _what: &str, _len: u64, _unit: &str) {}
    /// `n` more items are done.
    fn inc(&self, _n: u64) {}
    /// The phase is over.
    fn finish(&self) {}
    /// Something the user should know that does not stop the stage.
    fn warn(&self, _message: &str) {}
}

/// Progress that goes nowhere (tests, scripts, quiet runs).
#[derive(Debug, Clone, Copy, Default)]
pub struct Silent;

impl Progress for Silent {}
