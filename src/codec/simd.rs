//! Which instruction set the codecs' hot loops run on: AVX2 where the CPU has it, the plain
//! build otherwise, or everywhere when `MOCAP_SCALAR=1` is set when the process starts (read
//! once, at the first hot loop or `serve`'s first log line, which names the build).
//!
//! The loops compiled twice ([`dispatch!`]: mdtt's synthesis, spca's pose combination,
//! lsdt-clip's synthesis) are element-wise, and Rust never fuses a multiply and an add, so
//! both builds give the same bits; AVX2 is only faster. The switch is there so that claim can
//! be tested (`tests/frozen.rs` and `tests/golden.rs` decode and encode both ways) and so a
//! user who suspects the vector path can rule it out without rebuilding.

use std::sync::OnceLock;

/// The environment variable that forces the plain build: any value but empty or `0`.
pub const ENV: &str = "MOCAP_SCALAR";

/// The build the hot loops run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Path {
    /// Compiled with AVX2 enabled (x86-64 CPUs that have it).
    Avx2,
    /// Compiled for the baseline target.
    Scalar,
}

impl Path {
    pub fn name(self) -> &'static str {
        match self {
            Path::Avx2 => "avx2",
            Path::Scalar => "scalar",
        }
    }
}

/// The path of this process, chosen once (the first call reads [`ENV`] and the CPU).
pub fn path() -> Path {
    static PATH: OnceLock<Path> = OnceLock::new();
    *PATH.get_or_init(|| {
        let forced = std::env::var_os(ENV).is_some_and(|v| !v.is_empty() && v != "0");
        #[cfg(target_arch = "x86_64")]
        if !forced && std::is_x86_feature_detected!("avx2") {
            return Path::Avx2;
        }
        let _ = forced;
        Path::Scalar
    })
}

/// Define `fn name(args) body` compiled twice, for the baseline and with AVX2 enabled, and
/// calling the build [`path`] chose. The body is written once and inlined into both.
///
/// For the loops it serves: no return value, no generics, each argument a plain `name: Type`
/// (a tuple pattern becomes one argument destructured in the body).
macro_rules! dispatch {
    ($(#[$meta:meta])* $vis:vis fn $name:ident($($arg:ident: $ty:ty),* $(,)?) $body:block) => {
        $(#[$meta])*
        $vis fn $name($($arg: $ty),*) {
            #[inline(always)]
            fn body($($arg: $ty),*) $body
            #[cfg(target_arch = "x86_64")]
            #[target_feature(enable = "avx2")]
            fn avx2($($arg: $ty),*) {
                body($($arg),*)
            }
            #[cfg(target_arch = "x86_64")]
            if $crate::codec::simd::path() == $crate::codec::simd::Path::Avx2 {
                // SAFETY: `path()` is `Avx2` only on a CPU that has AVX2.
                return unsafe { avx2($($arg),*) };
            }
            body($($arg),*)
        }
    };
}
pub(crate) use dispatch;

#[cfg(test)]
mod tests {
    dispatch! {
        /// A loop of the kind dispatched: element-wise multiply-adds.
        fn axpy(a: f32, x: &[f32], y: &mut [f32]) {
            for (y, x) in y.iter_mut().zip(x) {
                *y += a * x;
            }
        }
    }

    /// The dispatched build (AVX2 here, where the CPU has it) against the loop written out.
    #[test]
    fn both_builds_give_the_same_bits() {
        if super::path() != super::Path::Avx2 {
            println!("not compared: this CPU runs the plain build only");
        }
        let x: Vec<f32> = (0..1000).map(|i| (i as f32 * 0.37).sin() * 1e3).collect();
        let mut y: Vec<f32> = (0..1000).map(|i| (i as f32 * 0.11).cos()).collect();
        let mut plain = y.clone();
        axpy(0.3, &x, &mut y);
        for (p, x) in plain.iter_mut().zip(&x) {
            *p += 0.3 * x;
        }
        assert_eq!(
            y.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            plain.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
    }
}
