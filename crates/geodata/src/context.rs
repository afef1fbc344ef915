//! An error that names the step that failed and keeps its cause, for jobs that chain
//! library calls (load, evaluate, write) and must say which one failed.

/// A step that failed (`what`: "loading the streets dataset D") and its cause.
#[derive(Debug, thiserror::Error)]
#[error("{what}")]
pub struct ContextError {
    /// The step that failed.
    pub what: String,
    /// Why it failed.
    #[source]
    pub source: Box<dyn std::error::Error + Send + Sync>,
}

/// Wraps an error with the step that failed.
pub trait WithContext<T> {
    /// The error, if any, as the cause of a [`ContextError`] saying `what()`.
    fn context(self, what: impl FnOnce() -> String) -> Result<T, ContextError>;
}

impl<T, E: std::error::Error + Send + Sync + 'static> WithContext<T> for Result<T, E> {
    fn context(self, what: impl FnOnce() -> String) -> Result<T, ContextError> {
        self.map_err(|e| ContextError {
            what: what(),
            source: Box::new(e),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cause_is_kept_as_the_source() {
        let r: Result<(), std::io::Error> = Err(std::io::Error::other("disk full"));
        let e = r.context(|| "writing out.json".into()).unwrap_err();
        assert_eq!(e.to_string(), "writing out.json");
        let source = std::error::Error::source(&e).map(ToString::to_string);
        assert_eq!(source.as_deref(), Some("disk full"));
    }
}
