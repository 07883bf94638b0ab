//! Readers for the payload's fields: postcard values, little-endian arrays and the lazily
//! decoded lists (observation layout, action names).

use serde::Deserialize;

use crate::PolicyError;

/// Alignment of every array in a version-2 payload (file offsets are multiples of it).
pub const TENSOR_ALIGN: usize = 16;

/// A borrowed array of little-endian `f32` (four bytes each) inside the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct F32s<'a> {
    bytes: &'a [u8],
    /// Payload offset of the first byte (for errors).
    offset: usize,
    /// Stored at an aligned offset for use in place (version 2), not after a varint (1).
    in_place: bool,
}

impl<'a> F32s<'a> {
    pub(crate) fn new(bytes: &'a [u8], offset: usize, in_place: bool) -> Self {
        Self { bytes, offset, in_place }
    }

    /// Whether the array is stored to be used in place (version 2).
    pub fn is_in_place(&self) -> bool {
        self.in_place
    }

    /// Number of values.
    pub fn len(&self) -> usize {
        self.bytes.len() / 4
    }

    pub fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }

    /// Decodes the values in order.
    pub fn iter(&self) -> impl Iterator<Item = f32> + 'a {
        self.bytes.chunks_exact(4).map(|c| {
            let mut b = [0u8; 4];
            b.copy_from_slice(c);
            f32::from_le_bytes(b)
        })
    }

    pub(crate) fn check_finite(&self, field: &'static str) -> Result<(), PolicyError> {
        match self.iter().position(|v| !v.is_finite()) {
            Some(index) => Err(PolicyError::NonFinite { field, index }),
            None => Ok(()),
        }
    }

    pub(crate) fn check_positive(&self, field: &'static str) -> Result<(), PolicyError> {
        self.check_finite(field)?;
        match self.iter().position(|v| v <= 0.0) {
            Some(index) => Err(PolicyError::NotPositive { field, index }),
            None => Ok(()),
        }
    }

    pub(crate) fn check_len(&self, field: &'static str, expected: usize) -> Result<(), PolicyError> {
        if self.len() != expected {
            return Err(PolicyError::Len { field, expected, got: self.len() });
        }
        Ok(())
    }

    /// Decodes into the front of `*storage` and advances it past the copied values
    /// (version 1, whose arrays sit at arbitrary offsets).
    pub(crate) fn copy_into(&self, storage: &mut &'a mut [f32]) -> Result<&'a [f32], PolicyError> {
        let n = self.len();
        let got = storage.len();
        let (head, tail) = core::mem::take(storage)
            .split_at_mut_checked(n)
            .ok_or(PolicyError::StorageTooSmall { needed: n, got })?;
        *storage = tail;
        for (dst, v) in head.iter_mut().zip(self.iter()) {
            *dst = v;
        }
        Ok(head)
    }

    /// The values in place (version 2): see [`borrow_in_place`].
    pub(crate) fn borrow(&self, field: &'static str) -> Result<&'a [f32], PolicyError> {
        borrow_in_place(self.bytes, self.offset, field)
    }
}

/// Views little-endian file bytes as a `&[T]` without copying. `bytemuck` checks length and
/// alignment (no `unsafe` here); a misaligned array is a typed error naming the field and
/// its file offset. On a big-endian target the bytes would be the wrong values, so the view
/// is refused there.
pub(crate) fn borrow_in_place<'a, T: bytemuck::Pod>(
    bytes: &'a [u8],
    payload_offset: usize,
    field: &'static str,
) -> Result<&'a [T], PolicyError> {
    let file_offset = payload_offset.saturating_add(crate::format::HEADER_LEN);
    if cfg!(target_endian = "big") {
        return Err(PolicyError::InPlaceNeedsLittleEndian { field });
    }
    bytemuck::try_cast_slice(bytes).map_err(|_| PolicyError::Misaligned {
        field,
        file_offset,
        align: core::mem::align_of::<T>(),
    })
}

/// Sequential reader over the payload.
#[derive(Debug, Clone)]
pub(crate) struct Reader<'a> {
    pub(crate) payload: &'a [u8],
    pub(crate) pos: usize,
}

impl<'a> Reader<'a> {
    pub(crate) fn new(payload: &'a [u8]) -> Self {
        Self { payload, pos: 0 }
    }

    pub(crate) fn rest(&self) -> &'a [u8] {
        self.payload.get(self.pos..).unwrap_or(&[])
    }

    /// The next `n` bytes.
    pub(crate) fn bytes(&mut self, n: usize, field: &'static str) -> Result<&'a [u8], PolicyError> {
        let b = self.rest().get(..n).ok_or(PolicyError::Malformed { field, offset: self.pos })?;
        self.pos = self.pos.saturating_add(n);
        Ok(b)
    }

    /// One postcard value.
    pub(crate) fn take<T: Deserialize<'a>>(&mut self, field: &'static str) -> Result<T, PolicyError> {
        let rest = self.rest();
        let (v, after) = postcard::take_from_bytes::<T>(rest)
            .map_err(|_| PolicyError::Malformed { field, offset: self.pos })?;
        self.pos = self.pos.saturating_add(rest.len().saturating_sub(after.len()));
        Ok(v)
    }

    /// A length or dimension: postcard varint (unsigned LEB128) of at most 32 bits.
    pub(crate) fn len(&mut self, field: &'static str) -> Result<usize, PolicyError> {
        let v: u32 = self.take(field)?;
        usize::try_from(v).map_err(|_| PolicyError::Malformed { field, offset: self.pos })
    }

    /// A postcard `seq<f32>` (version 1): varint count, then the values.
    pub(crate) fn f32s(&mut self, field: &'static str) -> Result<F32s<'a>, PolicyError> {
        let start = self.pos;
        let n = self.len(field)?;
        let n_bytes = n.checked_mul(4).ok_or(PolicyError::Malformed { field, offset: start })?;
        let offset = self.pos;
        Ok(F32s::new(self.bytes(n_bytes, field)?, offset, false))
    }

    /// A non-empty name.
    pub(crate) fn name(&mut self, field: &'static str, index: usize) -> Result<&'a str, PolicyError> {
        let s: &'a str = self.take(field)?;
        if s.is_empty() {
            return Err(PolicyError::EmptyName { field, index });
        }
        Ok(s)
    }

    /// Skips the zero padding up to the next multiple of [`TENSOR_ALIGN`] (version 2), then
    /// takes an array of `n` elements of `elem_bytes` each. Non-zero padding is an error, so
    /// that every valid file has exactly one encoding.
    pub(crate) fn tensor(
        &mut self,
        n: usize,
        elem_bytes: usize,
        field: &'static str,
    ) -> Result<(&'a [u8], usize), PolicyError> {
        let pad = (TENSOR_ALIGN - self.pos % TENSOR_ALIGN) % TENSOR_ALIGN;
        let padding = self.bytes(pad, field)?;
        if let Some(i) = padding.iter().position(|&b| b != 0) {
            return Err(PolicyError::NonZeroPadding { offset: self.pos - pad + i });
        }
        let n_bytes = n.checked_mul(elem_bytes).ok_or(PolicyError::Malformed { field, offset: self.pos })?;
        let offset = self.pos;
        Ok((self.bytes(n_bytes, field)?, offset))
    }

    /// [`Reader::tensor`] of `f32`.
    pub(crate) fn f32_tensor(&mut self, n: usize, field: &'static str) -> Result<F32s<'a>, PolicyError> {
        let (bytes, offset) = self.tensor(n, 4, field)?;
        Ok(F32s::new(bytes, offset, true))
    }
}

/// A named slice `start..end` of the observation vector.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ObsSlice<'a> {
    pub name: &'a str,
    pub start: usize,
    pub end: usize,
}

/// The observation layout, decoded lazily from the (already validated) file bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ObsLayout<'a> {
    pub(crate) raw: &'a [u8],
    pub(crate) count: usize,
}

impl<'a> ObsLayout<'a> {
    /// Number of named slices.
    pub fn len(&self) -> usize {
        self.count
    }

    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// The slices in order (they are contiguous and cover `0..obs_dim`).
    pub fn iter(&self) -> impl Iterator<Item = ObsSlice<'a>> + 'a {
        let mut r = Reader::new(self.raw);
        (0..self.count).map_while(move |_| {
            let name: &'a str = r.take("obs_layout").ok()?;
            let start = r.len("obs_layout").ok()?;
            let end = r.len("obs_layout").ok()?;
            Some(ObsSlice { name, start, end })
        })
    }

    /// The first slice called `name`.
    pub fn get(&self, name: &str) -> Option<ObsSlice<'a>> {
        self.iter().find(|s| s.name == name)
    }
}

/// A list of names (the action names), decoded lazily from the file bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Names<'a> {
    pub(crate) raw: &'a [u8],
    pub(crate) count: usize,
}

impl<'a> Names<'a> {
    pub fn len(&self) -> usize {
        self.count
    }

    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    pub fn iter(&self) -> impl Iterator<Item = &'a str> + 'a {
        let mut r = Reader::new(self.raw);
        (0..self.count).map_while(move |_| r.take::<&'a str>("action_names").ok())
    }

    /// Index of the first entry equal to `name`.
    pub fn position(&self, name: &str) -> Option<usize> {
        self.iter().position(|n| n == name)
    }
}
