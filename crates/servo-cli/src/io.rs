//! servo's files and logs: the [`servo_io`] crate, re-exported so that `crate::io::...` paths
//! keep working.

pub use servo_io::*;
