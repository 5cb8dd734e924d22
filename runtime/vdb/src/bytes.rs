//! A cursor over a file's bytes that checks every length against what is left before it
//! trusts it: nothing is read past the end, and nothing is allocated for a length the file
//! cannot hold.

use crate::VdbError;

/// The bytes of one file and where reading has got to.
pub(crate) struct Bytes<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> Bytes<'a> {
    pub(crate) fn new(data: &'a [u8]) -> Self {
        Bytes { data, pos: 0 }
    }

    /// Where the next read starts (bytes from the file's start).
    pub(crate) fn pos(&self) -> usize {
        self.pos
    }

    /// Bytes left after the cursor.
    pub(crate) fn left(&self) -> usize {
        self.data.len() - self.pos
    }

    /// Moves the cursor to `pos`, which must lie within the file.
    pub(crate) fn seek(&mut self, pos: u64, what: &'static str) -> Result<(), VdbError> {
        match usize::try_from(pos) {
            Ok(p) if p <= self.data.len() => {
                self.pos = p;
                Ok(())
            }
            _ => Err(VdbError::Corrupt(format!(
                "{what} at byte {pos} lies past the file's end ({} bytes)",
                self.data.len()
            ))),
        }
    }

    /// The next `n` bytes, or [`VdbError::Truncated`] naming `what` was being read.
    pub(crate) fn take(&mut self, n: usize, what: &'static str) -> Result<&'a [u8], VdbError> {
        match self.pos.checked_add(n) {
            Some(end) if end <= self.data.len() => {
                let s = &self.data[self.pos..end];
                self.pos = end;
                Ok(s)
            }
            _ => Err(VdbError::Truncated {
                what,
                at: self.pos,
                need: n,
                len: self.data.len(),
            }),
        }
    }

    fn array<const N: usize>(&mut self, what: &'static str) -> Result<[u8; N], VdbError> {
        let s = self.take(N, what)?;
        Ok(std::array::from_fn(|i| s[i]))
    }

    pub(crate) fn u8(&mut self, what: &'static str) -> Result<u8, VdbError> {
        Ok(self.take(1, what)?[0])
    }

    pub(crate) fn u32(&mut self, what: &'static str) -> Result<u32, VdbError> {
        self.array(what).map(u32::from_le_bytes)
    }

    pub(crate) fn i32(&mut self, what: &'static str) -> Result<i32, VdbError> {
        self.array(what).map(i32::from_le_bytes)
    }

    pub(crate) fn i64(&mut self, what: &'static str) -> Result<i64, VdbError> {
        self.array(what).map(i64::from_le_bytes)
    }

    pub(crate) fn u64(&mut self, what: &'static str) -> Result<u64, VdbError> {
        self.array(what).map(u64::from_le_bytes)
    }

    pub(crate) fn f64(&mut self, what: &'static str) -> Result<f64, VdbError> {
        self.array(what).map(f64::from_le_bytes)
    }

    pub(crate) fn vec3d(&mut self, what: &'static str) -> Result<[f64; 3], VdbError> {
        Ok([self.f64(what)?, self.f64(what)?, self.f64(what)?])
    }

    pub(crate) fn coord(&mut self, what: &'static str) -> Result<[i32; 3], VdbError> {
        Ok([self.i32(what)?, self.i32(what)?, self.i32(what)?])
    }

    /// A string as OpenVDB writes one: its length (u32), then its bytes.
    pub(crate) fn string(&mut self, what: &'static str) -> Result<String, VdbError> {
        let n = self.u32(what)? as usize;
        Ok(String::from_utf8_lossy(self.take(n, what)?).into_owned())
    }

    /// A node mask of `words` 64-bit words (bit n of the node is bit n % 64 of word n / 64).
    pub(crate) fn mask(&mut self, words: usize, what: &'static str) -> Result<Vec<u64>, VdbError> {
        let s = self.take(8 * words, what)?;
        Ok(s.chunks_exact(8)
            .map(|c| u64::from_le_bytes(std::array::from_fn(|i| c[i])))
            .collect())
    }
}

/// Bit `n` of a node mask.
pub(crate) fn bit(mask: &[u64], n: usize) -> bool {
    mask[n / 64] >> (n % 64) & 1 == 1
}

/// The set bits of a node mask, in increasing order.
pub(crate) fn ones(mask: &[u64]) -> impl Iterator<Item = usize> + '_ {
    mask.iter().enumerate().flat_map(|(w, &word)| {
        let mut rest = word;
        std::iter::from_fn(move || {
            (rest != 0).then(|| {
                let b = rest.trailing_zeros() as usize;
                rest &= rest - 1;
                64 * w + b
            })
        })
    })
}
