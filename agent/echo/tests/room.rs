//! The canceller on real speech through a simulated room: the agent's reply (LJ001-0001, 9.7 s) played by a page
//! that received it all at once, heard back by a microphone across a room (a delay, a decaying reverb tail, a
//! gain), in 20 ms messages stamped by the hub as they arrive.

use agent_echo::{Canceller, CancellerConfig, RATE, samples_us};

/// The shared fixtures: `$AGENT_FIXTURES`, else `shared/fixtures` beside the repository.
fn fixture(name: &str) -> Vec<f32> {
    let dir = std::env::var_os("AGENT_FIXTURES").map_or_else(
        || std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/fixtures"),
        std::path::PathBuf::from,
    );
    let path = dir.join(name);
    let mut wav = hound::WavReader::open(&path)
        .unwrap_or_else(|e| panic!("{}: {e} (set AGENT_FIXTURES)", path.display()));
    assert_eq!(wav.spec().sample_rate, RATE, "{}", path.display());
    wav.samples::<i16>()
        .map(|s| f32::from(s.unwrap_or(0)) / 32768.0)
        .collect()
}

/// The echo of `far` as a microphone `delay_ms` away hears it, `gain_db` loud, with a 150 ms reverb tail
/// (deterministic noise decaying with a 40 ms time constant).
fn room(far: &[f32], delay_ms: usize, gain_db: f32) -> Vec<f32> {
    let gain = 10f32.powf(gain_db / 20.0);
    let delay = delay_ms * RATE as usize / 1000;
    let tail = RATE as usize * 15 / 100;
    let mut seed = 0x1234_5678u32;
    let response: Vec<f32> = (0..tail)
        .map(|i| {
            if i == 0 {
                return 1.0;
            }
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let noise = (seed >> 8) as f32 / (1u32 << 24) as f32 - 0.5;
            noise * 0.3 * (-(i as f32) / (RATE as f32 * 0.04)).exp()
        })
        .collect();
    let mut echo = vec![0.0; far.len() + delay + tail];
    for (i, &x) in far.iter().enumerate() {
        for (j, &h) in response.iter().enumerate() {
            echo[i + delay + j] += gain * h * x;
        }
    }
    echo
}

/// Runs `mic` (starting when the reply's chunks arrive) through a canceller that was sent `reply` at once, as the
/// TTS module sends it ahead; returns the cleaned microphone.
fn cancel(cfg: CancellerConfig, reply: &[f32], mic: &[f32]) -> Vec<f32> {
    cancel_with_stats(cfg, reply, mic).0
}

/// [`cancel`], with what the canceller did.
fn cancel_with_stats(
    cfg: CancellerConfig,
    reply: &[f32],
    mic: &[f32],
) -> (Vec<f32>, agent_echo::CancellerStats) {
    let mut canceller = Canceller::new(cfg).expect("valid settings");
    let t0 = 1_000_000_000u64;
    for (k, chunk) in reply.chunks(441).enumerate() {
        let pcm: Vec<u8> = chunk
            .iter()
            .flat_map(|s| ((s * 32768.0) as i16).to_le_bytes())
            .collect();
        canceller.speech(t0, Some((1, (k * 441) as u32)), &pcm);
    }
    let mut out = Vec::new();
    for (k, chunk) in mic.chunks(441).enumerate() {
        let pcm: Vec<u8> = chunk
            .iter()
            .flat_map(|s| ((s * 32768.0).clamp(-32768.0, 32767.0) as i16).to_le_bytes())
            .collect();
        // Stamped 5 ms after its last sample was captured.
        let stamp = t0 + samples_us((k * 441 + chunk.len()) as u64) + 5_000;
        canceller.microphone(k as u64 + 1, stamp, &pcm, &mut out);
    }
    let stats = canceller.stats();
    println!("{stats:?}");
    let out = out
        .chunks_exact(2)
        .map(|b| f32::from(i16::from_le_bytes([b[0], b[1]])) / 32768.0)
        .collect();
    (out, stats)
}

fn energy(x: &[f32]) -> f64 {
    x.iter().map(|&s| f64::from(s).powi(2)).sum()
}

/// The canceller holding the microphone before AEC3 has found the echo (`hold_ms`, off by default).
const HOLDING: CancellerConfig = CancellerConfig {
    lead_ms: 60,
    jitter_ms: 60,
    residual_gate: true,
    hold_ms: 1500,
};

/// The page plays the reply 60 ms after it arrived: the echo is that much later again.
const PLAYED_MS: usize = 60;

#[test]
fn the_echo_of_a_reply_is_removed_by_more_than_25_db_once_converged() {
    let reply = fixture("audio/LJ001-0001.wav");
    // The adaptive filter and AEC3's suppressor alone, without the residual gate after them.
    let filter_only = CancellerConfig {
        residual_gate: false,
        ..CancellerConfig::default()
    };
    for delay_ms in [50, 300] {
        for gain_db in [-12.0, 0.0] {
            let echo = room(&reply, PLAYED_MS + delay_ms, gain_db);
            let cleaned = cancel(filter_only, &reply, &echo);
            // From 2 s on (convergence) to the end of what was processed.
            let span = 2 * RATE as usize..cleaned.len();
            let erle =
                10.0 * (energy(&echo[span.clone()]) / energy(&cleaned[span]).max(1e-12)).log10();
            println!("delay {delay_ms} ms, {gain_db} dB: ERLE {erle:.1} dB");
            assert!(
                erle >= 25.0,
                "delay {delay_ms} ms, {gain_db} dB: ERLE {erle:.1} dB"
            );
        }
    }
}

#[test]
fn a_user_talking_over_the_reply_comes_through() {
    let reply = fixture("audio/LJ001-0001.wav");
    let user = fixture("audio/LJ001-0002.wav");
    let echo = room(&reply, PLAYED_MS + 300, 0.0);
    let user_at = 3 * RATE as usize;
    let mut mic = echo.clone();
    mic.resize(mic.len().max(user_at + user.len()), 0.0);
    for (i, &s) in user.iter().enumerate() {
        mic[user_at + i] += s;
    }
    let cleaned = cancel(CancellerConfig::default(), &reply, &mic);
    let span = user_at..(user_at + user.len()).min(cleaned.len());
    let echo_left = {
        let alone = cancel(CancellerConfig::default(), &reply, &echo);
        energy(&alone[span.start..span.end.min(alone.len())])
    };
    let user_energy = energy(&user[..span.len()]);
    let cleaned_energy = energy(&cleaned[span.clone()]);
    let kept = 10.0 * (cleaned_energy / user_energy).log10();
    // How much of what comes out is the user: the correlation of the cleaned mix with the user alone, at the lag
    // the processing adds (a frame, and AEC3's resampling of 22050 Hz to its 16 kHz bands and back).
    let correlation = (0usize..800)
        .map(|lag| {
            let r: f64 = cleaned[span.start + lag..span.end]
                .iter()
                .zip(&user)
                .map(|(&c, &u)| f64::from(c) * f64::from(u))
                .sum();
            (r / (user_energy * cleaned_energy).sqrt()).abs()
        })
        .fold(0.0, f64::max);
    println!(
        "user kept at {kept:.1} dB, correlation with the user {correlation:.2}, the echo alone left {:.1} dB under \
         the user",
        10.0 * (user_energy / echo_left.max(1e-12)).log10()
    );
    assert!(kept > -10.0, "the user was suppressed: {kept:.1} dB");
    assert!(
        correlation > 0.3,
        "the user was distorted: correlation {correlation:.2}"
    );
}

/// With no speech from the agent (and so no echo found) the microphone passes through untouched, only delayed as
/// much as AEC3's path would delay it.
#[test]
fn with_the_agent_silent_the_microphone_passes_through() {
    use agent_echo::canceller::{FRAME, PROCESSING_DELAY};
    let user = fixture("audio/LJ001-0002.wav");
    let cleaned = cancel(CancellerConfig::default(), &[], &user);
    // As many samples out as in, a frame and AEC3's processing delay late.
    let late = PROCESSING_DELAY + FRAME;
    assert_eq!(cleaned.len(), user.len());
    assert!(cleaned[..late].iter().all(|&s| s == 0.0));
    assert_eq!(&cleaned[late..], &user[..cleaned.len() - late]);
}

/// A fresh stream's first words of echo, before AEC3 has found it, are held at any room's loudness (0 dB included,
/// which no learned gate holds): nothing loud comes out of the first half second of the reply's echo.
#[test]
fn the_first_words_of_the_echo_are_held_before_the_filter_has_found_it() {
    let reply = fixture("audio/LJ001-0001.wav");
    for delay_ms in [50, 300] {
        for gain_db in [-12.0, 0.0] {
            let echo = room(&reply, PLAYED_MS + delay_ms, gain_db);
            let (cleaned, stats) = cancel_with_stats(HOLDING, &reply, &echo);
            let found = stats.echo_found_after_ms;
            println!("delay {delay_ms} ms, {gain_db} dB: found after {found:?} ms of speech");
            assert!(found.is_some(), "AEC3 never found the echo: {stats:?}");
            // The loudest 20 ms of the first 1.5 s out, against the echo's loudest.
            let loudest = |x: &[f32]| {
                x[..(3 * RATE as usize / 2).min(x.len())]
                    .chunks(441)
                    .map(|c| energy(c) / c.len() as f64)
                    .fold(0.0, f64::max)
            };
            let left = 10.0 * (loudest(&cleaned) / loudest(&echo).max(1e-12)).log10();
            println!("  loudest 20 ms left of the first 1.5 s: {left:.1} dB");
            assert!(
                left < -20.0,
                "delay {delay_ms} ms, {gain_db} dB: {left:.1} dB left"
            );
        }
    }
}

/// With no echo at all (headphones) the canceller stops holding once `hold_ms` of the reply has played: a user
/// heard over the rest of the reply comes through untouched.
#[test]
fn without_an_echo_the_hold_ends_and_a_user_over_the_reply_passes_through() {
    use agent_echo::canceller::{FRAME, PROCESSING_DELAY};
    let reply = fixture("audio/LJ001-0001.wav");
    let user = fixture("audio/LJ001-0002.wav");
    let user_at = 3 * RATE as usize;
    let mut mic = vec![0.0; user_at];
    mic.extend_from_slice(&user);
    let (cleaned, stats) = cancel_with_stats(HOLDING, &reply, &mic);
    assert_eq!(stats.echo_found_after_ms, None, "{stats:?}");
    let late = PROCESSING_DELAY + FRAME;
    assert_eq!(&cleaned[user_at + late..], &user[..user.len() - late]);
}

/// With no echo (headphones) the residual gate, asked about frames only once AEC3 has found an echo, still keeps
/// no more than a window of the agent's levels: a 9.7 s reply leaves under a second's worth behind, not all of it.
#[test]
fn without_an_echo_the_residual_gate_keeps_only_a_window_of_the_agents_levels() {
    let reply = fixture("audio/LJ001-0001.wav");
    let mic = vec![0.0; reply.len()];
    let (_, stats) = cancel_with_stats(CancellerConfig::default(), &reply, &mic);
    assert_eq!(stats.echo_found_after_ms, None, "{stats:?}");
    assert!(
        stats.frames_with_speech > 800,
        "the reply did not play: {stats:?}"
    );
    // 700 ms of window, 60 ms of lead and the frame itself: 77 frames of 10 ms (913 before the fix).
    assert!(stats.residual_levels <= 77, "{stats:?}");
}

/// The levels of 10 ms frames of `x` (dBFS).
fn frame_levels(x: &[f32]) -> Vec<f32> {
    x.chunks(RATE as usize / 100)
        .map(agent_echo::residual::level_dbfs)
        .collect()
}

/// On real speech, the levels tell an echo from a person: the reply's echo through the room is never taken for no
/// echo, and a different person talking over the reply (no loudspeaker) is, within a second of the reply.
#[test]
fn the_levels_tell_the_replys_echo_from_a_person_talking_over_it() {
    use agent_echo::presence::Presence;
    let reply = fixture("audio/LJ001-0001.wav");
    let reference = frame_levels(&reply);
    for delay_ms in [50, 300] {
        for gain_db in [-12.0, 0.0] {
            let echo = frame_levels(&room(&reply, PLAYED_MS + delay_ms, gain_db));
            let mut presence = Presence::default();
            for (i, (&r, &m)) in reference.iter().zip(&echo).enumerate() {
                presence.frame(r, m);
                assert!(
                    !presence.no_echo(),
                    "{delay_ms} ms, {gain_db} dB, at {} ms",
                    i * 10
                );
            }
        }
    }
    for other in ["audio/LJ001-0002.wav", "audio/LJ001-0004.wav"] {
        let user = frame_levels(&fixture(other));
        let mut presence = Presence::default();
        let no_echo_at = reference.iter().zip(&user).position(|(&r, &m)| {
            presence.frame(r, m);
            presence.no_echo()
        });
        println!(
            "{other} over the reply: no echo after {:?} ms",
            no_echo_at.map(|i| i * 10)
        );
        assert!(no_echo_at.is_some_and(|i| i <= 100), "{other}");
    }
}
