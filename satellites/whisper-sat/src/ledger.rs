//! A satellite's book of utterances: found by its own segmenter, waiting for a claim, taken by another satellite,
//! or finished by anyone. Pure bookkeeping, so the claim rules can be tested without a hub.

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

#[derive(Debug)]
struct Entry {
    utterance: ClockedUtterance,
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

    /// Records a new utterance, claimable from `eligible_at`. Ignored if it is already finished or known.
    pub fn found(&mut self, utterance: ClockedUtterance, now: Instant, eligible_at: Instant) {
        if self.is_finished(&utterance.id, interval(&utterance))
            || self.entries.iter().any(|e| e.utterance.id == utterance.id)
        {
            return;
        }
        self.entries.push_back(Entry {
            utterance,
            standing: Standing::Waiting,
            eligible_at,
            found_at: now,
        });
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

    /// The holder's claim disappeared without the utterance finishing: it may be claimed again from `eligible_at`.
    pub fn released(&mut self, id: &str, eligible_at: Instant) {
        if let Some(e) = self
            .entries
            .iter_mut()
            .find(|e| e.utterance.id == id && e.standing == Standing::Taken)
        {
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
    pub fn next_claimable(&mut self, now: Instant) -> Option<ClockedUtterance> {
        let max_age = self.max_age;
        self.entries
            .retain(|e| now.duration_since(e.found_at) < max_age);
        let i = self
            .entries
            .iter()
            .position(|e| e.standing == Standing::Waiting && e.eligible_at <= now)?;
        self.entries.remove(i).map(|e| e.utterance)
    }

    /// Puts back an utterance taken out by `next_claimable` (its claim failed because another holds it).
    pub fn put_back(&mut self, utterance: ClockedUtterance, standing: Standing, now: Instant) {
        let entry = Entry {
            utterance,
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
            .filter(|e| e.standing == Standing::Waiting)
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
        }
    }

    #[test]
    fn claims_oldest_first_and_respects_eligibility() {
        let t0 = Instant::now();
        let later = t0 + Duration::from_millis(300);
        let mut l = Ledger::new(Duration::from_secs(60));
        l.found(utt("a", 0, 1_000_000), t0, later);
        l.found(utt("b", 2_000_000, 3_000_000), t0, t0);
        assert_eq!(l.next_claimable(t0).map(|u| u.id), Some("b".into()));
        assert_eq!(l.next_claimable(t0), None);
        assert_eq!(l.next_deadline(), Some(later));
        assert_eq!(l.next_claimable(later).map(|u| u.id), Some("a".into()));
    }

    #[test]
    fn taken_utterances_wait_for_release_or_finish() {
        let t0 = Instant::now();
        let mut l = Ledger::new(Duration::from_secs(60));
        l.found(utt("a", 0, 1_000_000), t0, t0);
        let u = l.next_claimable(t0).expect("claimable");
        l.put_back(u, Standing::Taken, t0);
        assert_eq!(l.next_claimable(t0), None);
        l.released("a", t0);
        assert_eq!(l.standing("a"), Some(Standing::Waiting));
        l.taken("a");
        // Finished by a transcript whose interval differs slightly: the same speech, dropped.
        l.finished("a2", 50_000, 1_020_000);
        assert!(l.is_empty());
        // Seen again later (a late segmenter): still finished.
        l.found(utt("a", 0, 1_000_000), t0, t0);
        assert!(l.is_empty());
    }

    #[test]
    fn stale_utterances_expire() {
        let t0 = Instant::now();
        let mut l = Ledger::new(Duration::from_secs(1));
        l.found(utt("a", 0, 1), t0, t0);
        assert_eq!(l.next_claimable(t0 + Duration::from_secs(2)), None);
        assert!(l.is_empty());
    }
}
