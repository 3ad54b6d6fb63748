//! The Slaney-style mel filterbank that Whisper's log-mel front end uses (librosa's `filters.mel` defaults).
//!
//! whisper.cpp reads this matrix from the model file instead of computing it, so the converter must write exactly
//! the filters the model was trained with: librosa's Slaney mel scale (linear below 1 kHz, logarithmic above) with
//! Slaney area normalisation, computed in double precision and stored as f32.

/// Builds the `n_mels x (n_fft / 2 + 1)` filterbank, row-major, for `sample_rate` and an `n_fft`-point FFT,
/// spanning 0 Hz to Nyquist.
pub fn slaney_filterbank(sample_rate: f64, n_fft: usize, n_mels: usize) -> Vec<f32> {
    let n_freqs = n_fft / 2 + 1;
    let fft_freqs: Vec<f64> = (0..n_freqs)
        .map(|k| k as f64 * sample_rate / n_fft as f64)
        .collect();
    // The band edges: n_mels + 2 points evenly spaced on the mel scale, converted back to Hz.
    let mel_max = hz_to_mel(sample_rate / 2.0);
    let edges: Vec<f64> = (0..n_mels + 2)
        .map(|i| mel_to_hz(mel_max * i as f64 / (n_mels + 1) as f64))
        .collect();
    let mut weights = Vec::with_capacity(n_mels * n_freqs);
    for m in 0..n_mels {
        let (lo, centre, hi) = (edges[m], edges[m + 1], edges[m + 2]);
        // Slaney normalisation makes every triangle's area one, so wide high-frequency bands do not dominate.
        let norm = 2.0 / (hi - lo);
        for &f in &fft_freqs {
            let rising = (f - lo) / (centre - lo);
            let falling = (hi - f) / (hi - centre);
            weights.push((rising.min(falling).max(0.0) * norm) as f32);
        }
    }
    weights
}

/// Linear spacing below 1 kHz (200/3 Hz per mel), logarithmic above, as in Slaney's Auditory Toolbox.
const F_SP: f64 = 200.0 / 3.0;
const MIN_LOG_HZ: f64 = 1000.0;
const MIN_LOG_MEL: f64 = MIN_LOG_HZ / F_SP;

fn log_step() -> f64 {
    6.4f64.ln() / 27.0
}

/// Hertz to Slaney mels.
pub fn hz_to_mel(hz: f64) -> f64 {
    if hz >= MIN_LOG_HZ {
        MIN_LOG_MEL + (hz / MIN_LOG_HZ).ln() / log_step()
    } else {
        hz / F_SP
    }
}

/// Slaney mels to Hertz.
pub fn mel_to_hz(mel: f64) -> f64 {
    if mel >= MIN_LOG_MEL {
        MIN_LOG_HZ * (log_step() * (mel - MIN_LOG_MEL)).exp()
    } else {
        F_SP * mel
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const N_FREQS: usize = 201;

    fn whisper_bank() -> Vec<f32> {
        slaney_filterbank(16_000.0, 400, 80)
    }

    fn row(bank: &[f32], m: usize) -> &[f32] {
        &bank[m * N_FREQS..(m + 1) * N_FREQS]
    }

    fn argmax(r: &[f32]) -> usize {
        r.iter()
            .enumerate()
            .fold(
                (0, f32::MIN),
                |best, (i, &v)| if v > best.1 { (i, v) } else { best },
            )
            .0
    }

    #[test]
    fn mel_scale_round_trips_and_is_linear_below_one_kilohertz() {
        for hz in [0.0, 100.0, 999.0, 1000.0, 4000.0, 8000.0] {
            assert!((mel_to_hz(hz_to_mel(hz)) - hz).abs() < 1e-9, "{hz}");
        }
        assert!((hz_to_mel(500.0) - 7.5).abs() < 1e-12);
        assert!((hz_to_mel(1000.0) - 15.0).abs() < 1e-12);
    }

    #[test]
    fn every_filter_is_a_non_negative_triangle_of_unit_area() {
        let bank = whisper_bank();
        assert_eq!(bank.len(), 80 * N_FREQS);
        for m in 0..80 {
            let r = row(&bank, m);
            assert!(
                r.iter().all(|&w| w >= 0.0),
                "filter {m} has a negative weight"
            );
            // Unimodal: weights rise to one peak and then fall.
            let peak = argmax(r);
            assert!(
                r[..=peak].windows(2).all(|w| w[0] <= w[1]),
                "filter {m} rises unevenly"
            );
            assert!(
                r[peak..].windows(2).all(|w| w[0] >= w[1]),
                "filter {m} falls unevenly"
            );
            // Area in Hz (sum x 40 Hz bin width) is close to one; the narrowest filters are sampled coarsely.
            let area: f32 = r.iter().sum::<f32>() * 40.0;
            assert!((0.9..1.1).contains(&area), "filter {m} area {area}");
        }
        // Centres increase with the filter index.
        let peaks: Vec<usize> = (0..80).map(|m| argmax(row(&bank, m))).collect();
        assert!(peaks.windows(2).all(|p| p[0] <= p[1]));
    }

    #[test]
    fn matches_reference_values_of_openai_whispers_mel_filters() {
        // Reference values read from `whisper/assets/mel_filters.npz` (array `mel_80`) of the openai-whisper
        // package (PyPI, version 20250625), which stores librosa's filterbank for these parameters.
        let bank = whisper_bank();
        let close = |a: f32, b: f32| (a - b).abs() <= 1e-7 + 1e-5 * b.abs();
        assert!(close(row(&bank, 0)[1], 0.024_862_595));
        assert_eq!(row(&bank, 0).iter().filter(|&&w| w > 0.0).count(), 1);
        assert_eq!(argmax(row(&bank, 10)), 10);
        assert!(close(row(&bank, 10)[10], 0.019_908_218));
        assert_eq!(argmax(row(&bank, 40)), 43);
        assert!(close(row(&bank, 40)[43], 0.014_735_566));
        assert!(close(row(&bank, 40).iter().sum(), 0.026_664_86));
        assert_eq!(argmax(row(&bank, 79)), 192);
        assert!(close(row(&bank, 79)[192], 0.003_164_711_9));
        assert_eq!(row(&bank, 79)[200], 0.0);
        let nonzero: Vec<usize> = (0..N_FREQS).filter(|&k| row(&bank, 79)[k] > 0.0).collect();
        assert_eq!((nonzero[0], nonzero[nonzero.len() - 1]), (186, 199));
    }
}
