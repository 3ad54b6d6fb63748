//! A finished turn as the spans robot-agent records for it: the root `turn` (end of speech -> first reply PCM) and
//! its four stages, each from the hub stamps `Agent.latency` is computed from, so the stages add up to the turn
//! and the turn to `total_ms`; then the page's `playback`. The satellites' spans hang under these by id
//! (docs/telemetry.md): `whisper.decode` under `transcription`, `llm.generate` and `synthesis` under `reply`. Pure.

use flow_telemetry::{SpanRecord, TraceContext};

use super::turns::TurnDone;

/// The names of the stage spans, in order; a stage's span id is the turn's `child(name)`.
pub const STAGES: [&str; 4] = ["voice_activity", "transcription", "rule", "reply"];

/// The turn's context: the one its transcript carried, else the one every process derives from its utterance.
pub fn turn_context(done: &TurnDone) -> TraceContext {
    done.name
        .trace
        .as_deref()
        .and_then(|t| TraceContext::parse(t).ok())
        .unwrap_or_else(|| TraceContext::turn(&done.name.utterance))
}

/// The root span and the four stages of `done`.
pub fn turn_spans(done: &TurnDone) -> Vec<SpanRecord> {
    let turn = turn_context(done);
    let start = done.speech_end_us;
    let end = start + done.total_us;
    let mut spans = vec![
        SpanRecord::root("turn", turn, start, end)
            .with("utterance", done.name.utterance.as_str())
            .with("rule", done.name.rule.as_str()),
    ];
    let mut from = start;
    let durations = [done.vad_us, done.transcript_us, done.rule_us, done.reply_us];
    for (i, (name, us)) in STAGES.into_iter().zip(durations).enumerate() {
        // The last stage ends with the turn, whatever rounding the rule's millisecond stamp left.
        let to = if i == STAGES.len() - 1 {
            end.max(from)
        } else {
            (from + us).min(end)
        };
        let span = SpanRecord::under(turn, name, from, to);
        spans.push(if name == "rule" {
            span.with("rule", done.name.rule.as_str())
        } else {
            span
        });
        from = to;
    }
    spans
}

/// The page's playback start of the reply: from its first PCM on the hub to when the holder's page says the user
/// hears it begin (`Agent.playback`), under the turn. It starts where the turn ends: the turn is what the agent
/// controls, this is the route to the ear (the page's jitter buffer and the loopback the echo canceller covers).
pub fn playback_span(done: &TurnDone, heard_us: u64) -> SpanRecord {
    let end = done.speech_end_us + done.total_us;
    SpanRecord::under(turn_context(done), "playback", end, heard_us)
}

#[cfg(test)]
mod tests {
    use super::super::turns::Turns;
    use super::*;

    /// A whole turn as the observer follows it: speech ends at 1.0 s, the VAD says so at 1.3 s, the transcript comes
    /// at 1.34 s, the rule at 1.345 s and the reply's first PCM at 1.4 s.
    fn done(trace: Option<String>) -> TurnDone {
        let mut turns = Turns::default();
        turns.vad_end("u1000", 1_000, 1_300_000);
        turns.transcript("u1000", trace.as_deref(), 1_340_000);
        turns.rule("main.answer", 1_345, true);
        turns.reply_audio(1_400_000).expect("a whole turn")
    }

    #[test]
    fn the_stages_follow_each_other_under_the_turn_and_add_up_to_it() {
        let spans = turn_spans(&done(None));
        let root = &spans[0];
        assert_eq!((root.name, root.parent), ("turn", None));
        assert_eq!(root.context, TraceContext::turn("u1000"));
        assert_eq!((root.start_us, root.end_us), (1_000_000, 1_400_000));
        let names: Vec<_> = spans[1..].iter().map(|s| s.name).collect();
        assert_eq!(names, STAGES);
        let mut at = root.start_us;
        for s in &spans[1..] {
            assert_eq!(s.parent, Some(root.context.span));
            assert_eq!(s.context, root.context.child(s.name));
            assert_eq!(
                s.start_us, at,
                "{} starts where the last stage ended",
                s.name
            );
            at = s.end_us;
        }
        assert_eq!(at, root.end_us);
        let sum: u64 = spans[1..].iter().map(SpanRecord::duration_us).sum();
        assert_eq!(sum, root.duration_us());
    }

    #[test]
    fn the_trace_the_transcript_carried_wins_and_a_malformed_one_falls_back_to_the_utterances() {
        let other = TraceContext::turn("elsewhere");
        let spans = turn_spans(&done(Some(other.traceparent())));
        assert_eq!(spans[0].context, other);
        let spans = turn_spans(&done(Some("garbage".into())));
        assert_eq!(spans[0].context, TraceContext::turn("u1000"));
    }

    #[test]
    fn the_playback_follows_the_turn_under_its_root() {
        let d = done(None);
        let span = playback_span(&d, 1_480_000);
        assert_eq!(span.parent, Some(TraceContext::turn("u1000").span));
        assert_eq!((span.start_us, span.end_us), (1_400_000, 1_480_000));
        // A page clock that puts the start before the first PCM makes an empty span, not a negative one.
        assert_eq!(playback_span(&d, 1_300_000).duration_us(), 0);
    }

    #[test]
    fn a_rule_stamped_before_its_transcript_still_ends_the_reply_with_the_turn() {
        let mut d = done(None);
        // The rule's millisecond stamp rounded below the transcript: its stage saturated to 0 and the reply took
        // the microseconds the turn has over the sum.
        d.rule_us = 0;
        d.reply_us = 59_500;
        let spans = turn_spans(&d);
        assert_eq!(spans[4].end_us, spans[0].end_us);
        let sum: u64 = spans[1..].iter().map(SpanRecord::duration_us).sum();
        assert_eq!(sum, spans[0].duration_us());
    }
}
