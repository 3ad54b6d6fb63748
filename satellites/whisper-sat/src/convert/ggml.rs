//! Writer for the legacy ggml model file that whisper.cpp's loader reads: magic, hparams, mel filters, vocabulary,
//! then the tensors.

use std::io::{self, Write};

use half::f16;

/// "ggml" in the loader's byte order.
pub const GGML_MAGIC: u32 = 0x6767_6d6c;

/// Model dimensions in the order whisper.cpp reads them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Hparams {
    pub n_vocab: i32,
    pub n_audio_ctx: i32,
    pub n_audio_state: i32,
    pub n_audio_head: i32,
    pub n_audio_layer: i32,
    pub n_text_ctx: i32,
    pub n_text_state: i32,
    pub n_text_head: i32,
    pub n_text_layer: i32,
    pub n_mels: i32,
    /// How the matrices are stored: ggml's file type (1: f16, 7: q8_0), plus 1000 x the quantisation format
    /// version for quantised files, as whisper.cpp's loader reads it ([`Weights::ftype`]).
    pub ftype: i32,
}

/// ggml's quantisation format version (`GGML_QNT_VERSION`), stored in `ftype` of quantised files.
const QNT_VERSION: i32 = 2;
/// `GGML_QNT_VERSION_FACTOR`: `ftype` = file type + version x this.
const QNT_VERSION_FACTOR: i32 = 1000;
/// Values per q8_0 block (`QK8_0`).
pub const Q8_0_BLOCK: usize = 32;

/// How a converted model stores its weight matrices.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Weights {
    /// 16-bit floats: the CTranslate2 packages' own precision.
    #[default]
    F16,
    /// ggml's q8_0: blocks of 32 signed bytes sharing one f16 scale, as faster-whisper's int8 holds its weights;
    /// whisper.cpp multiplies them with integer dot products.
    Q8_0,
}

impl Weights {
    /// The tensor type of a weight matrix.
    pub fn matrix_type(self) -> TensorType {
        match self {
            Self::F16 => TensorType::F16,
            Self::Q8_0 => TensorType::Q8_0,
        }
    }

    /// The header's `ftype`: `GGML_FTYPE_MOSTLY_F16` (1) or `GGML_FTYPE_MOSTLY_Q8_0` (7) with the quantisation
    /// version.
    pub fn ftype(self) -> i32 {
        match self {
            Self::F16 => 1,
            Self::Q8_0 => 7 + QNT_VERSION * QNT_VERSION_FACTOR,
        }
    }
}

/// Storage type of one tensor in the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TensorType {
    F32,
    F16,
    Q8_0,
}

impl TensorType {
    fn code(self) -> i32 {
        match self {
            Self::F32 => 0,
            Self::F16 => 1,
            Self::Q8_0 => 8,
        }
    }

    /// Bytes that `n` values take in this type (`n` a multiple of the block for q8_0).
    pub fn bytes(self, n: usize) -> usize {
        match self {
            Self::F32 => 4 * n,
            Self::F16 => 2 * n,
            Self::Q8_0 => n / Q8_0_BLOCK * (2 + Q8_0_BLOCK),
        }
    }
}

/// Why a tensor cannot be written in the type asked for.
fn unaligned(name: &str, shape: &[usize]) -> io::Error {
    io::Error::new(
        io::ErrorKind::InvalidInput,
        format!(
            "{name}: rows of {shape:?} are not a multiple of {Q8_0_BLOCK} values, as q8_0 needs"
        ),
    )
}

/// q8_0 blocks of `values` (a whole number of blocks), as ggml's reference quantiser makes them: per block the
/// scale d = max |x| / 127 (an f16), then each value as round(x / d), half away from zero.
///
/// ```text
///  0       2                                34
///  +-------+---------------------------------+
///  | d f16 | 32 x i8: round(x / d)           |   one block, repeated
///  +-------+---------------------------------+
/// ```
fn push_q8_0(buf: &mut Vec<u8>, values: &[f32]) {
    for block in values.chunks_exact(Q8_0_BLOCK) {
        let amax = block.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let d = amax / 127.0;
        let id = if d == 0.0 { 0.0 } else { 1.0 / d };
        buf.extend(f16::from_f32(d).to_le_bytes());
        // In range by construction: |x| * 127 / max |x| <= 127.
        buf.extend(block.iter().map(|&v| (v * id).round() as i8 as u8));
    }
}

/// Writes the file header: magic, hparams, the mel filterbank and the vocabulary.
pub fn write_header<W: Write>(
    w: &mut W,
    hp: &Hparams,
    n_fft_bins: usize,
    mel_filters: &[f32],
    vocabulary: &[Vec<u8>],
) -> io::Result<()> {
    w.write_all(&GGML_MAGIC.to_le_bytes())?;
    for v in [
        hp.n_vocab,
        hp.n_audio_ctx,
        hp.n_audio_state,
        hp.n_audio_head,
        hp.n_audio_layer,
        hp.n_text_ctx,
        hp.n_text_state,
        hp.n_text_head,
        hp.n_text_layer,
        hp.n_mels,
        hp.ftype,
    ] {
        w.write_all(&v.to_le_bytes())?;
    }
    w.write_all(&hp.n_mels.to_le_bytes())?;
    w.write_all(&(n_fft_bins as i32).to_le_bytes())?;
    for v in mel_filters {
        w.write_all(&v.to_le_bytes())?;
    }
    w.write_all(&(vocabulary.len() as i32).to_le_bytes())?;
    for token in vocabulary {
        w.write_all(&(token.len() as i32).to_le_bytes())?;
        w.write_all(token)?;
    }
    Ok(())
}

/// Writes one tensor. `shape` is in row-major (numpy) order; ggml stores dimensions innermost first, so they are
/// written reversed. Returns the number of bytes written.
pub fn write_tensor<W: Write>(
    w: &mut W,
    name: &str,
    shape: &[usize],
    ttype: TensorType,
    values: &[f32],
) -> io::Result<u64> {
    if ttype == TensorType::Q8_0 && shape.last().is_none_or(|&n| n % Q8_0_BLOCK != 0) {
        return Err(unaligned(name, shape));
    }
    w.write_all(&(shape.len() as i32).to_le_bytes())?;
    w.write_all(&(name.len() as i32).to_le_bytes())?;
    w.write_all(&ttype.code().to_le_bytes())?;
    for &d in shape.iter().rev() {
        w.write_all(&(d as i32).to_le_bytes())?;
    }
    let mut buf = Vec::with_capacity(ttype.bytes(values.len()));
    match ttype {
        TensorType::F32 => values.iter().for_each(|v| buf.extend(v.to_le_bytes())),
        TensorType::F16 => values
            .iter()
            .for_each(|&v| buf.extend(f16::from_f32(v).to_le_bytes())),
        TensorType::Q8_0 => push_q8_0(&mut buf, values),
    }
    w.write_all(name.as_bytes())?;
    w.write_all(&buf)?;
    Ok(12 + 4 * shape.len() as u64 + name.len() as u64 + buf.len() as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn i32_at(b: &[u8], at: usize) -> i32 {
        i32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
    }

    #[test]
    fn tensor_record_has_reversed_dims_and_converted_data() -> io::Result<()> {
        let mut out = Vec::new();
        let n = write_tensor(
            &mut out,
            "a.b",
            &[2, 3],
            TensorType::F16,
            &[1.0, 2.0, 3.0, 4.0, 5.0, -0.5],
        )?;
        assert_eq!(n as usize, out.len());
        assert_eq!(
            (i32_at(&out, 0), i32_at(&out, 4), i32_at(&out, 8)),
            (2, 3, 1)
        );
        assert_eq!((i32_at(&out, 12), i32_at(&out, 16)), (3, 2));
        assert_eq!(&out[20..23], b"a.b");
        let last = f16::from_le_bytes([out[out.len() - 2], out[out.len() - 1]]);
        assert_eq!(last.to_f32(), -0.5);
        Ok(())
    }

    /// Values back from q8_0 blocks.
    fn dequantise(bytes: &[u8]) -> Vec<f32> {
        bytes
            .chunks_exact(2 + Q8_0_BLOCK)
            .flat_map(|b| {
                let d = f16::from_le_bytes([b[0], b[1]]).to_f32();
                b[2..].iter().map(move |&q| f32::from(q as i8) * d)
            })
            .collect()
    }

    #[test]
    fn a_q8_0_block_holds_its_scale_and_each_value_rounded_to_it() -> io::Result<()> {
        let values: Vec<f32> = (0..32).map(|i| i as f32 - 16.0).collect();
        let mut out = Vec::new();
        let n = write_tensor(&mut out, "w", &[1, 32], TensorType::Q8_0, &values)?;
        assert_eq!(n as usize, out.len());
        assert_eq!(i32_at(&out, 8), 8, "ggml's type code of q8_0");
        let data = &out[out.len() - 34..];
        let d = f16::from_le_bytes([data[0], data[1]]).to_f32();
        assert!((d - 16.0 / 127.0).abs() < 1e-4, "scale {d}");
        assert_eq!(
            data[2] as i8, -127,
            "the largest magnitude takes the whole range"
        );
        assert_eq!(data[33] as i8, 119, "15 / (16 / 127) = 119.06");
        assert_eq!(data[18] as i8, 0);
        Ok(())
    }

    #[test]
    fn q8_0_weights_come_back_within_half_a_step_and_the_scale_rounding() -> io::Result<()> {
        // A fixed pseudo-random matrix of 4 rows x 64, with one all-zero block.
        let mut x = 0x2545_f491_u32;
        let mut values: Vec<f32> = (0..256)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                (x as f32 / u32::MAX as f32 - 0.5) * 0.2
            })
            .collect();
        values[64..96].fill(0.0);
        let mut out = Vec::new();
        write_tensor(&mut out, "w", &[4, 64], TensorType::Q8_0, &values)?;
        let data = &out[out.len() - TensorType::Q8_0.bytes(256)..];
        let back = dequantise(data);
        assert_eq!(back.len(), values.len());
        for (block, (v, b)) in values.chunks(32).zip(back.chunks(32)).enumerate() {
            let step = v.iter().fold(0.0f32, |m, x| m.max(x.abs())) / 127.0;
            // Half a step from rounding, plus what storing the scale in f16 (11 significant bits) moves the
            // largest value: 127 steps x 2^-11.
            let bound = step * (0.5 + 127.0 / 2048.0) + 1e-7;
            for (a, b) in v.iter().zip(b) {
                assert!((a - b).abs() <= bound, "block {block}: {a} -> {b}");
            }
        }
        assert!(back[64..96].iter().all(|&v| v == 0.0));
        Ok(())
    }

    #[test]
    fn a_q8_0_tensor_whose_rows_are_not_whole_blocks_is_refused_before_anything_is_written() {
        let mut out = Vec::new();
        let e = write_tensor(&mut out, "odd", &[2, 40], TensorType::Q8_0, &[0.0; 80]);
        assert!(e.is_err_and(|e| e.to_string().contains("odd")));
        assert!(out.is_empty());
    }

    #[test]
    fn quantised_files_carry_the_quantisation_version_in_ftype() {
        assert_eq!(Weights::F16.ftype(), 1);
        assert_eq!(Weights::Q8_0.ftype(), 2007);
        assert_eq!(Weights::Q8_0.matrix_type(), TensorType::Q8_0);
    }

    #[test]
    fn header_starts_with_magic_and_hparams() -> io::Result<()> {
        let hp = Hparams {
            n_vocab: 5,
            n_audio_ctx: 6,
            n_audio_state: 7,
            n_audio_head: 1,
            n_audio_layer: 2,
            n_text_ctx: 8,
            n_text_state: 7,
            n_text_head: 1,
            n_text_layer: 2,
            n_mels: 2,
            ftype: 1,
        };
        let mut out = Vec::new();
        write_header(&mut out, &hp, 3, &[0.0; 6], &[b"ab".to_vec(), vec![0xff]])?;
        assert_eq!(
            u32::from_le_bytes([out[0], out[1], out[2], out[3]]),
            GGML_MAGIC
        );
        assert_eq!(i32_at(&out, 4), 5);
        assert_eq!(i32_at(&out, 44), 1);
        assert_eq!((i32_at(&out, 48), i32_at(&out, 52)), (2, 3));
        let vocab_at = 56 + 6 * 4;
        assert_eq!(i32_at(&out, vocab_at), 2);
        assert_eq!(i32_at(&out, vocab_at + 4), 2);
        assert_eq!(&out[vocab_at + 8..vocab_at + 10], b"ab");
        assert_eq!(out.len(), vocab_at + 10 + 4 + 1);
        Ok(())
    }
}
