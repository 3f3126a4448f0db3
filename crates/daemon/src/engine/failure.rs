//! The source's last error for STATUS, written when it changes rather
//! than on every failed frame: a board that stays silent fails every frame
//! with the same error, and formatting it each time would allocate per
//! frame. Errors are told apart by kind and place (a cheap comparison, no
//! allocation), not by their whole text, whose details (a seq, a value)
//! may differ on every frame.

use lightpose_hal::SourceError;
use std::mem::Discriminant;

/// The kind and place of the last failure, and how many failed so.
#[derive(Debug, Default)]
pub(super) struct LastFailure {
    kind: Option<Discriminant<SourceError>>,
    place: String,
    /// Failures of this kind at this place since it was first seen.
    pub(super) count: u64,
}

impl LastFailure {
    /// Note `e`; true when it differs in kind or place from the last one
    /// (its text is then worth keeping). Allocates only then.
    pub(super) fn changed(&mut self, e: &SourceError) -> bool {
        let kind = std::mem::discriminant(e);
        let place = place_of(e);
        if self.kind == Some(kind) && self.place == place {
            self.count = self.count.saturating_add(1);
            return false;
        }
        self.kind = Some(kind);
        self.place.clear();
        self.place.push_str(place);
        self.count = 1;
        true
    }
}

fn place_of(e: &SourceError) -> &str {
    match e {
        SourceError::Bus { place, .. }
        | SourceError::Timeout { place }
        | SourceError::Unavailable { place, .. }
        | SourceError::BadData { place, .. } => place.as_str(),
        SourceError::Ended | SourceError::Stopped => "",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn timeout(place: &str) -> SourceError {
        SourceError::Timeout {
            place: place.into(),
        }
    }

    #[test]
    fn a_failure_is_new_once_per_kind_and_place() {
        let mut f = LastFailure::default();
        assert!(f.changed(&timeout("board a")));
        assert!(!f.changed(&timeout("board a")));
        assert!(!f.changed(&timeout("board a")));
        assert_eq!(f.count, 3);
        assert!(f.changed(&timeout("board b")), "another place");
        let bad = |msg: &str| SourceError::BadData {
            place: "board b".into(),
            msg: msg.into(),
        };
        assert!(f.changed(&bad("line seq 1 says 12 bits")), "another kind");
        assert!(!f.changed(&bad("line seq 2 says 12 bits")), "details aside");
        assert_eq!(f.count, 2);
    }
}
