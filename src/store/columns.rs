//! Typed columns: `JobStatus` and `JobKind` are stored as their lowercase names (TEXT with a
//! CHECK constraint on both backends) and decoded into the enums, so a row holds a status and a
//! kind, never a free string.

use super::{JobKind, JobStatus};
use sqlx::encode::IsNull;
use sqlx::error::BoxDynError;
use sqlx::{Database, Decode, Encode, Type};

/// The column impls of an enum with `as_str` and `FromStr`, for every backend whose `str` is TEXT.
macro_rules! text_column {
    ($ty:ty) => {
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
                Ok(text.parse::<$ty>()?)
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

text_column!(JobStatus);
text_column!(JobKind);
