//! AEC3's block processor driven directly at 16 kHz, for what `sonora`'s audio processing does not expose: the
//! adaptive filter's own (linear) output before the suppressor, and the suppressor's tuning.

use sonora_aec3::block::Block;
use sonora_aec3::block_processor::BlockProcessor;
use sonora_aec3::common::BLOCK_SIZE;
use sonora_aec3::config::EchoCanceller3Config;
use whisper_sat::resample::resample_clip;

/// The rate AEC3 runs one band at.
pub const RATE_16K: u32 = 16_000;

/// The two outputs of one run, at 16 kHz in [-1, 1].
pub struct Outputs {
    /// After the suppressor (what AEC3 hands out).
    pub suppressed: Vec<f32>,
    /// The adaptive filter's output: the microphone less the echo it models.
    pub linear: Vec<f32>,
}

/// Runs `mic` (22050 Hz) through AEC3 with `config`, the reference `reply` (22050 Hz) lined up sample for sample
/// with the microphone's clock (the bench's lead equals the page's jitter buffer).
pub fn run(config: &EchoCanceller3Config, reply: &[i16], mic: &[i16]) -> anyhow::Result<Outputs> {
    let to16 = |pcm: &[i16]| -> anyhow::Result<Vec<f32>> {
        let f: Vec<f32> = pcm.iter().map(|&s| f32::from(s) / 32768.0).collect();
        Ok(resample_clip(&f, 22_050, RATE_16K)?)
    };
    let (reference, capture) = (to16(reply)?, to16(mic)?);
    let mut aec = BlockProcessor::new(config, RATE_16K as usize, 1, 1);
    let mut render = Block::new(1, 1);
    let mut block = Block::new(1, 1);
    let mut linear = Block::new(1, 1);
    let blocks = capture.len() / BLOCK_SIZE;
    let mut out = Outputs {
        suppressed: Vec::with_capacity(blocks * BLOCK_SIZE),
        linear: Vec::with_capacity(blocks * BLOCK_SIZE),
    };
    for k in 0..blocks {
        let span = k * BLOCK_SIZE..(k + 1) * BLOCK_SIZE;
        for (i, r) in render.view_mut(0, 0).iter_mut().enumerate() {
            *r = reference.get(span.start + i).copied().unwrap_or(0.0) * 32768.0;
        }
        aec.buffer_render(&render);
        for (b, &c) in block.view_mut(0, 0).iter_mut().zip(&capture[span]) {
            *b = c * 32768.0;
        }
        aec.process_capture(false, false, Some(&mut linear), &mut block);
        out.suppressed
            .extend(block.view(0, 0).iter().map(|&s| s / 32768.0));
        out.linear
            .extend(linear.view(0, 0).iter().map(|&s| s / 32768.0));
    }
    Ok(out)
}

/// AEC3's defaults with the linear output exported.
pub fn default_config() -> EchoCanceller3Config {
    let mut c = EchoCanceller3Config::default();
    c.filter.export_linear_aec_output = true;
    c
}

/// The filter lengthened to 40 blocks (160 ms, for the room's reverberation; AEC3's default is 13, 52 ms) and a
/// suppressor that lets a person talking over the echo through sooner and further: the near-end tuning all the
/// time, and near-end dominance detected at a lower echo-to-near-end ratio and signal-to-noise ratio.
pub fn nearend_config() -> EchoCanceller3Config {
    let mut c = default_config();
    let f = &mut c.filter;
    f.refined.length_blocks = 40;
    f.coarse.length_blocks = 40;
    f.refined_initial.length_blocks = 40;
    f.coarse_initial.length_blocks = 40;
    let s = &mut c.suppressor;
    s.normal_tuning = s.nearend_tuning.clone();
    s.dominant_nearend_detection.enr_threshold = 0.1;
    s.dominant_nearend_detection.snr_threshold = 10.0;
    s.dominant_nearend_detection.trigger_threshold = 6;
    c
}
