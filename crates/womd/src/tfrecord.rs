//! TFRecord framing: `u64 length · u32 masked_crc(length) · data · u32 masked_crc(data)`.
//!
//! The reader walks a byte slice (normally a memory map of the file), so a multi-GB shard is
//! never read into memory; it checks both CRCs and never allocates from an untrusted length.

use std::io::Write;

/// Bytes of framing before a record's data (length + its CRC).
const HEADER_BYTES: usize = 12;
/// Bytes of framing after a record's data (the data CRC).
const FOOTER_BYTES: usize = 4;
const MASK_DELTA: u32 = 0xa282_ead8;

/// TFRecord's masked CRC-32C.
pub fn masked_crc32c(bytes: &[u8]) -> u32 {
    let crc = crc32c::crc32c(bytes);
    (crc.rotate_right(15)).wrapping_add(MASK_DELTA)
}

/// One record of a TFRecord file, borrowed from the underlying bytes.
#[derive(Debug, Clone, Copy)]
pub struct Record<'a> {
    /// 0-based position of the record in the file.
    pub index: usize,
    /// Byte offset of the record's length field in the file.
    pub offset: u64,
    /// The record's payload (without framing), borrowed from the file bytes.
    pub data: &'a [u8],
}

/// What is wrong with one record's framing.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RecordError {
    /// Fewer than the 12 header bytes are left.
    #[allow(missing_docs)]
    #[error("truncated header: {available} bytes left, a record header needs 12")]
    TruncatedHeader { available: u64 },
    /// The length field's CRC does not match.
    #[allow(missing_docs)]
    #[error("length CRC mismatch (stored {stored:#010x}, computed {computed:#010x})")]
    LengthCrc { stored: u32, computed: u32 },
    /// The length runs past the end of the file.
    #[allow(missing_docs)]
    #[error("record length {length} exceeds the {available} bytes left in the file")]
    TruncatedData { length: u64, available: u64 },
    /// The data's CRC does not match (resumable: the framing is intact).
    #[allow(missing_docs)]
    #[error("data CRC mismatch (stored {stored:#010x}, computed {computed:#010x})")]
    DataCrc { stored: u32, computed: u32 },
}

impl RecordError {
    /// Whether reading can go on with the next record after this error. Only a bad data CRC
    /// leaves the framing intact; after any other error the next record's start is unknown.
    pub fn is_resumable(&self) -> bool {
        matches!(self, Self::DataCrc { .. })
    }
}

/// A framing error together with where it happened.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("record {index} at byte {offset}: {kind}")]
pub struct RecordAt {
    /// 0-based index of the bad record in the file.
    pub index: usize,
    /// Byte offset of the bad record's length field in the file.
    pub offset: u64,
    /// What is wrong with it.
    pub kind: RecordError,
}

/// Iterates the records of a TFRecord byte slice.
///
/// Yields `Err` for a bad record; after a resumable error (bad data CRC) it goes on with the
/// next record, after any other error it stops.
#[derive(Debug, Clone)]
pub struct RecordIter<'a> {
    bytes: &'a [u8],
    pos: usize,
    index: usize,
    done: bool,
}

impl<'a> RecordIter<'a> {
    /// Iterates the records of `bytes`, from its start.
    pub fn new(bytes: &'a [u8]) -> Self {
        Self {
            bytes,
            pos: 0,
            index: 0,
            done: false,
        }
    }

    fn read_u32(&self, at: usize) -> u32 {
        u32::from_le_bytes(self.bytes[at..at + 4].try_into().expect("4 bytes"))
    }
}

impl<'a> Iterator for RecordIter<'a> {
    type Item = Result<Record<'a>, RecordAt>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done || self.pos == self.bytes.len() {
            return None;
        }
        let offset = self.pos as u64;
        let index = self.index;
        let fail = |it: &mut Self, kind: RecordError| {
            it.done = !kind.is_resumable();
            Some(Err(RecordAt {
                index,
                offset,
                kind,
            }))
        };
        let available = (self.bytes.len() - self.pos) as u64;
        if available < HEADER_BYTES as u64 {
            return fail(self, RecordError::TruncatedHeader { available });
        }
        let length_bytes = &self.bytes[self.pos..self.pos + 8];
        let length = u64::from_le_bytes(length_bytes.try_into().expect("8 bytes"));
        let stored = self.read_u32(self.pos + 8);
        let computed = masked_crc32c(length_bytes);
        if stored != computed {
            return fail(self, RecordError::LengthCrc { stored, computed });
        }
        let after_header = available - HEADER_BYTES as u64;
        let fits = after_header
            .checked_sub(FOOTER_BYTES as u64)
            .is_some_and(|room| length <= room);
        if !fits {
            return fail(
                self,
                RecordError::TruncatedData {
                    length,
                    available: after_header,
                },
            );
        }
        // `length` fits in the slice, so it fits in usize.
        let start = self.pos + HEADER_BYTES;
        let end = start + length as usize;
        let data = &self.bytes[start..end];
        let stored = self.read_u32(end);
        self.pos = end + FOOTER_BYTES;
        self.index += 1;
        let computed = masked_crc32c(data);
        if stored != computed {
            return fail(self, RecordError::DataCrc { stored, computed });
        }
        Some(Ok(Record {
            index,
            offset,
            data,
        }))
    }
}

/// Writes TFRecord framing around each record.
#[derive(Debug)]
pub struct RecordWriter<W: Write> {
    inner: W,
    records_written: usize,
}

impl<W: Write> RecordWriter<W> {
    /// A writer that frames records into `inner`.
    pub fn new(inner: W) -> Self {
        Self {
            inner,
            records_written: 0,
        }
    }

    /// Writes one record: length, length CRC, `data`, data CRC.
    pub fn write_record(&mut self, data: &[u8]) -> std::io::Result<()> {
        let length = (data.len() as u64).to_le_bytes();
        self.inner.write_all(&length)?;
        self.inner
            .write_all(&masked_crc32c(&length).to_le_bytes())?;
        self.inner.write_all(data)?;
        self.inner.write_all(&masked_crc32c(data).to_le_bytes())?;
        self.records_written += 1;
        Ok(())
    }

    /// Number of records written so far.
    pub fn records_written(&self) -> usize {
        self.records_written
    }

    /// Returns the inner writer. Nothing is buffered here; flushing `inner` is the caller's job.
    pub fn into_inner(self) -> W {
        self.inner
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn framed(records: &[&[u8]]) -> Vec<u8> {
        let mut w = RecordWriter::new(Vec::new());
        for r in records {
            w.write_record(r).unwrap();
        }
        w.into_inner()
    }

    #[test]
    fn crc32c_check_value() {
        assert_eq!(crc32c::crc32c(b"123456789"), 0xE306_9283);
    }

    #[test]
    fn round_trip_records() {
        let bytes = framed(&[b"hello", b"", b"world!"]);
        let got: Vec<_> = RecordIter::new(&bytes).map(|r| r.unwrap()).collect();
        assert_eq!(got.len(), 3);
        assert_eq!(got[0].data, b"hello");
        assert_eq!(got[1].data, b"");
        assert_eq!(got[2].data, b"world!");
        assert_eq!(got[1].offset, 12 + 5 + 4);
        assert_eq!(got[2].index, 2);
    }

    #[test]
    fn bad_data_crc_is_resumable() {
        let mut bytes = framed(&[b"hello", b"world"]);
        bytes[12] ^= 0xff; // corrupt the first record's data
        let got: Vec<_> = RecordIter::new(&bytes).collect();
        assert_eq!(got.len(), 2);
        assert!(matches!(
            got[0],
            Err(RecordAt {
                index: 0,
                offset: 0,
                kind: RecordError::DataCrc { .. }
            })
        ));
        assert_eq!(got[1].as_ref().unwrap().data, b"world");
    }

    #[test]
    fn bad_length_crc_stops() {
        let mut bytes = framed(&[b"hello", b"world"]);
        bytes[8] ^= 0x01;
        let got: Vec<_> = RecordIter::new(&bytes).collect();
        assert_eq!(got.len(), 1);
        assert!(matches!(
            got[0],
            Err(RecordAt {
                kind: RecordError::LengthCrc { .. },
                ..
            })
        ));
    }

    #[test]
    fn huge_length_is_rejected_without_allocating() {
        let length = (1u64 << 60).to_le_bytes();
        let mut bytes = length.to_vec();
        bytes.extend_from_slice(&masked_crc32c(&length).to_le_bytes());
        bytes.extend_from_slice(&[0u8; 16]);
        let got: Vec<_> = RecordIter::new(&bytes).collect();
        assert!(matches!(
            got[0],
            Err(RecordAt {
                kind: RecordError::TruncatedData {
                    length: 1_152_921_504_606_846_976,
                    ..
                },
                ..
            })
        ));
    }

    #[test]
    fn truncated_inputs() {
        let bytes = framed(&[b"hello"]);
        for cut in 1..bytes.len() {
            let got: Vec<_> = RecordIter::new(&bytes[..cut]).collect();
            assert_eq!(got.len(), 1, "cut at {cut}");
            assert!(got[0].is_err(), "cut at {cut}");
        }
        assert_eq!(RecordIter::new(&[]).count(), 0);
    }

    #[test]
    fn an_empty_record_cut_inside_its_footer_is_truncated() {
        // Found by fuzzing: a zero length left room for no footer at all.
        let bytes = framed(&[b""]);
        for cut in HEADER_BYTES..bytes.len() {
            let got: Vec<_> = RecordIter::new(&bytes[..cut]).collect();
            assert!(
                matches!(
                    got[..],
                    [Err(RecordAt {
                        kind: RecordError::TruncatedData { length: 0, .. },
                        ..
                    })]
                ),
                "cut at {cut}: {got:?}"
            );
        }
    }
}
