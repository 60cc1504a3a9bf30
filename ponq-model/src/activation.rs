//! The network's activation: LeakyReLU with one slope everywhere, shared by the stock layers
//! ([`crate::model`]) and the fast CPU kernels ([`crate::fast`]).

/// Slope of every LeakyReLU of the network.
pub const LEAKY_SLOPE: f64 = 0.01;
