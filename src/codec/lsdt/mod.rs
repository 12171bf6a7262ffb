//! LSDT — Hou, Chau, Magnenat-Thalmann, He, "Low-latency compression of mocap data using
//! learned spatial decorrelation transform" (CAGD 2016): a spatial transform learned once
//! for a library (a shared [`crate::codec::Basis`] of kind `lsdt`) and two low-latency codecs
//! that use it.
//!
//! # Layout
//! - [`train`]: Algorithm 1, the sparsity-constrained orthogonal transform per coordinate.
//! - [`spatial`]: applying the learned transform to frames (forward and inverse).
//! - [`clip`]: `lsdt-clip`, DCT over an `L`-frame clip then the learned transform.
//! - [`frame`]: `lsdt-frame`, closed-loop prediction then the learned transform, with
//!   periodic intra frames and a frame-at-a-time encoder for live streams.

pub mod clip;
pub mod frame;
pub mod spatial;
pub mod train;
