//! # ponq-train
//!
//! Training loop, losses and the training command-line programs. Not implemented yet (see the
//! issue "ponq-model + ponq-train").
