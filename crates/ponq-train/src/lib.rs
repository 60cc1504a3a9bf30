//! # ponq-train
//!
//! The command-line programs that evaluate (and, with the issue "ponq-model + ponq-train",
//! train and run) PoNQ. Training is not implemented yet: this crate holds `ponq-eval` for now.
