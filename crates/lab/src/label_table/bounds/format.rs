//! The Thrift structures of a Parquet footer and page header, as the Parquet format
//! (`parquet.thrift`) defines them: field ids and types, enums as i32, unions as structs.

/// A field's type.
#[derive(Clone, Copy, Debug)]
pub(super) enum Ty {
    Bool,
    Byte,
    I16,
    I32,
    I64,
    Double,
    Binary,
    List(&'static Ty),
    Struct(&'static [(i16, Ty)]),
}

impl Ty {
    /// The type's name, for a message.
    pub(super) fn name(self) -> &'static str {
        match self {
            Ty::Bool => "bool",
            Ty::Byte => "byte",
            Ty::I16 => "i16",
            Ty::I32 => "i32",
            Ty::I64 => "i64",
            Ty::Double => "double",
            Ty::Binary => "binary",
            Ty::List(_) => "list",
            Ty::Struct(_) => "struct",
        }
    }

    /// Whether compact-protocol type code `code` is this type's.
    pub(super) fn is_code(self, code: u8) -> bool {
        match self {
            Ty::Bool => code == 1 || code == 2,
            Ty::Byte => code == 3,
            Ty::I16 => code == 4,
            Ty::I32 => code == 5,
            Ty::I64 => code == 6,
            Ty::Double => code == 7,
            Ty::Binary => code == 8,
            Ty::List(_) => code == 9,
            Ty::Struct(_) => code == 12,
        }
    }
}

use Ty::{Binary, Bool, Byte, Double, I16, I32, I64, List, Struct};

const EMPTY: Ty = Struct(&[]);
const STRING_LIST: Ty = List(&Binary);

pub(super) const FILE_METADATA: &[(i16, Ty)] = &[
    (1, I32),
    (2, List(&Struct(SCHEMA_ELEMENT))),
    (3, I64),
    (4, List(&Struct(ROW_GROUP))),
    (5, List(&Struct(KEY_VALUE))),
    (6, Binary),
    (7, List(&Struct(&[(1, EMPTY)]))),
    (8, Struct(ENCRYPTION_ALGORITHM)),
    (9, Binary),
];

const SCHEMA_ELEMENT: &[(i16, Ty)] = &[
    (1, I32),
    (2, I32),
    (3, I32),
    (4, Binary),
    (5, I32),
    (6, I32),
    (7, I32),
    (8, I32),
    (9, I32),
    (10, Struct(LOGICAL_TYPE)),
];

const TIME_UNIT: Ty = Struct(&[(1, EMPTY), (2, EMPTY), (3, EMPTY)]);

const LOGICAL_TYPE: &[(i16, Ty)] = &[
    (1, EMPTY),
    (2, EMPTY),
    (3, EMPTY),
    (4, EMPTY),
    (5, Struct(&[(1, I32), (2, I32)])),
    (6, EMPTY),
    (7, Struct(&[(1, Bool), (2, TIME_UNIT)])),
    (8, Struct(&[(1, Bool), (2, TIME_UNIT)])),
    (10, Struct(&[(1, Byte), (2, Bool)])),
    (11, EMPTY),
    (12, EMPTY),
    (13, EMPTY),
    (14, EMPTY),
    (15, EMPTY),
    (16, Struct(&[(1, Byte)])),
    (17, Struct(&[(1, Binary)])),
    (18, Struct(&[(1, Binary), (2, I32)])),
];

const ROW_GROUP: &[(i16, Ty)] = &[
    (1, List(&Struct(COLUMN_CHUNK))),
    (2, I64),
    (3, I64),
    (4, List(&Struct(&[(1, I32), (2, Bool), (3, Bool)]))),
    (5, I64),
    (6, I64),
    (7, I16),
];

const COLUMN_CHUNK: &[(i16, Ty)] = &[
    (1, Binary),
    (2, I64),
    (3, Struct(COLUMN_METADATA)),
    (4, I64),
    (5, I32),
    (6, I64),
    (7, I32),
    (
        8,
        Struct(&[(1, EMPTY), (2, Struct(&[(1, STRING_LIST), (2, Binary)]))]),
    ),
    (9, Binary),
];

const COLUMN_METADATA: &[(i16, Ty)] = &[
    (1, I32),
    (2, List(&I32)),
    (3, STRING_LIST),
    (4, I32),
    (5, I64),
    (6, I64),
    (7, I64),
    (8, List(&Struct(KEY_VALUE))),
    (9, I64),
    (10, I64),
    (11, I64),
    (12, Struct(STATISTICS)),
    (13, List(&Struct(&[(1, I32), (2, I32), (3, I32)]))),
    (14, I64),
    (15, I32),
    (16, Struct(&[(1, I64), (2, List(&I64)), (3, List(&I64))])),
    (
        17,
        Struct(&[
            (
                1,
                Struct(&[
                    (1, Double),
                    (2, Double),
                    (3, Double),
                    (4, Double),
                    (5, Double),
                    (6, Double),
                    (7, Double),
                    (8, Double),
                ]),
            ),
            (2, List(&I32)),
        ]),
    ),
];

const STATISTICS: &[(i16, Ty)] = &[
    (1, Binary),
    (2, Binary),
    (3, I64),
    (4, I64),
    (5, Binary),
    (6, Binary),
    (7, Bool),
    (8, Bool),
];

const KEY_VALUE: &[(i16, Ty)] = &[(1, Binary), (2, Binary)];

const AES_GCM: Ty = Struct(&[(1, Binary), (2, Binary), (3, Bool)]);

const ENCRYPTION_ALGORITHM: &[(i16, Ty)] = &[(1, AES_GCM), (2, AES_GCM)];

pub(super) const PAGE_HEADER: &[(i16, Ty)] = &[
    (1, I32),
    (2, I32),
    (3, I32),
    (4, I32),
    (
        5,
        Struct(&[
            (1, I32),
            (2, I32),
            (3, I32),
            (4, I32),
            (5, Struct(STATISTICS)),
        ]),
    ),
    (6, EMPTY),
    (7, Struct(&[(1, I32), (2, I32), (3, Bool)])),
    (
        8,
        Struct(&[
            (1, I32),
            (2, I32),
            (3, I32),
            (4, I32),
            (5, I32),
            (6, I32),
            (7, Bool),
            (8, Struct(STATISTICS)),
        ]),
    ),
];
