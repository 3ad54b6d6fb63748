//! Whisper satellites' utterance claims as the hub shows them (claim channels appearing, marked done, removed),
//! turned into per-satellite counts: claims taken, claims lost (the holder vanished before it was done) and claims
//! retried (an utterance taken again after a loss). Pure, like [`super::turns`].

use std::collections::{HashMap, VecDeque};

/// What one claim event meant for the counters.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ClaimNews {
    Taken { satellite: String, retry: bool },
    Lost { satellite: String },
}

/// Most recently lost utterances remembered, to recognise their retries.
const REMEMBER_LOST: usize = 256;

#[derive(Debug, Default)]
pub struct Claims {
    /// Open claims by utterance: holder and whether it said it is done.
    open: HashMap<String, (String, bool)>,
    lost: VecDeque<String>,
}

impl Claims {
    /// A claim channel for `utterance` appeared, held by `satellite`.
    pub fn added(&mut self, utterance: &str, satellite: &str) -> ClaimNews {
        let retry = if let Some(at) = self.lost.iter().position(|u| u == utterance) {
            self.lost.remove(at);
            true
        } else {
            false
        };
        self.open
            .insert(utterance.to_owned(), (satellite.to_owned(), false));
        ClaimNews::Taken {
            satellite: satellite.to_owned(),
            retry,
        }
    }

    /// The holder marked the claim done (its transcript is in, or there is none to give).
    pub fn done(&mut self, utterance: &str) {
        if let Some(claim) = self.open.get_mut(utterance) {
            claim.1 = true;
        }
    }

    /// The claim channel went away: lost unless its holder had finished.
    pub fn removed(&mut self, utterance: &str) -> Option<ClaimNews> {
        let (satellite, done) = self.open.remove(utterance)?;
        if done {
            return None;
        }
        if self.lost.len() >= REMEMBER_LOST {
            self.lost.pop_front();
        }
        self.lost.push_back(utterance.to_owned());
        Some(ClaimNews::Lost { satellite })
    }
}

/// The satellite's name from a claim header (`satellite`) or, without one, the owner label (`name#conn`).
pub fn holder(header: &serde_json::Value, owner: &str) -> String {
    header
        .get("satellite")
        .and_then(|s| s.as_str())
        .filter(|s| !s.is_empty())
        .map_or_else(
            || owner.split('#').next().unwrap_or(owner).to_owned(),
            str::to_owned,
        )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_claim_finished_then_removed_is_not_lost() {
        let mut c = Claims::default();
        assert_eq!(
            c.added("u1", "a"),
            ClaimNews::Taken {
                satellite: "a".into(),
                retry: false
            }
        );
        c.done("u1");
        assert_eq!(c.removed("u1"), None);
    }

    #[test]
    fn a_holder_that_vanishes_loses_its_claim_and_the_next_taker_retries_it() {
        let mut c = Claims::default();
        c.added("u2", "a");
        assert_eq!(
            c.removed("u2"),
            Some(ClaimNews::Lost {
                satellite: "a".into()
            })
        );
        assert_eq!(
            c.added("u2", "b"),
            ClaimNews::Taken {
                satellite: "b".into(),
                retry: true
            }
        );
    }

    #[test]
    fn the_holder_is_the_header_name_else_the_owner_label() {
        assert_eq!(holder(&serde_json::json!({"satellite": "w1"}), "x#3"), "w1");
        assert_eq!(
            holder(&serde_json::json!({}), "whisper-sat#12"),
            "whisper-sat"
        );
    }
}
