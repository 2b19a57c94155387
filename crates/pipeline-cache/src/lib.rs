//! errmap's one unsafe call: a wgpu pipeline cache created from bytes that a pipeline cache gave earlier (`PipelineCache::get_data`), read back from a file only when its SHA-256 matches.
//!
//! `wgpu::Device::create_pipeline_cache` is `unsafe` because the driver trusts the bytes it
//! is given: they must be what `PipelineCache::get_data` returned. errmap keeps those bytes
//! in its cache folder. This crate is the only place that hands bytes to the driver, and a
//! [`Saved`] can only be made from `get_data`'s output or from a file whose SHA-256 (written
//! beside the bytes when they were saved) and key both match, so a truncated, overwritten
//! or foreign file never reaches the driver. (wgpu itself checks its own header: adapter,
//! driver validation key, wgpu version, length.) The errmap crate keeps
//! `#![forbid(unsafe_code)]`.
#![warn(missing_docs)]

use sha2::{Digest, Sha256};

/// First bytes of a cache file of this format.
const MAGIC: &[u8] = b"errmap-pipeline-cache 1\n";

/// Pipeline-cache bytes that came from `PipelineCache::get_data`, with the key (adapter,
/// driver, program version, architecture …) they were saved under.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Saved {
    key: String,
    data: Vec<u8>,
}

/// Why a cache file's bytes were not used.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Rejected {
    /// Not a file of this format, or cut short.
    Truncated,
    /// Saved under another key (another adapter, driver, version or architecture).
    OtherKey(String),
    /// The bytes do not match the SHA-256 saved with them.
    Corrupt,
}

impl std::fmt::Display for Rejected {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Rejected::Truncated => write!(f, "not a pipeline cache file, or cut short"),
            Rejected::OtherKey(key) => write!(f, "saved for another build ({key})"),
            Rejected::Corrupt => write!(f, "its checksum does not match (corrupt)"),
        }
    }
}

impl Saved {
    /// The current contents of `cache` (`None` when the backend keeps none).
    pub fn of(cache: &wgpu::PipelineCache, key: &str) -> Option<Saved> {
        cache.get_data().map(|data| Saved {
            key: key.to_string(),
            data,
        })
    }

    /// Size of the cache data handed to the driver, bytes (the key and header not counted).
    pub fn len(&self) -> usize {
        self.data.len()
    }

    /// Whether there is no cache data at all.
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    /// The file form: magic, key length (u32 LE), key, SHA-256 of the data, data.
    pub fn encode(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(MAGIC.len() + 4 + self.key.len() + 32 + self.data.len());
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&(self.key.len() as u32).to_le_bytes());
        out.extend_from_slice(self.key.as_bytes());
        out.extend_from_slice(&Sha256::digest(&self.data));
        out.extend_from_slice(&self.data);
        out
    }

    /// Reads [`Saved::encode`]'s form, checking that it was saved under `key` and that the
    /// data still has its SHA-256.
    pub fn decode(file: &[u8], key: &str) -> Result<Saved, Rejected> {
        let rest = file.strip_prefix(MAGIC).ok_or(Rejected::Truncated)?;
        let (len, rest) = split(rest, 4)?;
        let len = u32::from_le_bytes([len[0], len[1], len[2], len[3]]) as usize;
        let (saved_key, rest) = split(rest, len)?;
        let saved_key = String::from_utf8_lossy(saved_key);
        if saved_key != key {
            return Err(Rejected::OtherKey(saved_key.into_owned()));
        }
        let (digest, data) = split(rest, 32)?;
        if Sha256::digest(data).as_slice() != digest {
            return Err(Rejected::Corrupt);
        }
        Ok(Saved {
            key: key.to_string(),
            data: data.to_vec(),
        })
    }
}

fn split(bytes: &[u8], at: usize) -> Result<(&[u8], &[u8]), Rejected> {
    (bytes.len() >= at)
        .then(|| bytes.split_at(at))
        .ok_or(Rejected::Truncated)
}

/// A pipeline cache on `device` (which must have `Features::PIPELINE_CACHE`), started from
/// `saved` when given. With `fallback = false` wgpu reports a validation error (through the
/// device's error scopes) when it will not use the data: stale for this driver or wgpu.
pub fn create(
    device: &wgpu::Device,
    label: &str,
    saved: Option<&Saved>,
    fallback: bool,
) -> wgpu::PipelineCache {
    let descriptor = wgpu::PipelineCacheDescriptor {
        label: Some(label),
        data: saved.map(|s| s.data.as_slice()),
        fallback,
    };
    // SAFETY: `data` is `None`, or the bytes of a `Saved`, which holds only what
    // `PipelineCache::get_data` returned — in this process (`Saved::of`), or saved by
    // `Saved::encode` and read back intact (`Saved::decode` checks the SHA-256 stored with
    // them). wgpu then checks its own header (adapter key, driver validation key, version,
    // length) and, with `fallback`, drops data it cannot use.
    unsafe { device.create_pipeline_cache(&descriptor) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_saved_file_reads_back_only_whole_and_under_its_key() {
        let saved = Saved {
            key: "llvmpipe | 2-32-32-1 tanh".into(),
            data: vec![1, 2, 3, 250],
        };
        let file = saved.encode();
        assert_eq!(Saved::decode(&file, "llvmpipe | 2-32-32-1 tanh"), Ok(saved));
        assert_eq!(
            Saved::decode(&file, "llvmpipe | 2-16-1 tanh"),
            Err(Rejected::OtherKey("llvmpipe | 2-32-32-1 tanh".into()))
        );
        let mut flipped = file.clone();
        *flipped.last_mut().unwrap() ^= 1;
        assert_eq!(
            Saved::decode(&flipped, "llvmpipe | 2-32-32-1 tanh"),
            Err(Rejected::Corrupt)
        );
        assert_eq!(
            Saved::decode(&file[..file.len() - 40], "llvmpipe | 2-32-32-1 tanh"),
            Err(Rejected::Truncated)
        );
        assert_eq!(Saved::decode(b"junk", "k"), Err(Rejected::Truncated));
    }
}
