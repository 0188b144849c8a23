//! Progress on stderr: indicatif bars (hidden automatically when stderr is not a terminal) and
//! notes as lines.

use indicatif::{ProgressBar, ProgressStyle};

/// The terminal's [`scbg::Progress`].
#[derive(Debug, Clone, Copy, Default)]
pub struct Terminal;

struct TerminalBar(ProgressBar);

impl scbg::Bar for TerminalBar {
    fn inc(&self, n: u64) {
        self.0.inc(n);
    }
    fn set_message(&self, message: String) {
        self.0.set_message(message);
    }
}

impl Drop for TerminalBar {
    fn drop(&mut self) {
        self.0.finish_and_clear();
    }
}

impl scbg::Progress for Terminal {
    fn bar(&self, what: &str, len: u64) -> Box<dyn scbg::Bar + '_> {
        let pb = ProgressBar::new(len);
        pb.set_style(
            ProgressStyle::with_template(
                "{prefix:>10} [{elapsed_precise}] {wide_bar} {pos}/{len} {per_sec} eta {eta} {msg}",
            )
            .expect("valid template"),
        );
        pb.set_prefix(what.to_string());
        Box::new(TerminalBar(pb))
    }

    fn note(&self, text: &str) {
        eprintln!("{text}");
    }
}
