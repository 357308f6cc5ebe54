//! Contact mechanics of Sec 2.2.4: JKR (Eq 5).

pub mod jkr;
