//! A satellite's book of utterances: found by its own segmenter, waiting for a claim, taken by another satellite,
//! or finished by anyone. Pure bookkeeping, so the claim rules can be tested without a hub.
//!
//! With speculation an utterance enters the book when it pauses, before it has ended: the entry then holds the
//! provisional utterance, which the next pause or the end replaces under the same id (the id is the start, which a
//! pause does not change). When the voice resumes, the provisional audio is out of date and the entry is not
//! claimed until the segmenter reports the utterance again; a claim already made on it stays valid.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use crate::claim::overlaps;
use crate::stream::ClockedUtterance;

/// Two utterances whose intervals share more than this are the same speech seen by differently warmed-up
/// segmenters.
pub const SAME_SPEECH_US: u64 = 200_000;

/// Where an utterance stands for this satellite.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Standing {
    /// May be claimed from `eligible_at` on.
    Waiting,
    /// Another satellite holds the claim.
    Taken,
}

/// An utterance as the book hands it out for a claim.
#[derive(Debug, Clone, PartialEq)]
pub struct Pending {
    pub utterance: ClockedUtterance,
    /// False while the utterance is only paused: it may still grow.
    pub ended: bool,
}

#[derive(Debug)]
struct Entry {
    utterance: ClockedUtterance,
    ended: bool,
    /// The voice resumed after the pause this entry holds: its audio is not what will be transcribed.
    stale: bool,
    standing: Standing,
    eligible_at: Instant,
    found_at: Instant,
}

/// Utterances this satellite knows about and has not seen finished.
#[derive(Debug)]
pub struct Ledger {
    entries: VecDeque<Entry>,
    /// Intervals of utterances known to be finished (transcribed or rejected), newest last.
    finished: VecDeque<(String, u64, u64)>,
    max_age: Duration,
}

impl Ledger {
    /// `max_age`: utterances older than this are given up (their audio is stale for a conversation).
    pub fn new(max_age: Duration) -> Self {
        Self {
            entries: VecDeque::new(),
            finished: VecDeque::new(),
            max_age,
        }
    }

    /// Records an utterance that paused (`ended` false) or ended, claimable from `eligible_at`. An utterance already
    /// in the book is brought up to date under its id (keeping its standing and eligibility); one already finished
    /// is ignored.
    pub fn found(
        &mut self,
        utterance: ClockedUtterance,
        ended: bool,
        now: Instant,
        eligible_at: Instant,
    ) {
        if self.is_finished(&utterance.id, interval(&utterance)) {
            return;
        }
        if let Some(e) = self
            .entries
            .iter_mut()
            .find(|e| e.utterance.id == utterance.id)
        {
            e.utterance = utterance;
            e.ended = ended;
            e.stale = false;
            return;
        }
        self.entries.push_back(Entry {
            utterance,
            ended,
            stale: false,
            standing: Standing::Waiting,
            eligible_at,
            found_at: now,
        });
    }

    /// The voice of a paused utterance came back: it is not claimed again until it pauses again or ends.
    pub fn resumed(&mut self, id: &str) {
        if let Some(e) = self.entries.iter_mut().find(|e| e.utterance.id == id) {
            e.stale = true;
        }
    }

    /// Forgets an utterance that will never be transcribed (recognition was switched off while it was open).
    pub fn forget(&mut self, id: &str) {
        self.entries.retain(|e| e.utterance.id != id);
    }

    /// Marks an utterance finished by anyone (a transcript seen, or a claim marked done), dropping every entry that
    /// is the same speech.
    pub fn finished(&mut self, id: &str, start_us: u64, end_us: u64) {
        self.finished.push_back((id.to_owned(), start_us, end_us));
        while self.finished.len() > 1024 {
            self.finished.pop_front();
        }
        self.entries.retain(|e| {
            e.utterance.id != id
                && !overlaps(interval(&e.utterance), (start_us, end_us), SAME_SPEECH_US)
        });
    }

    /// True when this speech was finished already.
    pub fn is_finished(&self, id: &str, span: (u64, u64)) -> bool {
        self.finished
            .iter()
            .any(|(f, s, e)| f == id || overlaps(span, (*s, *e), SAME_SPEECH_US))
    }

    /// Another satellite holds this utterance.
    pub fn taken(&mut self, id: &str) {
        if let Some(e) = self.entries.iter_mut().find(|e| e.utterance.id == id) {
            e.standing = Standing::Taken;
        }
    }

    /// The holder's claim on `id` disappeared without the utterance finishing: it may be claimed again from
    /// `eligible_at`. `span`, the claim's interval when its header was seen, also releases the entries of the same
    /// speech under other ids: a satellite on another hub stamps the audio a network hop later and so can name the
    /// same speech a millisecond apart, and the entry this satellite put back as taken because of that claim must
    /// not stay taken once the claim is gone. (A release is only a chance to claim: the claim attempt still looks for
    /// any other live claim on the speech first.)
    pub fn released(&mut self, id: &str, span: Option<(u64, u64)>, eligible_at: Instant) {
        for e in self.entries.iter_mut().filter(|e| {
            e.standing == Standing::Taken
                && (e.utterance.id == id
                    || span.is_some_and(|s| overlaps(interval(&e.utterance), s, SAME_SPEECH_US)))
        }) {
            e.standing = Standing::Waiting;
            e.eligible_at = eligible_at;
        }
    }

    /// Postpones a claim attempt that failed for a passing reason.
    pub fn retry_later(&mut self, id: &str, eligible_at: Instant) {
        if let Some(e) = self.entries.iter_mut().find(|e| e.utterance.id == id) {
            e.eligible_at = eligible_at;
        }
    }

    /// Removes and returns the oldest utterance that may be claimed now, dropping expired ones on the way.
    pub fn next_claimable(&mut self, now: Instant) -> Option<Pending> {
        let max_age = self.max_age;
        self.entries
            .retain(|e| now.duration_since(e.found_at) < max_age);
        let i = self
            .entries
            .iter()
            .position(|e| e.claimable() && e.eligible_at <= now)?;
        self.entries.remove(i).map(|e| Pending {
            utterance: e.utterance,
            ended: e.ended,
        })
    }

    /// Puts back an utterance taken out by `next_claimable` (its claim failed because another holds it).
    pub fn put_back(&mut self, pending: Pending, standing: Standing, now: Instant) {
        let entry = Entry {
            utterance: pending.utterance,
            ended: pending.ended,
            stale: false,
            standing,
            eligible_at: now,
            found_at: now,
        };
        self.entries.push_front(entry);
    }

    /// When the next waiting entry becomes claimable (for the caller's timer).
    pub fn next_deadline(&self) -> Option<Instant> {
        self.entries
            .iter()
            .filter(|e| e.claimable())
            .map(|e| e.eligible_at)
            .min()
    }

    /// The standing of an utterance, if it is in the book.
    pub fn standing(&self, id: &str) -> Option<Standing> {
        self.entries
            .iter()
            .find(|e| e.utterance.id == id)
            .map(|e| e.standing)
    }

    /// Number of utterances in the book.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// True when nothing waits.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }
}

impl Entry {
    fn claimable(&self) -> bool {
        self.standing == Standing::Waiting && !self.stale
    }
}

fn interval(u: &ClockedUtterance) -> (u64, u64) {
    (u.start_us, u.speech_end_us)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn utt(id: &str, start: u64, end: u64) -> ClockedUtterance {
        ClockedUtterance {
            id: id.into(),
            start_us: start,
            speech_end_us: end,
            audio: Vec::new(),
            forced: false,
            closed_us: end,
        }
    }

    #[test]
    fn claims_oldest_first_and_respects_eligibility() {
        let t0 = Instant::now();
        let later = t0 + Duration::from_millis(300);
        let mut l = Ledger::new(Duration::from_secs(60));
        l.found(utt("a", 0, 1_000_000), true, t0, later);
        l.found(utt("b", 2_000_000, 3_000_000), true, t0, t0);
        assert_eq!(
            l.next_claimable(t0).map(|p| p.utterance.id),
            Some("b".into())
        );
        assert_eq!(l.next_claimable(t0), None);
        assert_eq!(l.next_deadline(), Some(later));
        assert_eq!(
            l.next_claimable(later).map(|p| p.utterance.id),
            Some("a".into())
        );
    }

    #[test]
    fn taken_utterances_wait_for_release_or_finish() {
        let t0 = Instant::now();
        let mut l = Ledger::new(Duration::from_secs(60));
        l.found(utt("a", 0, 1_000_000), true, t0, t0);
        let p = l.next_claimable(t0).expect("claimable");
        l.put_back(p, Standing::Taken, t0);
        assert_eq!(l.next_claimable(t0), None);
        l.released("a", None, t0);
        assert_eq!(l.standing("a"), Some(Standing::Waiting));
        l.taken("a");
        // Finished by a transcript whose interval differs slightly: the same speech, dropped.
        l.finished("a2", 50_000, 1_020_000);
        assert!(l.is_empty());
        // Seen again later (a late segmenter): still finished.
        l.found(utt("a", 0, 1_000_000), true, t0, t0);
        assert!(l.is_empty());
    }

    #[test]
    fn a_paused_utterance_is_brought_up_to_date_and_waits_while_the_voice_goes_on() {
        let t0 = Instant::now();
        let mut l = Ledger::new(Duration::from_secs(60));
        l.found(utt("a", 0, 400_000), false, t0, t0);
        // Another satellite claimed it at the pause; then the voice resumed and the utterance ended longer.
        l.taken("a");
        l.resumed("a");
        l.found(utt("a", 0, 1_500_000), true, t0, t0);
        assert_eq!(l.standing("a"), Some(Standing::Taken));
        assert_eq!(l.len(), 1);
        // The holder died: what is claimed again is the whole utterance, not the pause.
        l.released("a", None, t0);
        let p = l.next_claimable(t0).expect("claimable");
        assert_eq!(
            p,
            Pending {
                utterance: utt("a", 0, 1_500_000),
                ended: true
            }
        );
        // Nobody claimed a pause before the voice resumed: it waits for the next pause or the end.
        l.found(utt("b", 2_000_000, 2_400_000), false, t0, t0);
        l.resumed("b");
        assert_eq!(l.next_claimable(t0), None);
        assert_eq!(l.next_deadline(), None);
        l.found(utt("b", 2_000_000, 2_900_000), false, t0, t0);
        let p = l.next_claimable(t0).expect("claimable again");
        assert_eq!((p.utterance.speech_end_us, p.ended), (2_900_000, false));
        // Recognition switched off while it was open: forgotten.
        l.put_back(p, Standing::Taken, t0);
        l.forget("b");
        assert!(l.is_empty());
    }

    #[test]
    fn a_vanished_claim_under_another_id_releases_the_same_speech_only() {
        let t0 = Instant::now();
        let mut l = Ledger::new(Duration::from_secs(60));
        // A satellite on another hub claimed this speech as "u1001"; this satellite heard it as "u1000".
        l.found(utt("u1000", 1_000_000, 2_500_000), true, t0, t0);
        l.found(utt("u5000", 5_000_000, 6_000_000), true, t0, t0);
        l.taken("u1000");
        l.taken("u5000");
        // Its id alone finds nothing here; its interval finds the same speech and nothing else.
        l.released("u1001", None, t0);
        assert_eq!(l.standing("u1000"), Some(Standing::Taken));
        l.released("u1001", Some((1_001_000, 2_400_000)), t0);
        assert_eq!(l.standing("u1000"), Some(Standing::Waiting));
        assert_eq!(l.standing("u5000"), Some(Standing::Taken));
    }

    #[test]
    fn stale_utterances_expire() {
        let t0 = Instant::now();
        let mut l = Ledger::new(Duration::from_secs(1));
        l.found(utt("a", 0, 1), true, t0, t0);
        assert_eq!(l.next_claimable(t0 + Duration::from_secs(2)), None);
        assert!(l.is_empty());
    }
}
