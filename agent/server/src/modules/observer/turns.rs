//! The stages of a conversational turn, matched up from the timestamps the pipeline already carries: the end of
//! speech (the VAD end event's `at_ms`), the VAD end event itself, the final transcript of that utterance, the rule
//! that fired on it, and the first PCM of the reply. Pure: it is fed events with their hub times and says which
//! stage durations it saw (and, at the reply, the whole turn), so it is tested without a hub.

use std::collections::HashMap;

/// A stage of a turn, the label of `agent_conversation_seconds`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Stage {
    /// End of speech -> the VAD end event (the silence hangover).
    SpeechEndToVadEnd,
    /// The VAD end event -> the final transcript (can be zero: speculation may have it ready).
    VadEndToTranscript,
    /// The final transcript -> the rule that fired on it.
    TranscriptToRule,
    /// The rule -> the first PCM of the reply.
    RuleToReplyAudio,
    /// End of speech -> the first PCM of the reply: what the user waits.
    SpeechEndToReplyAudio,
}

impl Stage {
    pub fn label(self) -> &'static str {
        match self {
            Stage::SpeechEndToVadEnd => "speech_end_to_vad_end",
            Stage::VadEndToTranscript => "vad_end_to_transcript",
            Stage::TranscriptToRule => "transcript_to_rule",
            Stage::RuleToReplyAudio => "rule_to_reply_audio",
            Stage::SpeechEndToReplyAudio => "speech_end_to_reply_audio",
        }
    }
}

/// How long a turn waits for its next stage before it is forgotten (an utterance nobody answered).
const STALE_US: u64 = 30_000_000;
/// Most turns followed at once; more means events without their ends, and the oldest are forgotten.
const MAX_TURNS: usize = 64;

#[derive(Debug, Clone, Copy)]
struct Turn {
    speech_end_us: u64,
    vad_end_us: u64,
}

/// What names a turn across processes: its utterance id and the trace context its transcript carried.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TurnName {
    pub utterance: String,
    /// The `traceparent` of the transcript, if it had one.
    pub trace: Option<String>,
    /// The rule that answered it.
    pub rule: String,
}

/// The turn that has its transcript and waits for its rule, then for its reply.
#[derive(Debug, Clone)]
struct Answering {
    name: TurnName,
    speech_end_us: u64,
    vad_stage_us: u64,
    transcript_us: u64,
    transcript_stage_us: u64,
    rule_us: Option<u64>,
    rule_stage_us: u64,
    /// The first PCM of an utterance that came before any rule: the rule's message may arrive after the reply's
    /// first chunk (they travel on different channels, and a reply that needs no work follows its rule within a
    /// millisecond), so the turn is completed when the rule comes, if the speech started after it fired.
    early_reply_us: Option<u64>,
}

/// A turn from the end of speech to its reply, every stage in µs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TurnDone {
    pub name: TurnName,
    pub speech_end_us: u64,
    pub vad_us: u64,
    pub transcript_us: u64,
    pub rule_us: u64,
    pub reply_us: u64,
    pub total_us: u64,
}

/// Follows turns through their stages; every method returns the stage durations (µs) its event completed.
#[derive(Debug, Default)]
pub struct Turns {
    ended: HashMap<String, Turn>,
    answering: Option<Answering>,
}

impl Turns {
    /// The VAD says utterance `utterance` ended: speech stopped at `speech_end_ms` (hub clock), the event was
    /// published at `event_us`.
    pub fn vad_end(
        &mut self,
        utterance: &str,
        speech_end_ms: u64,
        event_us: u64,
    ) -> Vec<(Stage, u64)> {
        self.forget_stale(event_us);
        let speech_end_us = speech_end_ms.saturating_mul(1000);
        if self.ended.len() >= MAX_TURNS
            && let Some(oldest) = self
                .ended
                .iter()
                .min_by_key(|(_, t)| t.vad_end_us)
                .map(|(k, _)| k.clone())
        {
            self.ended.remove(&oldest);
        }
        self.ended.insert(
            utterance.to_owned(),
            Turn {
                speech_end_us,
                vad_end_us: event_us,
            },
        );
        vec![(
            Stage::SpeechEndToVadEnd,
            event_us.saturating_sub(speech_end_us),
        )]
    }

    /// A final transcript of `utterance` was published at `event_us`, carrying the trace context `trace`.
    pub fn transcript(
        &mut self,
        utterance: &str,
        trace: Option<&str>,
        event_us: u64,
    ) -> Vec<(Stage, u64)> {
        let Some(turn) = self.ended.remove(utterance) else {
            return Vec::new();
        };
        let stage = event_us.saturating_sub(turn.vad_end_us);
        self.answering = Some(Answering {
            name: TurnName {
                utterance: utterance.to_owned(),
                trace: trace.map(str::to_owned),
                rule: String::new(),
            },
            speech_end_us: turn.speech_end_us,
            vad_stage_us: turn.vad_end_us.saturating_sub(turn.speech_end_us),
            transcript_us: event_us,
            transcript_stage_us: stage,
            rule_us: None,
            rule_stage_us: 0,
            early_reply_us: None,
        });
        vec![(Stage::VadEndToTranscript, stage)]
    }

    /// Rule `rule` fired at `at_ms`; `heard` says whether its guard rested on something heard (an answer, not a
    /// greeting or a timer). Returns the stage it completed, and the whole turn when its reply's first PCM had
    /// already come.
    pub fn rule(
        &mut self,
        rule: &str,
        at_ms: u64,
        heard: bool,
    ) -> (Vec<(Stage, u64)>, Option<TurnDone>) {
        let at_us = at_ms.saturating_mul(1000);
        let (rule_stage_us, early) = match &mut self.answering {
            Some(a) if heard && a.rule_us.is_none() && at_us + 1000 >= a.transcript_us => {
                a.rule_us = Some(at_us);
                rule.clone_into(&mut a.name.rule);
                a.rule_stage_us = at_us.saturating_sub(a.transcript_us);
                (a.rule_stage_us, a.early_reply_us.take())
            }
            _ => return (Vec::new(), None),
        };
        // Speech that started before the rule fired (by more than its millisecond stamp) was not its reply.
        let done = early
            .filter(|e| e + 1000 >= at_us)
            .and_then(|e| self.reply_audio(e));
        (vec![(Stage::TranscriptToRule, rule_stage_us)], done)
    }

    /// The first PCM of an utterance of speech was published at `event_us`: the turn it answers, if any, is done.
    pub fn reply_audio(&mut self, event_us: u64) -> Option<TurnDone> {
        let answering = self.answering.as_mut()?;
        let Some(rule_us) = answering.rule_us else {
            // Its rule's message has not come yet (or it is not a reply): kept for when it does.
            if answering.early_reply_us.is_none() && event_us >= answering.transcript_us {
                answering.early_reply_us = Some(event_us);
            }
            return None;
        };
        let a = self.answering.take()?;
        Some(TurnDone {
            name: a.name,
            speech_end_us: a.speech_end_us,
            vad_us: a.vad_stage_us,
            transcript_us: a.transcript_stage_us,
            rule_us: a.rule_stage_us,
            reply_us: event_us.saturating_sub(rule_us),
            total_us: event_us.saturating_sub(a.speech_end_us),
        })
    }

    fn forget_stale(&mut self, now_us: u64) {
        self.ended
            .retain(|_, t| now_us.saturating_sub(t.vad_end_us) < STALE_US);
        if self
            .answering
            .as_ref()
            .is_some_and(|a| now_us.saturating_sub(a.transcript_us) >= STALE_US)
        {
            self.answering = None;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_whole_turn_yields_every_stage_in_order() {
        let mut t = Turns::default();
        assert_eq!(
            t.vad_end("u1", 1_000, 1_300_000),
            vec![(Stage::SpeechEndToVadEnd, 300_000)]
        );
        assert_eq!(
            t.transcript("u1", Some("00-t-s-01"), 1_340_000),
            vec![(Stage::VadEndToTranscript, 40_000)]
        );
        assert_eq!(
            t.rule("main.answer", 1_345, true),
            (vec![(Stage::TranscriptToRule, 5_000)], None)
        );
        assert_eq!(
            t.reply_audio(1_400_000),
            Some(TurnDone {
                name: TurnName {
                    utterance: "u1".into(),
                    trace: Some("00-t-s-01".into()),
                    rule: "main.answer".into(),
                },
                speech_end_us: 1_000_000,
                vad_us: 300_000,
                transcript_us: 40_000,
                rule_us: 5_000,
                reply_us: 55_000,
                total_us: 400_000,
            })
        );
        assert_eq!(t.reply_audio(1_500_000), None, "one reply per turn");
    }

    #[test]
    fn speech_nobody_asked_for_and_rules_on_other_facts_are_not_turns() {
        let mut t = Turns::default();
        assert_eq!(t.reply_audio(5_000_000), None, "a greeting");
        t.vad_end("u2", 10_000, 10_300_000);
        t.transcript("u2", None, 10_310_000);
        assert!(
            t.rule("main.greet", 10_320, false).0.is_empty(),
            "a rule on a face, not on speech"
        );
        assert_eq!(
            t.reply_audio(10_325_000),
            None,
            "speech of the greeting: no rule answered the turn yet"
        );
        let (stages, done) = t.rule("main.answer", 10_330, true);
        assert_eq!(
            (stages.len(), done),
            (1, None),
            "the greeting began before the answer's rule"
        );
        assert!(t.reply_audio(10_500_000).is_some());
    }

    #[test]
    fn a_reply_whose_first_pcm_overtakes_its_rule_message_still_completes_the_turn() {
        let mut t = Turns::default();
        t.vad_end("u1", 1_000, 1_300_000);
        t.transcript("u1", None, 1_340_000);
        // The reply's first chunk arrives before the rule's message, which says it fired just before.
        assert_eq!(t.reply_audio(1_346_500), None);
        let (stages, done) = t.rule("main.answer", 1_346, true);
        assert_eq!(stages, vec![(Stage::TranscriptToRule, 6_000)]);
        let done = done.expect("the turn completes with the rule");
        assert_eq!((done.reply_us, done.total_us), (500, 346_500));
        assert_eq!(t.reply_audio(1_400_000), None, "one reply per turn");
    }

    #[test]
    fn speech_that_began_before_the_rule_fired_is_not_its_reply() {
        let mut t = Turns::default();
        t.vad_end("u1", 1_000, 1_300_000);
        t.transcript("u1", None, 1_340_000);
        assert_eq!(
            t.reply_audio(1_341_000),
            None,
            "a greeting already under way"
        );
        let (_, done) = t.rule("main.answer", 1_350, true);
        assert_eq!(done, None);
        assert!(
            t.reply_audio(1_360_000).is_some(),
            "the reply that follows the rule"
        );
    }

    #[test]
    fn a_transcript_of_an_unknown_utterance_and_stale_turns_are_ignored() {
        let mut t = Turns::default();
        assert!(t.transcript("nobody", None, 1).is_empty());
        t.vad_end("old", 1_000, 1_000_000);
        t.vad_end("new", 40_000, 40_000_000);
        assert!(
            t.transcript("old", None, 40_100_000).is_empty(),
            "forgotten after 30 s"
        );
        assert_eq!(t.transcript("new", None, 40_100_000).len(), 1);
    }
}
