//! # ponq-model
//!
//! The PoNQ network (3D CNN encoder + five decoders) on Burn. Not implemented yet (see the
//! issue "ponq-model + ponq-train").
