//! Collecting every mismatch between a document and the code, so one test run lists all the
//! lines to update instead of stopping at the first.

use crate::markdown::Doc;

/// Problems found while comparing a document with the code, reported all at once.
#[derive(Debug, Default)]
pub struct Problems {
    found: Vec<String>,
}

impl Problems {
    /// An empty list.
    pub fn new() -> Self {
        Problems::default()
    }

    /// Records a problem at `line` of `doc`.
    pub fn at(&mut self, doc: &Doc, line: usize, message: impl AsRef<str>) {
        self.found
            .push(format!("{}: {}", doc.at(line), message.as_ref()));
    }

    /// Number of problems recorded.
    pub fn len(&self) -> usize {
        self.found.len()
    }

    /// True when nothing was recorded.
    pub fn is_empty(&self) -> bool {
        self.found.is_empty()
    }

    /// Panics with every recorded problem, one per paragraph, if there is any.
    ///
    /// # Panics
    /// When a problem was recorded: that is the test failing.
    pub fn finish(self, what: &str) {
        if !self.found.is_empty() {
            panic!(
                "{what}: the document no longer matches the code ({} problem(s)); update the lines named below\n\n{}\n",
                self.found.len(),
                self.found.join("\n\n")
            );
        }
    }
}
