//! Typed columns: `JobStatus`, `JobKind` and `FailureCode` are stored as their names (TEXT; a
//! CHECK constraint on both backends for the first two) and decoded into the enums, so a row
//! holds a status, a kind and a failure code, never a free string.

use super::{FailureCode, JobKind, JobStatus};
use sqlx::encode::IsNull;
use sqlx::error::BoxDynError;
use sqlx::{Database, Decode, Encode, Type};

/// A name that is not one of an enum's stored names.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown {what} {name:?}")]
pub struct UnknownName {
    /// What the name should have named (`status`, `job kind`).
    pub what: &'static str,
    pub name: String,
}

/// Display and FromStr by the names of an enum with `ALL` and `as_str`.
macro_rules! named {
    ($ty:ty, $what:literal) => {
        impl std::fmt::Display for $ty {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(self.as_str())
            }
        }

        impl std::str::FromStr for $ty {
            type Err = UnknownName;
            fn from_str(s: &str) -> Result<Self, UnknownName> {
                <$ty>::ALL
                    .iter()
                    .copied()
                    .find(|v| v.as_str() == s)
                    .ok_or_else(|| UnknownName {
                        what: $what,
                        name: s.to_string(),
                    })
            }
        }
    };
}

/// The column impls of an enum with `as_str`, for every backend whose `str` is TEXT; `$parse`
/// turns the stored text back into the enum.
macro_rules! text_column {
    ($ty:ty, $parse:expr) => {
        impl<DB: Database> Type<DB> for $ty
        where
            str: Type<DB>,
        {
            fn type_info() -> DB::TypeInfo {
                <str as Type<DB>>::type_info()
            }

            fn compatible(ty: &DB::TypeInfo) -> bool {
                <str as Type<DB>>::compatible(ty)
            }
        }

        impl<'r, DB: Database> Decode<'r, DB> for $ty
        where
            &'r str: Decode<'r, DB>,
        {
            fn decode(value: DB::ValueRef<'r>) -> Result<Self, BoxDynError> {
                let text = <&'r str as Decode<'r, DB>>::decode(value)?;
                let parse: fn(&str) -> Result<$ty, BoxDynError> = $parse;
                parse(text)
            }
        }

        // Encoded as an owned `String`: a borrowed `&'static str` would tie the query's
        // lifetime to `'static` on drivers whose `&str` encodes by reference.
        impl<'q, DB: Database> Encode<'q, DB> for $ty
        where
            String: Encode<'q, DB>,
        {
            fn encode_by_ref(
                &self,
                buf: &mut <DB as Database>::ArgumentBuffer,
            ) -> Result<IsNull, BoxDynError> {
                <String as Encode<'q, DB>>::encode(self.as_str().to_string(), buf)
            }
        }
    };
}

named!(JobStatus, "status");
named!(JobKind, "job kind");
text_column!(JobStatus, |s| Ok(s.parse::<JobStatus>()?));
text_column!(JobKind, |s| Ok(s.parse::<JobKind>()?));
// Leniently: a code an older version stored reads as what it means now.
text_column!(FailureCode, |s| Ok(FailureCode::from_stored(s)));
