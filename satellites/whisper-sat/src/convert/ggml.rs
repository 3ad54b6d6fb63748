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
    /// 1: matrices stored as f16.
    pub ftype: i32,
}

/// Storage type of one tensor in the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TensorType {
    F32,
    F16,
}

impl TensorType {
    fn code(self) -> i32 {
        match self {
            Self::F32 => 0,
            Self::F16 => 1,
        }
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
    w.write_all(&(shape.len() as i32).to_le_bytes())?;
    w.write_all(&(name.len() as i32).to_le_bytes())?;
    w.write_all(&ttype.code().to_le_bytes())?;
    for &d in shape.iter().rev() {
        w.write_all(&(d as i32).to_le_bytes())?;
    }
    w.write_all(name.as_bytes())?;
    let mut buf = Vec::with_capacity(values.len() * 4);
    match ttype {
        TensorType::F32 => values.iter().for_each(|v| buf.extend(v.to_le_bytes())),
        TensorType::F16 => values
            .iter()
            .for_each(|&v| buf.extend(f16::from_f32(v).to_le_bytes())),
    }
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
