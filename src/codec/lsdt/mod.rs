//! LSDT — Hou, Chau, Magnenat-Thalmann, He, "Low-latency compression of mocap data using
//! learned spatial decorrelation transform" (CAGD 2016). The learned transform is trained
//! here; the `lsdt-clip` and `lsdt-frame` codecs that use it come with the shared-basis work.
//!
//! # Layout
//! - [`train`]: Algorithm 1, the sparsity-constrained orthogonal transform per coordinate.

pub mod train;
