//! Peer methods measured in the same harness as the sparse VAL method (DESIGN §6).

pub mod brute;
pub mod lpv;
