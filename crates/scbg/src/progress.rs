//! Progress reporting for long-running library calls, independent of any terminal.

/// Receives progress from a library call: counted stages as [`Bar`]s and one-line notes
/// (per-epoch losses, summaries). A command-line front end draws bars; a server logs or
/// ignores them.
pub trait Progress: Sync {
    /// Starts a counted stage of `len` units called `what`; the stage ends when the bar is
    /// dropped.
    fn bar(&self, what: &str, len: u64) -> Box<dyn Bar + '_>;
    /// A line of information for the user (not an error).
    fn note(&self, text: &str);
}

/// One counted stage of a [`Progress`].
pub trait Bar: Send + Sync {
    /// `n` more units done.
    fn inc(&self, n: u64);
    /// A short status shown beside the bar (e.g. the current loss).
    fn set_message(&self, message: String);
}

/// A [`Progress`] that ignores everything.
#[derive(Debug, Clone, Copy, Default)]
pub struct Quiet;

impl Progress for Quiet {
    fn bar(&self, _what: &str, _len: u64) -> Box<dyn Bar + '_> {
        Box::new(Quiet)
    }
    fn note(&self, _text: &str) {}
}

impl Bar for Quiet {
    fn inc(&self, _n: u64) {}
    fn set_message(&self, _message: String) {}
}
