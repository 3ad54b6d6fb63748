//! Claims on utterances: the hub's channel namespace as the lock that gives each utterance to one satellite.
//!
//! A satellite that wants to transcribe an utterance creates the channel `Agent.asr.claim.<id>`. The hub refuses a
//! second channel of the same name, so exactly one satellite succeeds; the hub removes a dead connection's channels
//! and tells everyone, which is how the others learn that a claim was orphaned and the utterance is free again.

use serde::{Deserialize, Serialize};

use crate::turn::Turn;

/// Prefix of claim channels.
pub const CLAIM_PREFIX: &str = agent_contract::channels::ASR_CLAIM_PREFIX;
/// Prefix of the presence channels satellites keep while they run.
pub const PRESENCE_PREFIX: &str = agent_contract::channels::ASR_PRESENCE_PREFIX;

/// The claim channel of an utterance.
pub fn claim_channel(utterance_id: &str) -> String {
    format!("{CLAIM_PREFIX}{utterance_id}")
}

/// The utterance id of a claim channel name.
pub fn claimed_utterance(channel: &str) -> Option<&str> {
    channel.strip_prefix(CLAIM_PREFIX)
}

/// The JSON header of a claim channel: the interval, so satellites whose segmentation differs slightly can still
/// see that an overlapping utterance is taken, and who holds it. `speculative` marks a claim made when the utterance
/// paused, before it ended (its interval is then the speech so far); it is for people and tests reading the hub, the
/// claim rules do not depend on it. `done` is set once the holder has finished with the utterance (transcript
/// submitted, or none to give), so the others drop it. `pause` is where the holder stands on the end of the turn
/// at the pause it decodes, so that every satellite's segmenter ends the turn where the holder's does.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ClaimHeader {
    pub start_us: u64,
    pub end_us: u64,
    /// The holder's name; a header without one (written by hand, say) still counts as a claim.
    #[serde(default)]
    pub satellite: String,
    #[serde(default, skip_serializing_if = "is_false")]
    pub speculative: bool,
    #[serde(default, skip_serializing_if = "is_false")]
    pub done: bool,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pause: Option<PauseTurn>,
}

/// The end of the turn at one pause of a claimed utterance, as its holder judged it: `verdict` is `None` while the
/// pause's transcript is being decoded (the others hold the end for it, as the holder does), then the verdict.
/// Only the holder decodes, so without this the others would end the same turn on the plain hangover, and a
/// resumed voice between the two ends would make their utterances differ from the holder's.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct PauseTurn {
    /// Hub time of the end of speech before the pause: the pause's name, the same in every segmenter.
    pub speech_end_us: u64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub verdict: Option<Turn>,
    /// Set once the holder's segmenter ended the utterance at this pause: the hub time it closed it at. The
    /// others end theirs there too, even when their voice has resumed meanwhile (the verdict reached them late).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub closed_us: Option<u64>,
}

fn is_false(b: &bool) -> bool {
    !*b
}

impl ClaimHeader {
    /// The header of a fresh claim (not done).
    pub fn new(start_us: u64, end_us: u64, satellite: &str, speculative: bool) -> Self {
        ClaimHeader {
            start_us,
            end_us,
            satellite: satellite.to_owned(),
            speculative,
            done: false,
            pause: None,
        }
    }

    /// Reads a claim channel's header; `None` when it is not a claim header (not JSON, or no interval).
    pub fn parse(header: &str) -> Option<Self> {
        serde_json::from_str(header).ok()
    }

    /// The claimed speech, start and end in microseconds.
    pub fn interval(&self) -> (u64, u64) {
        (self.start_us, self.end_us)
    }

    /// The header as the claim channel carries it (compact JSON).
    pub fn to_json(&self) -> String {
        // A struct of numbers, a string and booleans always serialises; the fallback is never used.
        serde_json::to_string(self).unwrap_or_else(|_| "{}".to_owned())
    }
}

/// Whether the claim this satellite (`our_name`) holds on `ours` gives way to the claim `theirs` on the same speech.
///
/// Claims are exclusive by channel name, but two satellites can claim the same speech under different names in
/// the same instant: on federated hubs, where each hub sees the other's claim only a network hop later
/// (docs/federation.md), or on one hub when two segmenters cut the speech a frame apart. Both then see both headers,
/// and this rule, which needs nothing else, gives them the same verdict: the satellite whose name sorts first keeps
/// the speech. A finished claim is no rival (its transcript is out), and neither is a header without a name.
pub fn yields_to(our_name: &str, ours: (u64, u64), theirs: &ClaimHeader, min_us: u64) -> bool {
    !theirs.done
        && !theirs.satellite.is_empty()
        && theirs.satellite.as_str() < our_name
        && overlaps(ours, theirs.interval(), min_us)
}

/// True when two intervals share more than `min_us`.
pub fn overlaps(a: (u64, u64), b: (u64, u64), min_us: u64) -> bool {
    let lo = a.0.max(b.0);
    let hi = a.1.min(b.1);
    hi > lo && hi - lo > min_us
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn of_two_claims_on_the_same_speech_the_first_name_keeps_it() {
        let speech = (1_000_000, 2_500_000);
        let by = |name: &str| ClaimHeader::new(1_000_900, 2_400_000, name, true);
        // Both sides reach the same verdict from the two headers.
        assert!(yields_to("whisper-b", speech, &by("whisper-a"), 200_000));
        assert!(!yields_to("whisper-a", speech, &by("whisper-b"), 200_000));
        // Other speech, a finished claim, or an anonymous one is no rival.
        let elsewhere = ClaimHeader::new(3_000_000, 4_000_000, "whisper-a", false);
        assert!(!yields_to("whisper-b", speech, &elsewhere, 200_000));
        let mut done = by("whisper-a");
        done.done = true;
        assert!(!yields_to("whisper-b", speech, &done, 200_000));
        assert!(!yields_to("whisper-b", speech, &by(""), 200_000));
        assert!(!yields_to("whisper-a", speech, &by("whisper-a"), 200_000));
    }

    #[test]
    fn names_and_headers_round_trip() {
        let name = claim_channel("u1700000000123");
        assert_eq!(claimed_utterance(&name), Some("u1700000000123"));
        assert_eq!(
            claimed_utterance(agent_contract::channels::AUDIO.name),
            None
        );
        let plain = ClaimHeader::new(5, 9, "s1", false);
        assert_eq!(ClaimHeader::parse(&plain.to_json()), Some(plain.clone()));
        assert_eq!(plain.interval(), (5, 9));
        assert!(!plain.to_json().contains("speculative"));
        assert!(!plain.to_json().contains("done"));
        let speculative = ClaimHeader::new(5, 9, "s1", true);
        assert_eq!(
            ClaimHeader::parse(&speculative.to_json()),
            Some(speculative.clone())
        );
        assert!(speculative.to_json().contains("\"speculative\":true"));
        assert_eq!(ClaimHeader::parse("{}"), None);
        assert_eq!(ClaimHeader::parse("not json"), None);
    }

    #[test]
    fn a_done_claim_says_so_in_its_header_and_parses_back() {
        let done = ClaimHeader {
            done: true,
            ..ClaimHeader::new(5, 9, "s1", true)
        };
        // Tests and people reading the hub look for this exact text.
        assert!(done.to_json().contains("\"done\":true"));
        assert!(ClaimHeader::parse(&done.to_json()).is_some_and(|h| h.done));
        let foreign = r#"{"start_us":1,"end_us":2,"done":true,"extra":[1]}"#;
        assert_eq!(
            ClaimHeader::parse(foreign),
            Some(ClaimHeader {
                start_us: 1,
                end_us: 2,
                satellite: String::new(),
                speculative: false,
                done: true,
                pause: None,
            })
        );
    }

    #[test]
    fn a_pause_and_its_verdict_travel_in_the_header() {
        let deciding = ClaimHeader {
            pause: Some(PauseTurn {
                speech_end_us: 9,
                verdict: None,
                closed_us: None,
            }),
            ..ClaimHeader::new(5, 9, "s1", true)
        };
        let json = deciding.to_json();
        assert!(json.contains(r#""pause":{"speech_end_us":9}"#), "{json}");
        assert_eq!(ClaimHeader::parse(&json), Some(deciding.clone()));
        let judged = ClaimHeader {
            pause: Some(PauseTurn {
                speech_end_us: 9,
                verdict: Some(Turn::Complete),
                closed_us: None,
            }),
            ..deciding
        };
        let json = judged.to_json();
        assert!(json.contains(r#""verdict":"complete""#), "{json}");
        assert_eq!(ClaimHeader::parse(&json), Some(judged));
        let ended = ClaimHeader {
            pause: Some(PauseTurn {
                speech_end_us: 9,
                verdict: Some(Turn::Unknown),
                closed_us: Some(12),
            }),
            ..ClaimHeader::new(5, 9, "s1", true)
        };
        let json = ended.to_json();
        assert!(json.contains(r#""closed_us":12"#), "{json}");
        assert_eq!(ClaimHeader::parse(&json), Some(ended));
        // A header from before verdicts were shared has none.
        assert_eq!(
            ClaimHeader::parse(r#"{"start_us":1,"end_us":2}"#).and_then(|h| h.pause),
            None
        );
    }

    #[test]
    fn overlap_needs_a_real_intersection() {
        assert!(overlaps((0, 100), (50, 150), 10));
        assert!(!overlaps((0, 100), (95, 150), 10));
        assert!(!overlaps((0, 100), (100, 150), 0));
    }
}
