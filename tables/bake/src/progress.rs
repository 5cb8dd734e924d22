//! Progress of a long bake, reported to whoever runs it: the library decides nothing about
//! terminals, CI or verbosity.

/// Receives the progress of a bake. Implementations must be cheap and thread-safe: steps are
/// reported from worker threads.
pub trait Progress: Sync {
    /// Field `name` starts; `steps` calls of [`FieldProgress::advance`] will follow.
    fn field(&self, name: &str, steps: u64) -> Box<dyn FieldProgress + '_>;
}

/// The progress of one field.
pub trait FieldProgress: Sync {
    /// What is being done now (e.g. "Mie per wavelength").
    fn message(&self, text: &str);
    /// One step is done.
    fn advance(&self);
    /// The field is done.
    fn finish(&self);
}

/// Reports nothing.
#[derive(Debug, Clone, Copy, Default)]
pub struct Silent;

struct SilentField;

impl FieldProgress for SilentField {
    fn message(&self, _: &str) {}
    fn advance(&self) {}
    fn finish(&self) {}
}

impl Progress for Silent {
    fn field(&self, _: &str, _: u64) -> Box<dyn FieldProgress + '_> {
        Box::new(SilentField)
    }
}
