//! The jobs file the fleet's satellite processes decode from: the utterances travel once, as per job a u32 sample
//! count then the f32 samples, little-endian; after that a job is named by its index.

use std::path::Path;

use anyhow::Context;

/// Writes `jobs` to `path` in the worker's format.
pub fn write_jobs(path: &Path, jobs: &[Vec<f32>]) -> anyhow::Result<()> {
    let mut bytes = Vec::new();
    for job in jobs {
        bytes.extend_from_slice(&u32::try_from(job.len())?.to_le_bytes());
        for s in job {
            bytes.extend_from_slice(&s.to_le_bytes());
        }
    }
    std::fs::write(path, bytes).with_context(|| format!("writing {}", path.display()))
}

/// Reads back what [`write_jobs`] wrote.
pub fn read_jobs(path: &Path) -> anyhow::Result<Vec<Vec<f32>>> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let mut jobs = Vec::new();
    let mut rest = &bytes[..];
    while !rest.is_empty() {
        let (len, tail) = rest
            .split_first_chunk::<4>()
            .context("truncated job length")?;
        let n = u32::from_le_bytes(*len) as usize;
        let body = tail.get(..n * 4).context("truncated job samples")?;
        jobs.push(
            body.chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect(),
        );
        rest = &tail[n * 4..];
    }
    Ok(jobs)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jobs_written_to_a_file_are_read_back_sample_for_sample() {
        let dir = tempfile::tempdir().expect("temporary directory");
        let path = dir.path().join("jobs.f32");
        let jobs = vec![vec![0.5, -1.0, 0.25], Vec::new(), vec![f32::MIN_POSITIVE]];
        write_jobs(&path, &jobs).expect("writing the jobs");
        assert_eq!(read_jobs(&path).expect("reading the jobs"), jobs);
    }

    #[test]
    fn a_truncated_jobs_file_is_refused() {
        let dir = tempfile::tempdir().expect("temporary directory");
        let path = dir.path().join("jobs.f32");
        write_jobs(&path, &[vec![1.0, 2.0]]).expect("writing the jobs");
        let bytes = std::fs::read(&path).expect("reading the file");
        std::fs::write(&path, &bytes[..bytes.len() - 2]).expect("truncating the file");
        assert!(read_jobs(&path).is_err());
    }
}
