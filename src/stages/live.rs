//! LIVE
