//! Reader for CTranslate2's `model.bin`: the spec header, the named variables and their aliases.
//!
//! The layout (version 6) is a little-endian stream: u32 binary version, a string spec name, u32 spec revision,
//! u32 variable count, then per variable its name, u8 rank, rank x u32 dims, u8 dtype, u32 byte count and the raw
//! bytes, and finally u32 alias count with (alias, target) string pairs. A string is a u16 length that counts a
//! trailing NUL, followed by the bytes and that NUL.

use std::collections::HashMap;
use std::io::Read;

use half::f16;

/// Errors from reading a CTranslate2 model file.
#[derive(Debug, thiserror::Error)]
pub enum Ct2Error {
    #[error("reading the model file: {0}")]
    Io(#[from] std::io::Error),
    #[error("unsupported CTranslate2 binary version {0} (this reader knows version 5 and 6)")]
    Version(u32),
    #[error("variable {name}: unknown dtype code {code}")]
    Dtype { name: String, code: u8 },
    #[error("variable {name}: {bytes} bytes do not fit shape {dims:?} of {dtype:?}")]
    Size {
        name: String,
        bytes: usize,
        dims: Vec<usize>,
        dtype: Dtype,
    },
    #[error("string in the header is not UTF-8 or lacks its NUL terminator")]
    BadString,
    #[error("variable {0} is missing from the model")]
    Missing(String),
    #[error("variable {name} has dtype {dtype:?}, which cannot be read as {wanted}")]
    WrongType {
        name: String,
        dtype: Dtype,
        wanted: &'static str,
    },
}

/// Element type of a variable, with CTranslate2's numeric codes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dtype {
    F32,
    I8,
    I16,
    I32,
    F16,
    Bf16,
}

impl Dtype {
    fn from_code(code: u8) -> Option<Self> {
        Some(match code {
            0 => Self::F32,
            1 => Self::I8,
            2 => Self::I16,
            3 => Self::I32,
            4 => Self::F16,
            5 => Self::Bf16,
            _ => return None,
        })
    }

    /// Size in bytes of one element.
    pub fn size(self) -> usize {
        match self {
            Self::I8 => 1,
            Self::I16 | Self::F16 | Self::Bf16 => 2,
            Self::F32 | Self::I32 => 4,
        }
    }

    /// CTranslate2's numeric code of this type (used when writing synthetic files in tests).
    pub fn code(self) -> u8 {
        match self {
            Self::F32 => 0,
            Self::I8 => 1,
            Self::I16 => 2,
            Self::I32 => 3,
            Self::F16 => 4,
            Self::Bf16 => 5,
        }
    }
}

/// One named array of the model, with its raw little-endian bytes.
#[derive(Debug, Clone)]
pub struct Variable {
    pub name: String,
    /// Shape in row-major (numpy) order; empty for a scalar.
    pub dims: Vec<usize>,
    pub dtype: Dtype,
    pub data: Vec<u8>,
}

impl Variable {
    /// Number of elements (1 for a scalar).
    pub fn len(&self) -> usize {
        self.dims.iter().product()
    }

    /// True when the variable holds no element.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The values widened to f32; integer types are converted as numbers.
    pub fn to_f32(&self) -> Vec<f32> {
        let d = &self.data;
        match self.dtype {
            Dtype::F32 => d
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect(),
            Dtype::F16 => d
                .chunks_exact(2)
                .map(|c| f16::from_le_bytes([c[0], c[1]]).to_f32())
                .collect(),
            Dtype::Bf16 => d
                .chunks_exact(2)
                .map(|c| half::bf16::from_le_bytes([c[0], c[1]]).to_f32())
                .collect(),
            Dtype::I8 => d.iter().map(|&b| f32::from(b as i8)).collect(),
            Dtype::I16 => d
                .chunks_exact(2)
                .map(|c| f32::from(i16::from_le_bytes([c[0], c[1]])))
                .collect(),
            Dtype::I32 => d
                .chunks_exact(4)
                .map(|c| i32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f32)
                .collect(),
        }
    }

    /// The value of an integer scalar (head counts and flags are stored this way).
    pub fn scalar_i64(&self) -> Result<i64, Ct2Error> {
        let d = &self.data;
        let wrong = || Ct2Error::WrongType {
            name: self.name.clone(),
            dtype: self.dtype,
            wanted: "an integer scalar",
        };
        if self.len() != 1 {
            return Err(wrong());
        }
        Ok(match self.dtype {
            Dtype::I8 => i64::from(d[0] as i8),
            Dtype::I16 => i64::from(i16::from_le_bytes([d[0], d[1]])),
            Dtype::I32 => i64::from(i32::from_le_bytes([d[0], d[1], d[2], d[3]])),
            _ => return Err(wrong()),
        })
    }
}

/// A parsed `model.bin`: header fields, variables in file order and aliases.
#[derive(Debug)]
pub struct Ct2Model {
    pub version: u32,
    pub spec: String,
    pub revision: u32,
    pub variables: Vec<Variable>,
    index: HashMap<String, usize>,
    /// Alias name -> target variable name (e.g. a tied output projection).
    pub aliases: HashMap<String, String>,
}

impl Ct2Model {
    /// Parses a whole model from a reader. `on_progress` receives the number of bytes read so far, so a caller can
    /// drive a progress bar over a large file.
    pub fn read<R: Read>(mut r: R, mut on_progress: impl FnMut(u64)) -> Result<Self, Ct2Error> {
        let mut consumed = 0u64;
        let version = read_u32(&mut r)?;
        if !(5..=6).contains(&version) {
            return Err(Ct2Error::Version(version));
        }
        let spec = read_string(&mut r)?;
        let revision = read_u32(&mut r)?;
        let count = read_u32(&mut r)?;
        let mut variables = Vec::with_capacity(count as usize);
        for _ in 0..count {
            let name = read_string(&mut r)?;
            let rank = read_u8(&mut r)?;
            let mut dims = Vec::with_capacity(rank as usize);
            for _ in 0..rank {
                dims.push(read_u32(&mut r)? as usize);
            }
            let code = read_u8(&mut r)?;
            let dtype = Dtype::from_code(code).ok_or_else(|| Ct2Error::Dtype {
                name: name.clone(),
                code,
            })?;
            let bytes = read_u32(&mut r)? as usize;
            let elements: usize = dims.iter().product();
            if elements * dtype.size() != bytes {
                return Err(Ct2Error::Size {
                    name,
                    bytes,
                    dims,
                    dtype,
                });
            }
            let mut data = vec![0u8; bytes];
            r.read_exact(&mut data)?;
            consumed += bytes as u64;
            on_progress(consumed);
            variables.push(Variable {
                name,
                dims,
                dtype,
                data,
            });
        }
        let mut aliases = HashMap::new();
        // Version 5 files may end right after the variables; a clean end of file then means "no aliases".
        let alias_count = match read_u32(&mut r) {
            Ok(n) => n,
            Err(Ct2Error::Io(e)) if e.kind() == std::io::ErrorKind::UnexpectedEof => 0,
            Err(e) => return Err(e),
        };
        for _ in 0..alias_count {
            let alias = read_string(&mut r)?;
            let target = read_string(&mut r)?;
            aliases.insert(alias, target);
        }
        let index = variables
            .iter()
            .enumerate()
            .map(|(i, v)| (v.name.clone(), i))
            .collect();
        Ok(Self {
            version,
            spec,
            revision,
            variables,
            index,
            aliases,
        })
    }

    /// Looks a variable up by name, following an alias if the name is one.
    pub fn get(&self, name: &str) -> Result<&Variable, Ct2Error> {
        let target = self.aliases.get(name).map_or(name, String::as_str);
        self.index
            .get(target)
            .map(|&i| &self.variables[i])
            .ok_or_else(|| Ct2Error::Missing(name.to_owned()))
    }

    /// True when the model has a variable (or alias) of this name.
    pub fn contains(&self, name: &str) -> bool {
        self.get(name).is_ok()
    }
}

fn read_u8<R: Read>(r: &mut R) -> Result<u8, Ct2Error> {
    let mut b = [0u8; 1];
    r.read_exact(&mut b)?;
    Ok(b[0])
}

fn read_u16<R: Read>(r: &mut R) -> Result<u16, Ct2Error> {
    let mut b = [0u8; 2];
    r.read_exact(&mut b)?;
    Ok(u16::from_le_bytes(b))
}

fn read_u32<R: Read>(r: &mut R) -> Result<u32, Ct2Error> {
    let mut b = [0u8; 4];
    r.read_exact(&mut b)?;
    Ok(u32::from_le_bytes(b))
}

fn read_string<R: Read>(r: &mut R) -> Result<String, Ct2Error> {
    let len = read_u16(r)? as usize;
    let mut b = vec![0u8; len];
    r.read_exact(&mut b)?;
    if b.pop() != Some(0) {
        return Err(Ct2Error::BadString);
    }
    String::from_utf8(b).map_err(|_| Ct2Error::BadString)
}

/// Writer for the same format, used by tests to build small synthetic models.
#[derive(Debug, Default)]
pub struct Ct2Writer {
    buf: Vec<u8>,
    variables: Vec<(String, Vec<usize>, Dtype, Vec<u8>)>,
    aliases: Vec<(String, String)>,
}

impl Ct2Writer {
    /// Adds a variable with raw little-endian data.
    pub fn variable(
        &mut self,
        name: &str,
        dims: &[usize],
        dtype: Dtype,
        data: Vec<u8>,
    ) -> &mut Self {
        self.variables
            .push((name.to_owned(), dims.to_vec(), dtype, data));
        self
    }

    /// Adds a float16 variable from f32 values.
    pub fn f16(&mut self, name: &str, dims: &[usize], values: &[f32]) -> &mut Self {
        let data = values
            .iter()
            .flat_map(|&v| f16::from_f32(v).to_le_bytes())
            .collect();
        self.variable(name, dims, Dtype::F16, data)
    }

    /// Adds an alias.
    pub fn alias(&mut self, alias: &str, target: &str) -> &mut Self {
        self.aliases.push((alias.to_owned(), target.to_owned()));
        self
    }

    /// Serialises the whole file (version 6).
    pub fn finish(mut self, spec: &str, revision: u32) -> Vec<u8> {
        self.buf.extend(6u32.to_le_bytes());
        put_string(&mut self.buf, spec);
        self.buf.extend(revision.to_le_bytes());
        self.buf.extend((self.variables.len() as u32).to_le_bytes());
        for (name, dims, dtype, data) in &self.variables {
            put_string(&mut self.buf, name);
            self.buf.push(dims.len() as u8);
            for &d in dims {
                self.buf.extend((d as u32).to_le_bytes());
            }
            self.buf.push(dtype.code());
            self.buf.extend((data.len() as u32).to_le_bytes());
            self.buf.extend(data);
        }
        self.buf.extend((self.aliases.len() as u32).to_le_bytes());
        for (a, t) in &self.aliases {
            put_string(&mut self.buf, a);
            put_string(&mut self.buf, t);
        }
        self.buf
    }
}

fn put_string(buf: &mut Vec<u8>, s: &str) {
    buf.extend(((s.len() + 1) as u16).to_le_bytes());
    buf.extend(s.as_bytes());
    buf.push(0);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_a_synthetic_file_with_scalars_tensors_and_an_alias() -> Result<(), Ct2Error> {
        let mut w = Ct2Writer::default();
        w.variable(
            "encoder/num_heads",
            &[],
            Dtype::I16,
            6i16.to_le_bytes().to_vec(),
        )
        .f16(
            "decoder/embeddings/weight",
            &[2, 3],
            &[0.5, -1.0, 2.0, 0.0, 0.25, 3.5],
        )
        .variable(
            "encoder/conv1/bias",
            &[2],
            Dtype::F32,
            [1.5f32, -2.0]
                .iter()
                .flat_map(|v| v.to_le_bytes())
                .collect(),
        )
        .alias("decoder/projection/weight", "decoder/embeddings/weight");
        let bytes = w.finish("WhisperSpec", 3);
        let mut seen = 0;
        let m = Ct2Model::read(&bytes[..], |n| seen = n)?;
        assert_eq!(
            (m.version, m.spec.as_str(), m.revision),
            (6, "WhisperSpec", 3)
        );
        assert_eq!(m.variables.len(), 3);
        assert_eq!(seen, 2 + 12 + 8);
        assert_eq!(m.get("encoder/num_heads")?.scalar_i64()?, 6);
        let emb = m.get("decoder/projection/weight")?;
        assert_eq!(emb.name, "decoder/embeddings/weight");
        assert_eq!(emb.dims, vec![2, 3]);
        assert_eq!(emb.to_f32(), vec![0.5, -1.0, 2.0, 0.0, 0.25, 3.5]);
        assert_eq!(m.get("encoder/conv1/bias")?.to_f32(), vec![1.5, -2.0]);
        assert!(matches!(m.get("nope"), Err(Ct2Error::Missing(_))));
        Ok(())
    }

    #[test]
    fn rejects_truncated_and_inconsistent_files() {
        let mut w = Ct2Writer::default();
        w.f16("x", &[4], &[1.0, 2.0, 3.0, 4.0]);
        let bytes = w.finish("WhisperSpec", 3);
        assert!(matches!(
            Ct2Model::read(&bytes[..bytes.len() - 10], |_| {}),
            Err(Ct2Error::Io(_))
        ));
        let mut bad = Ct2Writer::default();
        bad.variable("y", &[3], Dtype::F32, vec![0; 8]);
        assert!(matches!(
            Ct2Model::read(&bad.finish("WhisperSpec", 3)[..], |_| {}),
            Err(Ct2Error::Size { .. })
        ));
        let mut wrong_version = 9u32.to_le_bytes().to_vec();
        wrong_version.extend([0u8; 8]);
        assert!(matches!(
            Ct2Model::read(&wrong_version[..], |_| {}),
            Err(Ct2Error::Version(9))
        ));
    }
}
