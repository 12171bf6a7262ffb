//! `pga`: principal geodesic analysis of joint rotations with IK reconstruction (Tournier,
//! Wu, Courty, Arnaud, Reveret: *Motion Compression using Principal Geodesics Analysis*,
//! CGF 28(2), 2009).
//!
//! The pieces, pure math each: [`model`] (the Karcher mean of poses and their principal
//! geodesics), [`lifting`] (the multiscale lifting of root and end-point trajectories) and
//! [`ik`] (Levenberg–Marquardt in geodesic coordinates to reach the decoded end points).

pub mod chunk;
pub mod frames;
pub mod ik;
pub mod layout;
pub mod lifting;
pub mod model;
