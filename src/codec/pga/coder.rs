//! One chunk's coding, written once for both directions: its step index, its trajectories
//! through the lifting ([`chunk`]) and the frames they decode to ([`frames`]) — what the
//! encoder's trials measure is exactly what the decoder gives.

use super::chunk::{self, Steps, Trajectories};
use super::frames::{self, Solve};
use super::layout::Layout;
use super::lifting::coarsest_stride;
use super::params::Params;
use super::scale::{alpha, Scale};
use crate::codec::branches::{self, Turning};
use crate::codec::entropy::io::Io;
use crate::codec::error::Result;
use crate::codec::skeleton::printed;
use crate::codec::twists::{self, Around};

/// What codes and decodes chunks: the layout, the parameters, and what follows from them.
pub struct Coder {
    pub layout: Layout,
    pub params: Params,
    scale: Scale,
    solve: Solve,
    /// The encoder's dead zone ([`Steps::dead_zone`]); 0 when decoding.
    dead_zone: f64,
    /// The joints whose Euler branches a chunk of version 3 on carries.
    turnings: Vec<Turning>,
}

impl Coder {
    pub fn new(layout: &Layout, params: Params) -> Coder {
        let scale = Scale::new(
            layout.chain(),
            &params.model,
            super::scale::lever_floor(params.version),
        );
        let solve = Solve {
            lambda: scale.weights(params.lambda),
            iterations: usize::from(params.iterations),
        };
        Coder {
            turnings: layout.turnings(),
            layout: layout.clone(),
            params,
            scale,
            solve,
            dead_zone: 0.0,
        }
    }

    /// The same, encoding with a dead zone.
    pub fn with_dead_zone(self, dead_zone: f64) -> Coder {
        Coder { dead_zone, ..self }
    }

    /// One chunk of `frames` frames at step index `s`, twisting near lock or not (version
    /// 4; both when encoding, read when decoding) through `io`: its decoded channel values,
    /// rounded as printed. The encoder gives the chunk's trajectories and its source channel
    /// values (for their Euler branches and twists).
    pub fn code<I: Io>(
        &self,
        io: &mut I,
        s: u32,
        twists: bool,
        frames: usize,
        given: Option<(&Trajectories, Around)>,
    ) -> Result<Vec<f64>> {
        let s = io.raw(s, 8);
        let twists = self.params.version >= 4 && io.raw(u32::from(twists), 1) == 1;
        let steps = Steps {
            dead_zone: self.dead_zone,
            ..self
                .scale
                .steps(alpha(self.params.base, s), self.params.rho)
        };
        let ends = if self.params.iterations == 0 {
            0
        } else {
            self.layout.chain().ends().len()
        };
        let stride = coarsest_stride(frames, 1 << self.params.stride_log2);
        let g = &self.params.model;
        let t = chunk::code(
            io,
            frames,
            ends,
            g.dims(),
            stride,
            &steps,
            given.map(|g| g.0),
        )?;
        let cc = self.layout.channels();
        let mut out = Vec::with_capacity(frames * cc);
        frames::channels(&self.layout, g, &t, &self.solve, &mut out);
        for v in &mut out {
            *v = printed(*v);
        }
        if twists {
            twists::code_frames(io, &self.turnings, cc, given.map(|g| g.1), &mut out)?;
        }
        if self.params.version >= 3 {
            branches::code(io, &self.turnings, cc, given.map(|g| g.1.chunk()), &mut out)?;
        }
        Ok(out)
    }
}
