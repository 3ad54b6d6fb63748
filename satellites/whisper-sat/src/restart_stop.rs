//! Ending a greedy decode as soon as it starts saying the utterance again: whisper.cpp's logits filter, which
//! forces the end-of-text token once the tokens decoded so far end with a repeat of their own beginning.
//!
//! With the fitted encoder window (docs/asr.md), short utterances are often transcribed whole and then said again
//! and again until the token cap ("How many people do you see? How many people do you see? How many..."). The
//! transcriber keeps such an output once ([`crate::transcriber::repeated_utterance`]), but by then the decoder has
//! spent a step on every repeated token: measured with tiny.en on two cores, 22-29 tokens instead of 3-7, about
//! 60-100 ms of a 150-200 ms inference, all of it on the critical path of a reply. This filter watches the tokens as
//! they come and ends the decode once the phrase has been said a second time whole, when it holds enough words for
//! the audio (the same tests as the whole-output rule), keeping the phrase once: what that rule keeps, unless the
//! decoder would have strayed only after the second time (then the rule found no clean repetition and the full
//! window decoded it again; docs/asr.md has the one such utterance measured). Not
//! earlier: a second time that strays from the first ("nessuno ulteriore messaggio nessun ulteriore messaggio.")
//! marks a decode the model is unsure of, which goes on to the token cap and the full-window retry as before (ending
//! such a decode three tokens into the repeat cost a word on the Italian prompts).
//!
//! whisper-rs has no safe setter for the logits filter, so the raw one is used here, and `unsafe` is kept to this
//! module: the callback reads the token slice and writes the logits slice that whisper.cpp hands it, and the
//! [`RestartStop`] behind the user-data pointer, which the borrow checker keeps alive for as long as the parameters
//! can be used.

#![allow(unsafe_code)]

use std::ffi::{c_int, c_void};
use std::sync::atomic::{AtomicUsize, Ordering};

use whisper_rs::{
    FullParams, WhisperContext, WhisperSysContext, WhisperSysState, WhisperTokenData,
};

/// Which tokens of a model's vocabulary begin a word, computed once per model.
#[derive(Debug, Clone)]
pub struct WordStarts {
    /// Per token id: 1 when the token holds a letter or digit and begins with a space (a word of its own), 2 when it
    /// holds one without the space (the rest of a word, or the first word of a text), 3 for a sentence's end (`.`,
    /// `?`, `!`), 0 for other punctuation.
    marks: Vec<u8>,
}

impl WordStarts {
    /// Marks every token of `ctx`'s vocabulary.
    pub fn of(ctx: &WhisperContext) -> Self {
        let n = usize::try_from(ctx.n_vocab()).unwrap_or(0);
        let marks = (0..n)
            .map(|id| {
                let bytes = i32::try_from(id)
                    .ok()
                    .and_then(|id| ctx.token_to_bytes(id).ok())
                    .unwrap_or_default();
                Self::mark(bytes)
            })
            .collect();
        Self { marks }
    }

    /// The mark of one token's text (bytes, since a multilingual token may hold part of a character).
    fn mark(bytes: &[u8]) -> u8 {
        // Bytes from 0x80 up belong to non-ASCII characters, letters in every language Whisper writes.
        let wordy = bytes
            .iter()
            .any(|b| b.is_ascii_alphanumeric() || *b >= 0x80);
        let sentence_end = matches!(bytes.trim_ascii(), b"." | b"?" | b"!" | b"?!" | b"!?");
        match (wordy, bytes.first()) {
            (false, _) if sentence_end => 3,
            (false, _) => 0,
            (true, Some(b' ')) => 1,
            (true, _) => 2,
        }
    }

    /// Words in a text of `tokens`: every token that begins one, and the first token holding a letter when it has
    /// no space before it.
    pub fn words(&self, tokens: impl IntoIterator<Item = i32>) -> usize {
        let mut words = 0;
        for id in tokens {
            match usize::try_from(id).ok().and_then(|i| self.marks.get(i)) {
                Some(1) => words += 1,
                Some(2) if words == 0 => words += 1,
                _ => {}
            }
        }
        words
    }

    /// Whether the token `id` ends a sentence (`.`, `?`, `!`).
    pub fn ends_sentence(&self, id: i32) -> bool {
        usize::try_from(id)
            .ok()
            .and_then(|i| self.marks.get(i))
            .is_some_and(|&m| m == 3)
    }
}

/// The length of the phrase that `tokens` are, said twice: `tokens[..p] == tokens[p..]`.
pub fn restarted_phrase(tokens: &[i32]) -> Option<usize> {
    restarted_phrase_of(tokens, |&id| id)
}

/// [`restarted_phrase`] over any token records, compared by the id `id` reads from each: the filter runs it on
/// whisper.cpp's records as they are, with no copy per decoder step.
fn restarted_phrase_of<T>(tokens: &[T], id: impl Fn(&T) -> i32) -> Option<usize> {
    let n = tokens.len();
    let p = n / 2;
    (n >= 2 && n.is_multiple_of(2) && tokens[..p].iter().map(&id).eq(tokens[p..].iter().map(&id)))
        .then_some(p)
}

/// One decode's watch for a restart: what it needs to judge one, and what it found.
#[derive(Debug)]
pub struct RestartStop<'w> {
    words: &'w WordStarts,
    /// Fewest words the repeated phrase must hold to stand for the whole utterance.
    min_words: f32,
    /// Fewest words a sentence must hold to be taken for the whole utterance when a repeat starts after it.
    min_sentence_words: f32,
    eot: c_int,
    n_vocab: usize,
    /// The length in tokens of the phrase the decode was ended on, or 0.
    phrase: AtomicUsize,
}

impl<'w> RestartStop<'w> {
    /// A watch for a decode of `ctx` whose repeated phrase counts only with `min_words` words or more, and a
    /// sentence followed by the start of a repeat with `min_sentence_words` or more.
    pub fn new(
        ctx: &WhisperContext,
        words: &'w WordStarts,
        min_words: f32,
        min_sentence_words: f32,
    ) -> Self {
        Self {
            words,
            min_words,
            min_sentence_words,
            eot: ctx.token_eot(),
            n_vocab: usize::try_from(ctx.n_vocab()).unwrap_or(0),
            phrase: AtomicUsize::new(0),
        }
    }

    /// The length in tokens of the phrase the decode was ended on, once it was.
    pub fn phrase(&self) -> Option<usize> {
        match self.phrase.load(Ordering::Relaxed) {
            0 => None,
            p => Some(p),
        }
    }

    /// Whether the decode should end before `tokens` go on: they say their beginning again, and that beginning
    /// holds enough words. Records the phrase when so.
    fn should_end<T>(&self, tokens: &[T], id: impl Fn(&T) -> i32) -> bool {
        let Some(p) = restarted_phrase_of(tokens, &id) else {
            return false;
        };
        self.keep_if_enough_words(tokens, p, self.min_words, id)
    }

    /// Whether the decode should end at once because `tokens` are a whole sentence (they end with `.`, `?` or `!`)
    /// and the token the decoder is about to pick, `next()`, is their first one again: the fitted window's repeat
    /// starting. The sentence must hold enough words for the whole audio at an ordinary pace of speech
    /// (`min_sentence_words`, more than a repeated phrase needs), so that the first sentence of several, even one
    /// whose next sentence opens with the same word ("I went home. I slept."), is not taken for the whole. This
    /// saves the decoder steps of the second time through, which [`Self::should_end`] waits for; a decode whose
    /// first time through ends unpunctuated still waits for it (a second time that strays marks a decode the model
    /// is unsure of). `next` is only asked once the tokens end a sentence, since it scans the whole vocabulary.
    /// Records the phrase when so.
    fn ends_a_sentence_then_restarts<T>(
        &self,
        tokens: &[T],
        next: impl FnOnce() -> i32,
        id: impl Fn(&T) -> i32,
    ) -> bool {
        let (Some(first), Some(last)) = (tokens.first(), tokens.last()) else {
            return false;
        };
        if tokens.len() < 2 || !self.words.ends_sentence(id(last)) || id(first) != next() {
            return false;
        }
        self.keep_if_enough_words(tokens, tokens.len(), self.min_sentence_words, id)
    }

    /// Records `tokens[..p]` as the phrase kept when it holds at least `min_words` words.
    fn keep_if_enough_words<T>(
        &self,
        tokens: &[T],
        p: usize,
        min_words: f32,
        id: impl Fn(&T) -> i32,
    ) -> bool {
        if (self.words.words(tokens[..p].iter().map(&id)) as f32) < min_words {
            return false;
        }
        self.phrase.store(p, Ordering::Relaxed);
        true
    }

    /// Makes decoding with `params` end when it restarts. The watch is borrowed for the parameters' lifetime, so it
    /// outlives every inference that can run with them. Only for greedy decoding with one decoder and no temperature
    /// fallback (as the transcriber decodes): beam search or `best_of` filter several decoders' logits, possibly at
    /// once, and a fallback pass would decode again after a stop, while one watch records one phrase.
    pub fn attach<'a>(&'a self, params: &mut FullParams<'a, '_>) {
        // SAFETY: `filter` only reads the `RestartStop` behind the user-data pointer (its one mutable field is an
        // atomic), which is borrowed for `'a`, as long as `params` may be used; whisper.cpp calls the filter only
        // during `whisper_full` with these parameters.
        unsafe {
            params.set_filter_logits_callback(Some(filter));
            params.set_filter_logits_callback_user_data(
                std::ptr::from_ref(self).cast_mut().cast::<c_void>(),
            );
        }
    }
}

/// whisper.cpp's logits filter: before each decoder step, with the tokens so far and the next token's logits.
unsafe extern "C" fn filter(
    _ctx: *mut WhisperSysContext,
    _state: *mut WhisperSysState,
    tokens: *const WhisperTokenData,
    n_tokens: c_int,
    logits: *mut f32,
    user_data: *mut c_void,
) {
    let Ok(n) = usize::try_from(n_tokens) else {
        return;
    };
    if user_data.is_null() || tokens.is_null() || logits.is_null() || n < 2 {
        return;
    }
    // SAFETY: `RestartStop::attach` is the only place this filter is installed, always with a pointer to a
    // `RestartStop` that lives as long as the parameters (see there); it is only read here, apart from its atomic.
    let stop = unsafe { &*user_data.cast::<RestartStop>() };
    // SAFETY: whisper.cpp passes the decoder's `n_tokens` tokens so far, a live vector it does not touch while the
    // filter runs.
    let tokens = unsafe { std::slice::from_raw_parts(tokens, n) };
    let Ok(eot) = usize::try_from(stop.eot) else {
        return;
    };
    if eot >= stop.n_vocab {
        return;
    }
    // SAFETY: whisper.cpp passes the next token's logits, one per vocabulary entry (`n_vocab`, asserted there), in
    // a vector of its decoder that nothing else touches while the filter runs.
    let logits = unsafe { std::slice::from_raw_parts_mut(logits, stop.n_vocab) };
    let end = stop.should_end(tokens, |t| t.id)
        || stop.ends_a_sentence_then_restarts(tokens, || best(logits), |t| t.id);
    if !end {
        return;
    }
    logits.fill(f32::NEG_INFINITY);
    logits[eot] = 0.0;
}

/// The id of the highest logit (the token a greedy decoder picks next); -1 for no logits.
fn best(logits: &[f32]) -> i32 {
    logits
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .and_then(|(i, _)| i32::try_from(i).ok())
        .unwrap_or(-1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_phrase_counts_once_it_is_said_a_second_time_whole() {
        let phrase = [10, 11, 12, 13, 14, 15, 16];
        let mut tokens = phrase.to_vec();
        for &t in &phrase[..6] {
            tokens.push(t);
            assert_eq!(
                restarted_phrase(&tokens),
                None,
                "{} tokens of the repeat",
                tokens.len() - 7
            );
        }
        tokens.push(phrase[6]);
        assert_eq!(restarted_phrase(&tokens), Some(7));
        assert_eq!(restarted_phrase(&[1, 2, 1, 2]), Some(2));
        assert_eq!(restarted_phrase(&[5, 5]), Some(1));
    }

    #[test]
    fn a_second_time_that_strays_from_the_first_is_no_restart() {
        // "nessuno ulteriore messaggio nessun ulteriore messaggio": the model is unsure, and is left to go on.
        assert_eq!(restarted_phrase(&[1, 2, 3, 4, 1, 9, 3, 4]), None);
        // "the cat saw the dog": the first token comes back, but what follows it does not.
        assert_eq!(restarted_phrase(&[1, 2, 3, 1, 4]), None);
        assert_eq!(restarted_phrase(&[1, 2, 3, 1, 2, 4]), None);
        assert_eq!(restarted_phrase(&[]), None);
        assert_eq!(restarted_phrase(&[7]), None);
    }

    fn vocabulary() -> WordStarts {
        // 0 " How", 1 " many", 2 "?", 3 "How", 4 "atively", 5 " è", 6 ",".
        let texts: [&[u8]; 7] = [
            b" How",
            b" many",
            b"?",
            b"How",
            b"atively",
            " è".as_bytes(),
            b",",
        ];
        WordStarts {
            marks: texts.iter().map(|t| WordStarts::mark(t)).collect(),
        }
    }

    /// A watch over [`vocabulary`] with the given word minimums (no model needed: the fields are set directly).
    fn watch(words: &WordStarts, min_words: f32, min_sentence_words: f32) -> RestartStop<'_> {
        RestartStop {
            words,
            min_words,
            min_sentence_words,
            eot: 7,
            n_vocab: 8,
            phrase: AtomicUsize::new(0),
        }
    }

    #[test]
    fn a_whole_sentence_ends_the_decode_as_soon_as_its_repeat_begins() {
        let v = vocabulary();
        // " How many?" and the decoder about to say " How" again: ended now, the sentence kept whole.
        let stop = watch(&v, 1.0, 2.0);
        assert!(stop.ends_a_sentence_then_restarts(&[0, 1, 2], || 0, |&t| t));
        assert_eq!(stop.phrase(), Some(3));
        // Another word next, no sentence end yet, or too few words for the audio: the decode goes on.
        let stop = watch(&v, 1.0, 2.0);
        assert!(!stop.ends_a_sentence_then_restarts(&[0, 1, 2], || 1, |&t| t));
        assert!(!stop.ends_a_sentence_then_restarts(&[0, 1], || 0, |&t| t));
        assert!(!stop.ends_a_sentence_then_restarts(&[0, 1, 6], || 0, |&t| t));
        assert!(!watch(&v, 1.0, 2.5).ends_a_sentence_then_restarts(&[0, 1, 2], || 0, |&t| t));
        assert_eq!(stop.phrase(), None);
    }

    #[test]
    fn only_full_stops_question_and_exclamation_marks_end_a_sentence() {
        for (text, ends) in [
            (&b"."[..], true),
            (b"?", true),
            (b" !", true),
            (b",", false),
            (b"...", false),
            (b" many", false),
        ] {
            assert_eq!(WordStarts::mark(text) == 3, ends, "{text:?}");
        }
    }

    #[test]
    fn words_are_counted_from_the_tokens_that_begin_them() {
        let v = vocabulary();
        assert_eq!(v.words([0, 1, 2]), 2);
        assert_eq!(
            v.words([3, 1, 6, 5]),
            3,
            "a first word without its space counts"
        );
        assert_eq!(v.words([0, 4]), 1, "the rest of a word is not another");
        assert_eq!(v.words([2, 6]), 0);
        assert_eq!(
            v.words([99, -1]),
            0,
            "ids outside the vocabulary count for nothing"
        );
    }

    #[test]
    fn the_filter_ends_a_restart_only_when_the_phrase_holds_enough_words() {
        let v = vocabulary();
        let stop = |min_words| watch(&v, min_words, 100.0);
        let enough = stop(1.5);
        assert!(enough.should_end(&[0, 1, 2, 0, 1, 2], |&id| id));
        assert_eq!(enough.phrase(), Some(3));
        let too_few = stop(2.5);
        assert!(!too_few.should_end(&[0, 1, 2, 0, 1, 2], |&id| id));
        assert_eq!(too_few.phrase(), None);
    }

    #[test]
    fn the_callback_forces_the_end_of_text_token_on_a_restart() {
        let v = vocabulary();
        let stop = watch(&v, 1.0, 100.0);
        let token = |id| WhisperTokenData {
            id,
            tid: 0,
            p: 0.5,
            plog: -0.7,
            pt: 0.0,
            ptsum: 0.0,
            t0: 0,
            t1: 0,
            t_dtw: 0,
            vlen: 0.0,
        };
        let user = std::ptr::from_ref(&stop).cast_mut().cast::<c_void>();
        let mut logits = [1.0f32; 8];
        let going_on = [token(0), token(1), token(2), token(0)];
        // SAFETY: live slices of the lengths passed, and a pointer to a live `RestartStop`, as whisper.cpp and
        // `attach` pass them.
        unsafe {
            filter(
                std::ptr::null_mut(),
                std::ptr::null_mut(),
                going_on.as_ptr(),
                4,
                logits.as_mut_ptr(),
                user,
            );
        }
        assert_eq!(
            logits, [1.0; 8],
            "no restart yet: the logits are left alone"
        );
        let restarted = [token(0), token(1), token(2), token(0), token(1), token(2)];
        // SAFETY: as above.
        unsafe {
            filter(
                std::ptr::null_mut(),
                std::ptr::null_mut(),
                restarted.as_ptr(),
                6,
                logits.as_mut_ptr(),
                user,
            );
        }
        assert_eq!(logits[7], 0.0);
        assert!(logits[..7].iter().all(|l| *l == f32::NEG_INFINITY));
        assert_eq!(stop.phrase(), Some(3));

        // A whole sentence (" How many?") with the decoder's best next token its first one again: ended at once.
        let stop = watch(&v, 1.0, 2.0);
        let user = std::ptr::from_ref(&stop).cast_mut().cast::<c_void>();
        let mut logits = [0.0f32; 8];
        logits[0] = 5.0;
        let sentence = [token(0), token(1), token(2)];
        // SAFETY: as above.
        unsafe {
            filter(
                std::ptr::null_mut(),
                std::ptr::null_mut(),
                sentence.as_ptr(),
                3,
                logits.as_mut_ptr(),
                user,
            );
        }
        assert_eq!(logits[7], 0.0);
        assert_eq!(stop.phrase(), Some(3));
    }
}
