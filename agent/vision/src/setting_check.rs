//! The one shape of a configured value's check, shared by `settings.rs` and `people_settings.rs`: a condition, the
//! key it is about, and the reason shown when it does not hold.

use crate::error::VisionError;

/// The setting `key` is invalid for `reason`.
pub(crate) fn invalid(key: &'static str, reason: impl Into<String>) -> VisionError {
    VisionError::InvalidSetting {
        key,
        reason: reason.into(),
    }
}

/// `Ok` when `ok`, else the setting `key` is invalid for `reason`.
pub(crate) fn check(ok: bool, key: &'static str, reason: &str) -> Result<(), VisionError> {
    if ok {
        Ok(())
    } else {
        Err(invalid(key, reason))
    }
}
