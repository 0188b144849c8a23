//! Bounds checks of a Parquet file's Thrift structures before the Parquet crate decodes them.
//!
//! Fuzzing found three ways a few kilobytes of malformed Parquet hold parquet 60.1 for seconds
//! or gigabytes:
//! - It skips a field it does not know one claimed element at a time, and skipping a boolean
//!   reads no byte (in a footer), or reads nothing more at the end of a column chunk (in a page
//!   header): a list claiming 2^31 elements in a few bytes loops 2^31 times. In the compact
//!   protocol every element of a list, set or map takes a byte at least, so a collection
//!   claiming more elements than bytes remain is malformed.
//! - It allocates and zeroes what a page header claims: the page's uncompressed size (up to
//!   2 GiB) before decompressing, and a dictionary of as many values as its header claims
//!   (2^31 eight-byte values). Snappy, the one codec built in, expands at most 32 times, and a
//!   dictionary holds a value per bit of its page at most (booleans).
//!
//! [`check_footer`] and [`check_pages`] walk the structures once, reading only headers and
//! lengths, and refuse such a file before the Parquet crate sees it. The walk follows the
//! format's schema ([`format`]) as the Parquet crate does, and refuses a field the schema
//! knows but that comes with another wire type (the crate would read it as the schema's type,
//! somewhere else than this walk); fields the schema does not know are skipped by their wire
//! type, as the crate skips them. Hand-written because no Thrift crate in the tree exposes a
//! bounded skip.

mod format;

use format::Ty;

/// The deepest nesting walked; a label table's footer nests a few levels.
const MAX_DEPTH: u32 = 32;

/// The most a page may expand: Snappy's worst case (a 2-byte copy tag for 64 bytes) is 32
/// times, plus room for the uncompressed levels of a version 2 data page.
const MAX_EXPANSION: u64 = 32;
const EXPANSION_SLACK_BYTES: u64 = 64 * 1024;

/// Checks the Thrift of the footer of the Parquet file `file` (its `FileMetaData`); an error
/// says what is malformed. A file too short to hold a footer passes: the Parquet crate
/// refuses it with its own message.
pub(super) fn check_footer(file: &[u8]) -> Result<(), String> {
    let Some(tail) = file.len().checked_sub(8).map(|at| &file[at..]) else {
        return Ok(());
    };
    let length = u32::from_le_bytes(tail[..4].try_into().expect("4 bytes")) as usize;
    let Some(start) = (file.len() - 8).checked_sub(length) else {
        return Ok(());
    };
    Walker::new(&file[start..file.len() - 8], &[])
        .schema_struct(format::FILE_METADATA, 0)
        .map_err(|why| format!("footer metadata: {why}"))
}

/// Checks the page headers of one column chunk (`chunk`, its bytes in the file): each must
/// parse within the chunk with no collection claiming more elements than bytes remain (the
/// Parquet crate's page reader, too, loops over a claimed count at the chunk's end), no page
/// may claim to expand beyond what Snappy can, and no dictionary more values than its page
/// has bits.
pub(super) fn check_pages(chunk: &[u8]) -> Result<(), String> {
    // The page header's uncompressed and compressed sizes, and its dictionary header's count.
    const SIZES: &[&[i16]] = &[&[2], &[3], &[7, 1]];
    let mut at = 0usize;
    while at < chunk.len() {
        let mut walker = Walker::new(&chunk[at..], SIZES);
        walker
            .schema_struct(format::PAGE_HEADER, 0)
            .map_err(|why| format!("the page header at byte {at} of its column chunk: {why}"))?;
        let (Some(uncompressed), Some(compressed)) = (walker.kept(0), walker.kept(1)) else {
            // No sizes: the Parquet crate refuses the page with its own message.
            return Ok(());
        };
        let dictionary_values = walker.kept(2);
        let (Ok(uncompressed), Ok(compressed)) =
            (u64::try_from(uncompressed), u64::try_from(compressed))
        else {
            return Ok(());
        };
        if uncompressed > compressed * MAX_EXPANSION + EXPANSION_SLACK_BYTES {
            return Err(format!(
                "a page at byte {at} of its column chunk claims {uncompressed} bytes from {compressed}"
            ));
        }
        if let Some(values) = dictionary_values
            && values > 0
            && values as u64 > uncompressed.saturating_mul(8)
        {
            return Err(format!(
                "a dictionary page at byte {at} of its column chunk claims {values} values in {uncompressed} bytes"
            ));
        }
        at = at
            .saturating_add(walker.at)
            .saturating_add(compressed as usize);
    }
    Ok(())
}

fn zigzag(v: u64) -> i64 {
    (v >> 1) as i64 ^ -((v & 1) as i64)
}

/// A walk through Thrift compact-protocol bytes that reads headers and lengths only.
struct Walker<'a> {
    bytes: &'a [u8],
    at: usize,
    /// The ids of the known fields from the walk's root to where it is.
    path: Vec<i16>,
    /// The i32 fields whose values the walk keeps, by their paths, and the values kept: the
    /// index into `keep` and the value, in the order read.
    keep: &'static [&'static [i16]],
    kept: Vec<(usize, i64)>,
}

impl<'a> Walker<'a> {
    fn new(bytes: &'a [u8], keep: &'static [&'static [i16]]) -> Self {
        Self {
            bytes,
            at: 0,
            path: Vec::new(),
            keep,
            kept: Vec::new(),
        }
    }

    /// The value of `keep[k]` as the Parquet crate takes it (the last one read), if read.
    fn kept(&self, k: usize) -> Option<i64> {
        self.kept
            .iter()
            .rev()
            .find(|(i, _)| *i == k)
            .map(|&(_, v)| v)
    }

    fn left(&self) -> usize {
        self.bytes.len() - self.at
    }

    fn byte(&mut self) -> Result<u8, String> {
        let b = *self
            .bytes
            .get(self.at)
            .ok_or_else(|| format!("ends at byte {}", self.at))?;
        self.at += 1;
        Ok(b)
    }

    /// A varint read as parquet 60.1 reads one: any length, bits past the 64th wrapping.
    fn varint(&mut self) -> Result<u64, String> {
        let mut value = 0u64;
        let mut shift = 0u32;
        loop {
            let b = self.byte()?;
            value |= u64::from(b & 0x7f).wrapping_shl(shift);
            if b & 0x80 == 0 {
                return Ok(value);
            }
            shift = shift.wrapping_add(7);
        }
    }

    /// An i32 field's value, as parquet 60.1 reads it (a zigzag varint truncated to 32 bits).
    fn i32(&mut self) -> Result<i64, String> {
        Ok(i64::from(zigzag(self.varint()?) as i32))
    }

    fn skip(&mut self, n: u64) -> Result<(), String> {
        if n > self.left() as u64 {
            return Err(format!(
                "{n} bytes claimed at byte {}, {} left",
                self.at,
                self.left()
            ));
        }
        self.at += n as usize;
        Ok(())
    }

    /// A field's id from its header and the struct's previous one, as parquet 60.1 reads it
    /// (an id written in full is truncated to 16 bits; a delta past `i16::MAX` is malformed).
    fn field_id(&mut self, previous: i16, header: u8) -> Result<i16, String> {
        match header >> 4 {
            0 => Ok(zigzag(self.varint()?) as i16),
            delta => previous
                .checked_add(i16::from(delta))
                .ok_or_else(|| format!("a field id past {} at byte {}", i16::MAX, self.at)),
        }
    }

    /// A struct of the format's schema (`fields`), to its stop byte: a field the schema knows
    /// must come with its type, one it does not is skipped by its wire type.
    fn schema_struct(&mut self, fields: &[(i16, Ty)], depth: u32) -> Result<(), String> {
        if depth > MAX_DEPTH {
            return Err(format!("nested over {MAX_DEPTH} deep"));
        }
        let mut id = 0i16;
        loop {
            let header = self.byte()?;
            let code = header & 0x0f;
            if code == 0 {
                return Ok(());
            }
            id = self.field_id(id, header)?;
            match fields.iter().find(|(known, _)| *known == id) {
                Some(&(_, ty)) if ty.is_code(code) => {
                    self.path.push(id);
                    let keep = self.keep.iter().position(|p| *p == self.path.as_slice());
                    match (ty, keep) {
                        (Ty::I32, Some(k)) => {
                            let value = self.i32()?;
                            self.kept.push((k, value));
                        }
                        _ => self.schema_value(ty, depth)?,
                    }
                    self.path.pop();
                }
                Some(&(_, ty)) => {
                    return Err(format!(
                        "field {id} at byte {} has wire type {code}, the format's is {}",
                        self.at,
                        ty.name()
                    ));
                }
                None => self.value(code, depth)?,
            }
        }
    }

    /// A field's value of the schema's type `ty` (a boolean field's value is in its header).
    fn schema_value(&mut self, ty: Ty, depth: u32) -> Result<(), String> {
        match ty {
            Ty::Bool => Ok(()),
            Ty::Byte => self.skip(1),
            Ty::I16 | Ty::I32 | Ty::I64 => self.varint().map(drop),
            Ty::Double => self.skip(8),
            Ty::Binary => {
                let length = self.varint()?;
                self.skip(length)
            }
            Ty::List(element) => {
                let (size, code) = self.list_header()?;
                if (size, code) == (0, 0) {
                    return Ok(()); // an empty list written as a 0 byte, as some writers do
                }
                if !element.is_code(code) {
                    return Err(format!(
                        "a list at byte {} of wire type {code}, the format's is {}",
                        self.at,
                        element.name()
                    ));
                }
                self.claims(size, 1)?;
                for _ in 0..size {
                    match *element {
                        Ty::Bool => self.skip(1)?,
                        element => self.schema_value(element, depth + 1)?,
                    }
                }
                Ok(())
            }
            Ty::Struct(fields) => self.schema_struct(fields, depth + 1),
        }
    }

    /// A list or set header: its size and its elements' compact type.
    fn list_header(&mut self) -> Result<(u64, u8), String> {
        let header = self.byte()?;
        let size = match header >> 4 {
            15 => self.varint()?,
            small => u64::from(small),
        };
        Ok((size, header & 0x0f))
    }

    /// Refuses a collection of `size` elements of `per_element` values each that cannot fit in
    /// the bytes left (each value takes a byte at least in a well-formed file).
    fn claims(&self, size: u64, per_element: u64) -> Result<(), String> {
        if size.saturating_mul(per_element) > self.left() as u64 {
            return Err(format!(
                "a collection of {size} elements at byte {} with {} bytes left",
                self.at,
                self.left()
            ));
        }
        Ok(())
    }

    /// One value of compact type `kind` as a collection's element. A boolean takes no byte:
    /// parquet 60.1 skips it so, and the walk must stay where the Parquet crate's reading is.
    fn value(&mut self, kind: u8, depth: u32) -> Result<(), String> {
        match kind {
            1 | 2 => Ok(()),
            3 => self.skip(1),
            4..=6 => self.varint().map(drop),
            7 => self.skip(8),
            8 => {
                let length = self.varint()?;
                self.skip(length)
            }
            9 | 10 => {
                let (size, code) = self.list_header()?;
                self.elements(size, &[code], depth)
            }
            11 => {
                let size = self.varint()?;
                if size == 0 {
                    return Ok(());
                }
                let types = self.byte()?;
                self.elements(size, &[types >> 4, types & 0x0f], depth)
            }
            12 => self.schema_struct(&[], depth + 1),
            13 => self.skip(16),
            other => Err(format!("unknown type {other} at byte {}", self.at)),
        }
    }

    fn elements(&mut self, size: u64, kinds: &[u8], depth: u32) -> Result<(), String> {
        if depth > MAX_DEPTH {
            return Err(format!("nested over {MAX_DEPTH} deep"));
        }
        self.claims(size, kinds.len() as u64)?;
        for _ in 0..size {
            for &kind in kinds {
                self.value(kind, depth + 1)?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file_with_footer(metadata: &[u8]) -> Vec<u8> {
        let mut file = b"PAR1".to_vec();
        file.extend_from_slice(metadata);
        file.extend_from_slice(&(metadata.len() as u32).to_le_bytes());
        file.extend_from_slice(b"PAR1");
        file
    }

    #[test]
    fn a_list_claiming_more_elements_than_bytes_is_refused() {
        // Field 20 (not in the format, so skipped), a list of booleans claiming 2^31
        // elements; then the same list claiming one.
        let metadata = [0x09, 0x28, 0xf1, 0x80, 0x80, 0x80, 0x80, 0x08, 0x00];
        let why = check_footer(&file_with_footer(&metadata)).unwrap_err();
        assert!(why.contains("2147483648 elements"), "{why}");
        check_footer(&file_with_footer(&[0x09, 0x28, 0x11, 0x00])).unwrap();
        // A string longer than the footer; deep nesting.
        let why = check_footer(&file_with_footer(&[0x08, 0x28, 0x7f, b'a', 0x00])).unwrap_err();
        assert!(why.contains("127 bytes claimed"), "{why}");
        let deep = [vec![0x0c, 0x28], vec![0x1c; 40], vec![0x00; 41]].concat();
        assert!(
            check_footer(&file_with_footer(&deep))
                .unwrap_err()
                .contains("deep")
        );
    }

    #[test]
    fn a_known_field_of_another_wire_type_is_refused() {
        // FileMetaData's field 1 (version, an i32) as a list: the Parquet crate reads an i32
        // there, this walk a list, so they part ways.
        let why = check_footer(&file_with_footer(&[0x19, 0x15, 0x00])).unwrap_err();
        assert!(
            why.contains("field 1 at byte 1 has wire type 9, the format's is i32"),
            "{why}"
        );
        // A field id written in full is read as 16 bits: 65537 is field 1.
        let why = check_footer(&file_with_footer(&[0x09, 0x82, 0x80, 0x08, 0x15, 0x00]));
        assert!(why.unwrap_err().contains("field 1"));
    }

    #[test]
    fn a_label_table_the_lab_writes_passes() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("labels.parquet");
        let row = |i: u32| crate::labels::LabelRow {
            scenario_id: format!("scene-{}", i % 7),
            window_step: 10,
            a_id: i64::from(i),
            b_id: -1,
            sample: i % 4,
            psi: i as f32 * 0.37 - 3.0,
            e_marg: 11.5,
            e_cond: i as f32 * 0.01,
            psi_true: i.is_multiple_of(3).then_some(0.5),
            audience_size: 1,
        };
        let rows: Vec<_> = (0..5000).map(row).collect();
        crate::labels::write_label_table(&path, &rows).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        check_footer(&bytes).unwrap();
        let back = crate::labels::label_table_from_bytes(bytes, &path).unwrap();
        assert_eq!(back, rows);
    }

    #[test]
    fn a_page_claiming_more_than_snappy_can_expand_to_is_refused() {
        // Page headers: type 0, uncompressed (zigzag), compressed (zigzag), a data page
        // header (field 5, a struct with field 1 = 0), stop; then the page's bytes.
        let page = |uncompressed: u32, compressed: u8| {
            let mut header = vec![0x15, 0x00, 0x15];
            let mut v = u64::from(uncompressed) << 1;
            while v >= 0x80 {
                header.push((v as u8) | 0x80);
                v >>= 7;
            }
            header.push(v as u8);
            header.extend_from_slice(&[0x15, compressed << 1, 0x2c, 0x15, 0x00, 0x00, 0x00]);
            header.extend(std::iter::repeat_n(7u8, usize::from(compressed)));
            header
        };
        let fine = [page(100, 50), page(64 * 32, 60)].concat();
        check_pages(&fine).unwrap();
        let bomb = [page(100, 50), page(1 << 30, 10)].concat();
        let why = check_pages(&bomb).unwrap_err();
        assert!(why.contains("claims 1073741824 bytes from 10"), "{why}");
        // A header that does not parse within the chunk.
        let unknown_list = [0x09, 0x28, 0xf8, 0xff, 0xff, 0x07];
        assert!(check_pages(&unknown_list).unwrap_err().contains("elements"));
        // A dictionary page (type 2) of 16 bytes claiming 2^30 values; then one of 2 values.
        let dictionary = |values: u32| {
            let mut header = vec![0x15, 0x04, 0x15, 0x20, 0x15, 0x20, 0x4c, 0x15];
            let mut v = u64::from(values) << 1;
            while v >= 0x80 {
                header.push((v as u8) | 0x80);
                v >>= 7;
            }
            header.push(v as u8);
            header.extend_from_slice(&[0x00, 0x00]);
            header.extend([0u8; 16]);
            header
        };
        let why = check_pages(&dictionary(1 << 30)).unwrap_err();
        assert!(
            why.contains("claims 1073741824 values in 16 bytes"),
            "{why}"
        );
        check_pages(&dictionary(2)).unwrap();
    }
}
