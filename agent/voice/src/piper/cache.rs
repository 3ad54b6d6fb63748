//! The sentences the voice spoke last, kept so that the program's fixed replies and greetings ("Nice to see you.",
//! "Let me think.") are played without running the network again: least recently used first out, bounded by the
//! audio they hold. A sentence is found by its text and the request's rate and volume; the voice and its noise and
//! length settings are fixed for the voice the cache belongs to, so a new voice starts with an empty cache.

use std::collections::VecDeque;
use std::sync::Arc;

use super::spoken::Sentence;

/// What a sentence was spoken with, besides the voice.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Key {
    pub text: String,
    /// The request's length multiplier (its rate).
    pub length: f32,
    /// The request's gain (its volume).
    pub gain: f32,
}

/// The cache: at most `capacity` samples of audio.
#[derive(Debug)]
pub(crate) struct SentenceCache {
    entries: VecDeque<(Key, Arc<Sentence>)>,
    samples: usize,
    capacity: usize,
}

impl SentenceCache {
    pub(crate) fn new(capacity_samples: usize) -> Self {
        SentenceCache {
            entries: VecDeque::new(),
            samples: 0,
            capacity: capacity_samples,
        }
    }

    /// The sentence spoken with `key`, now the most recently used.
    pub(crate) fn get(&mut self, key: &Key) -> Option<Arc<Sentence>> {
        let index = self.entries.iter().position(|(k, _)| k == key)?;
        let entry = self.entries.remove(index)?;
        let sentence = Arc::clone(&entry.1);
        self.entries.push_back(entry);
        Some(sentence)
    }

    /// Keeps `sentence` as the most recently used, dropping the least recently used ones until it fits. A sentence
    /// longer than the whole cache is not kept.
    pub(crate) fn put(&mut self, key: Key, sentence: Arc<Sentence>) {
        let size = sentence.pcm.len();
        if size > self.capacity {
            return;
        }
        if let Some(index) = self.entries.iter().position(|(k, _)| *k == key)
            && let Some((_, old)) = self.entries.remove(index)
        {
            self.samples -= old.pcm.len();
        }
        while self.samples + size > self.capacity {
            match self.entries.pop_front() {
                Some((_, old)) => self.samples -= old.pcm.len(),
                None => break,
            }
        }
        self.samples += size;
        self.entries.push_back((key, sentence));
    }

    #[cfg(test)]
    fn len(&self) -> usize {
        self.entries.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(text: &str) -> Key {
        Key {
            text: text.into(),
            length: 1.0,
            gain: 1.0,
        }
    }

    fn sentence(samples: usize) -> Arc<Sentence> {
        Arc::new(Sentence {
            pcm: vec![1; samples],
            ..Sentence::default()
        })
    }

    #[test]
    fn a_sentence_is_found_only_with_the_same_rate_and_volume() {
        let mut cache = SentenceCache::new(1000);
        cache.put(key("Hello!"), sentence(100));
        assert!(cache.get(&key("Hello!")).is_some());
        let faster = Key {
            length: 0.8,
            ..key("Hello!")
        };
        assert!(cache.get(&faster).is_none());
        let louder = Key {
            gain: 1.5,
            ..key("Hello!")
        };
        assert!(cache.get(&louder).is_none());
        assert!(cache.get(&key("Hello")).is_none());
    }

    #[test]
    fn the_least_recently_used_sentence_goes_first_when_the_audio_does_not_fit() {
        let mut cache = SentenceCache::new(300);
        cache.put(key("a"), sentence(100));
        cache.put(key("b"), sentence(100));
        cache.put(key("c"), sentence(100));
        // "a" is used again, so "b" is now the oldest.
        assert!(cache.get(&key("a")).is_some());
        cache.put(key("d"), sentence(150));
        assert!(cache.get(&key("b")).is_none());
        assert!(cache.get(&key("c")).is_none());
        assert!(cache.get(&key("a")).is_some());
        assert!(cache.get(&key("d")).is_some());
        assert_eq!(cache.len(), 2);
        // Too long for the whole cache: not kept, nothing dropped for it.
        cache.put(key("e"), sentence(400));
        assert_eq!(cache.len(), 2);
        // Kept again under the same key: replaced, not counted twice.
        cache.put(key("a"), sentence(100));
        assert_eq!(cache.len(), 2);
        cache.put(key("f"), sentence(50));
        assert_eq!(cache.len(), 3);
    }
}
