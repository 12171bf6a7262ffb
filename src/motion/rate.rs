//! Frame rates as files state them, and which frames a span of seconds holds.
//!
//! A rate read from a frame time printed with rounding is not the rate the take was
//! recorded at: BVH's `Frame Time: 0.0333333` is 30.00003 fps, CMU's `0.0083333` is
//! 120.00048. Reckoned at the printed rate, frame 30 of a "30 fps" take lies at 0.999999 s
//! and a second from 0 holds 31 frames. Times are reckoned at the [`nominal`] rate instead:
//! the whole rate such a rate was written for. Real rates that are not whole (29.97, 59.94)
//! are 1e-3 off a whole one and stay as they are.

/// How near (relative) a rate must lie to a whole one to be that rate printed with
/// rounding: a frame time printed to 6 or 7 significant digits is 1e-6 to 1e-5 off, NTSC's
/// 29.97 is 1e-3 off 30 (the same tolerance resampling's grid snaps with).
const PRINTED: f64 = 1e-4;

/// The rate `fps` was written for: the nearest whole rate within [`PRINTED`], else `fps`.
pub fn nominal(fps: f64) -> f64 {
    let whole = fps.round();
    if whole >= 1.0 && (fps - whole).abs() <= PRINTED * fps {
        whole
    } else {
        fps
    }
}

/// The first frame at `fps` whose time `f / nominal(fps)` is at or after `t` seconds, as a
/// float (the caller checks it against the take's frames before using it as an index).
/// A time reckoned at either rate lands on the same frame: `t` within the two rates'
/// difference of frame `f`'s time (and 1e-9) counts as at it, so frame 100's time at a
/// printed 59.9988 fps is frame 100, not 101.
pub fn first_frame_from(t: f64, fps: f64) -> f64 {
    (t * nominal(fps) - slack(t, fps)).ceil().max(0.0)
}

/// How far (in frames at the nominal rate) a time `t` reckoned at the printed rate `fps`
/// can lie from the same frame reckoned at the nominal one, with room for rounding; never
/// more than [`MAX_SLACK`] of a frame, so a time between frames stays between them. (Far
/// enough into a take the two reckonings part by more: 8,000 frames in at a printed
/// 59.9988 fps, 160,000 at BVH's 30.00003.)
pub fn slack(t: f64, fps: f64) -> f64 {
    let f = (t * nominal(fps)).abs();
    (1.5 * (fps / nominal(fps) - 1.0).abs() * f + 1e-9 * f.max(1.0)).min(MAX_SLACK)
}

/// The most of a frame [`slack`] allows.
pub const MAX_SLACK: f64 = 0.25;

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn printed_rates_are_the_rates_they_were_written_for() {
        assert_eq!(nominal(1.0 / 0.0333333), 30.0);
        assert_eq!(nominal(1.0 / 0.0083333), 120.0);
        assert_eq!(nominal(1.0 / 0.008333), 120.0);
        assert_eq!(nominal(1.0 / 0.041667), 24.0);
        assert_eq!(nominal(29.97), 29.97);
        assert_eq!(nominal(59.94), 59.94);
        assert_eq!(nominal(0.5), 0.5);
    }

    /// A rate as a file prints it: the frame time of a whole or NTSC rate, printed with
    /// 4 to 8 decimals.
    fn printed_rate() -> impl Strategy<Value = f64> {
        let rates = prop_oneof![
            (1u32..=2000).prop_map(f64::from),
            Just(30000.0 / 1001.0),
            Just(60000.0 / 1001.0),
            Just(24000.0 / 1001.0),
        ];
        (rates, 4i32..=8).prop_map(|(fps, digits)| {
            let scale = 10f64.powi(digits);
            let printed = ((1.0 / fps) * scale).round() / scale;
            if printed > 0.0 {
                1.0 / printed
            } else {
                fps
            }
        })
    }

    proptest! {
        /// `[t0, t1)` holds exactly the frames whose time at the nominal rate lies in it,
        /// for times on frames (as a caller reckons them from a rate) and between them.
        #[test]
        fn a_span_holds_the_frames_whose_times_lie_in_it(
            fps in printed_rate(),
            a in 0u32..100_000,
            len in 1u32..100_000,
            between in prop::bool::ANY,
            at_printed in prop::bool::ANY,
        ) {
            // Times reckoned at the nominal rate, or at the printed one (as a take's
            // record, its headers and its CSV columns give them).
            // At the printed rate only where the two reckonings lie within the slack, and,
            // for a time between frames, where the slack cannot reach back to the frame
            // before it (the time lands `shift - drift` after it; the slack is 1.5 drift):
            // past that, which frame a time reckoned at the printed rate means is not told.
            let drift = (fps / nominal(fps) - 1.0).abs() * f64::from(a + len);
            let shift = if between { 0.37 } else { 0.0 };
            let told = 1.5 * drift < MAX_SLACK && (!between || 2.5 * drift < shift);
            let rate = if at_printed && told { fps } else { nominal(fps) };
            let t0 = (f64::from(a) + shift) / rate;
            let t1 = (f64::from(a + len) + shift) / rate;
            let (f0, f1) = (first_frame_from(t0, fps), first_frame_from(t1, fps));
            let want0 = f64::from(a) + if between { 1.0 } else { 0.0 };
            prop_assert_eq!(f0, want0);
            prop_assert_eq!(f1 - f0, f64::from(len));
        }
    }

    #[test]
    fn a_second_of_a_printed_thirty_fps_take_is_thirty_frames() {
        let fps = 1.0 / 0.0333333;
        assert_eq!(
            first_frame_from(1.0, fps) - first_frame_from(0.0, fps),
            30.0
        );
        assert_eq!(first_frame_from(10.0, 1.0 / 0.0083333), 1200.0);
        // NTSC stays NTSC: one second of 29.97 fps holds frames 0..=29.
        assert_eq!(first_frame_from(1.0, 30000.0 / 1001.0), 30.0);
        // Frame 100's time at a printed 59.9988 fps (0.016667 s) is frame 100.
        let fps = 1.0 / 0.016667;
        assert_eq!(first_frame_from(100.0 / fps, fps), 100.0);
        assert_eq!(first_frame_from(5_000.0 / fps, fps), 5_000.0);
    }
}
