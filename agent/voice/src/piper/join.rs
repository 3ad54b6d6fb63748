//! Joining the parts of one sentence that the network spoke in separate runs, so that they play as one: the
//! silence each run ends and starts with is cut to a short pause, and each cut edge fades to zero over a few
//! milliseconds, so the samples on both sides of a join meet at zero (no click) and the pause is that of a
//! comma, not of a new sentence (no gap). Cues and phonemes move with the samples they belong to.

use super::spoken::Sentence;
use crate::viseme::Viseme;

/// Below this level (about -40 dBFS) a sample is silence.
const QUIET: i16 = 330;
/// The pause a part may end with before the next one, in ms: about what the voice makes for a comma.
const END_PAUSE_MS: u64 = 90;
/// The silence a later part may start with, in ms.
const START_PAUSE_MS: u64 = 30;
/// The fade at each cut edge, in ms.
const FADE_MS: u64 = 4;

fn samples(ms: u64, rate: u32) -> usize {
    (ms * u64::from(rate) / 1000) as usize
}

/// Cuts the silence at the end of a part that another part will follow to [`END_PAUSE_MS`] and fades its last
/// samples to zero.
pub(crate) fn end_part(part: &mut Sentence, rate: u32) {
    let sound_end = part
        .pcm
        .iter()
        .rposition(|s| s.unsigned_abs() > QUIET.unsigned_abs())
        .map_or(0, |i| i + 1);
    let keep = (sound_end + samples(END_PAUSE_MS, rate)).min(part.pcm.len());
    part.pcm.truncate(keep);
    let end = keep as u64;
    for cue in &mut part.cues {
        cue.0 = cue.0.min(end);
    }
    part.phonemes.retain(|(at, _)| *at < end);
    // A part cut before a joining word ends on an open shape: the mouth rests in the pause.
    if part.cues.last().is_some_and(|(_, v)| *v != Viseme::Sil) {
        part.cues.push(((sound_end as u64).min(end), Viseme::Sil));
    }
    fade_out(&mut part.pcm, samples(FADE_MS, rate));
}

/// Cuts the silence at the start of a part that follows another to [`START_PAUSE_MS`] and fades its first samples
/// in from zero; its cues and phonemes move back by what was cut.
pub(crate) fn start_part(part: &mut Sentence, rate: u32) {
    let sound_start = part
        .pcm
        .iter()
        .position(|s| s.unsigned_abs() > QUIET.unsigned_abs())
        .unwrap_or(part.pcm.len());
    let cut = sound_start.saturating_sub(samples(START_PAUSE_MS, rate));
    part.pcm.drain(..cut);
    let cut = cut as u64;
    for cue in &mut part.cues {
        cue.0 = cue.0.saturating_sub(cut);
    }
    for phoneme in &mut part.phonemes {
        phoneme.0 = phoneme.0.saturating_sub(cut);
    }
    fade_in(&mut part.pcm, samples(FADE_MS, rate));
}

/// Appends `part` to `whole`: its samples after the others, its cues and phonemes moved by the samples before it.
pub(crate) fn append(whole: &mut Sentence, part: Sentence) {
    let offset = whole.pcm.len() as u64;
    whole.pcm.extend_from_slice(&part.pcm);
    whole
        .cues
        .extend(part.cues.into_iter().map(|(at, v)| (at + offset, v)));
    whole
        .phonemes
        .extend(part.phonemes.into_iter().map(|(at, p)| (at + offset, p)));
    whole.unknown.extend(part.unknown);
}

fn fade_out(pcm: &mut [i16], length: usize) {
    let length = length.min(pcm.len());
    let start = pcm.len() - length;
    for (k, sample) in pcm[start..].iter_mut().enumerate() {
        // From just under 1 down to 0 at the last sample.
        let weight = (length - 1 - k) as f32 / length as f32;
        *sample = (f32::from(*sample) * weight) as i16;
    }
}

fn fade_in(pcm: &mut [i16], length: usize) {
    let length = length.min(pcm.len());
    for (k, sample) in pcm[..length].iter_mut().enumerate() {
        let weight = k as f32 / length as f32;
        *sample = (f32::from(*sample) * weight) as i16;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const RATE: u32 = 22050;

    /// `lead` ms of silence, `tone` ms of a loud 220 Hz tone, `tail` ms of silence.
    fn part(lead: u64, tone: u64, tail: u64) -> Sentence {
        let (lead, tone, tail) = (
            samples(lead, RATE),
            samples(tone, RATE),
            samples(tail, RATE),
        );
        let mut pcm = vec![0i16; lead];
        pcm.extend((0..tone).map(|i| {
            (12000.0 * (2.0 * std::f32::consts::PI * 220.0 * i as f32 / RATE as f32).sin()) as i16
        }));
        pcm.extend(std::iter::repeat_n(0, tail));
        Sentence {
            cues: vec![
                (lead as u64, Viseme::Aa),
                ((lead + tone) as u64, Viseme::Sil),
            ],
            phonemes: vec![(lead as u64, 'a')],
            pcm,
            ..Sentence::default()
        }
    }

    #[test]
    fn a_join_meets_at_zero_with_a_comma_long_pause() {
        // The tone stops mid-wave, as a cut would: the fades still bring both edges to zero.
        let mut head = part(100, 503, 400);
        let mut tail = part(250, 300, 200);
        end_part(&mut head, RATE);
        start_part(&mut tail, RATE);
        assert_eq!(head.pcm.last(), Some(&0));
        assert_eq!(tail.pcm.first(), Some(&0));
        let head_len = head.pcm.len();
        let mut whole = head;
        append(&mut whole, tail);
        // No step between neighbouring samples across the join is larger than the tone's own.
        let join = &whole.pcm[head_len - 200..head_len + 200];
        let largest = join
            .windows(2)
            .map(|w| (i32::from(w[1]) - i32::from(w[0])).abs())
            .max()
            .unwrap_or(0);
        let tone_step = (12000.0 * 2.0 * std::f32::consts::PI * 220.0 / RATE as f32) as i32 + 1;
        assert!(largest <= tone_step, "{largest} > {tone_step}");
        // The silence between the tones is the pause kept at the end plus the one kept at the start.
        let loud: Vec<usize> = whole
            .pcm
            .iter()
            .enumerate()
            .filter(|(_, s)| s.unsigned_abs() > QUIET.unsigned_abs())
            .map(|(i, _)| i)
            .collect();
        let gap = loud.windows(2).map(|w| w[1] - w[0]).max().unwrap_or(0);
        let gap_ms = gap as u64 * 1000 / u64::from(RATE);
        assert!(
            (END_PAUSE_MS..=END_PAUSE_MS + START_PAUSE_MS + 2 * FADE_MS + 5).contains(&gap_ms),
            "pause {gap_ms} ms"
        );
    }

    #[test]
    fn cues_and_phonemes_move_with_their_samples() {
        let mut head = part(100, 500, 400);
        let mut tail = part(250, 300, 200);
        end_part(&mut head, RATE);
        start_part(&mut tail, RATE);
        let tail_sound = tail
            .pcm
            .iter()
            .position(|s| s.unsigned_abs() > QUIET.unsigned_abs())
            .expect("sound");
        // The tail's open cue still sits where its sound starts (within the fade).
        let open = tail.cues[0].0 as usize;
        assert!(
            open.abs_diff(tail_sound) <= samples(FADE_MS, RATE),
            "{open} vs {tail_sound}"
        );
        let head_len = head.pcm.len() as u64;
        assert!(head.cues.iter().all(|c| c.0 <= head_len));
        let mut whole = head;
        append(&mut whole, tail);
        assert_eq!(whole.cues.len(), 4);
        assert_eq!(whole.phonemes[1].0, head_len + open as u64);
        assert!(whole.cues.windows(2).all(|w| w[0].0 <= w[1].0));
    }

    #[test]
    fn a_part_that_ends_open_rests_where_its_sound_ends() {
        let mut head = part(100, 500, 400);
        head.cues.pop();
        end_part(&mut head, RATE);
        let (at, viseme) = *head.cues.last().expect("a cue");
        assert_eq!(viseme, Viseme::Sil);
        assert!(at.abs_diff(samples(600, RATE) as u64) <= 2, "{at}");
    }

    #[test]
    fn a_silent_part_is_cut_to_its_pauses() {
        let mut silent = Sentence {
            pcm: vec![0; 10_000],
            ..Sentence::default()
        };
        end_part(&mut silent, RATE);
        assert_eq!(silent.pcm.len(), samples(END_PAUSE_MS, RATE));
        start_part(&mut silent, RATE);
        assert_eq!(silent.pcm.len(), samples(START_PAUSE_MS, RATE));
    }
}
