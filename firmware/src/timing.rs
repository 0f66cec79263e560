//! The ECU's timing facts, each written once: the core clock and the two tasks'
//! periods. A leaf module (it imports nothing) that the library's tasks, the
//! deadline monitor, the friction check, the RTIC application and the simulator
//! all read.

/// Core clock of the ECU (the STM32F405 at its rated 168 MHz), Hz.
pub const ECU_CLOCK_HZ: u32 = 168_000_000;
/// Period (= deadline) of the `control` task, µs.
pub const CONTROL_PERIOD_US: u64 = 10_000;
/// Period (= deadline) of the `plan` task, µs.
pub const PLAN_PERIOD_US: u64 = 100_000;
/// Tick of the ECU application's monotonic (its SysTick interrupt's period), µs:
/// the control period, of which every release is a whole multiple, so that the
/// tick interrupts the tasks as rarely as the releases allow (the response times
/// are read from the core clock, not from the tick).
pub const MONO_TICK_US: u64 = CONTROL_PERIOD_US;

const _: () = assert!(
    CONTROL_PERIOD_US.is_multiple_of(MONO_TICK_US) && PLAN_PERIOD_US.is_multiple_of(MONO_TICK_US),
    "every release must fall on a monotonic tick"
);

/// Core clock ticks per µs (168): the ECU's clock is a whole number of MHz, so a
/// tick count becomes µs by one small division.
pub const TICKS_PER_US: u32 = ECU_CLOCK_HZ / 1_000_000;

const _: () = assert!(
    ECU_CLOCK_HZ.is_multiple_of(1_000_000),
    "the core clock must be a whole number of MHz"
);
const _: () = assert!(
    MONO_TICK_US < 1 << 16,
    "the monotonic tick must be below 2^16 µs for `div_u64_small`"
);

/// `n / d` (rounded down) for a divisor below 2¹⁶ (dimensionless; the caller's
/// units), by three 32-bit divisions (the M4F's `UDIV`) instead of the library's
/// 64-bit division, whose long path (a dividend past 2³², 25.6 s of core ticks)
/// is a loop. Branch-free, loop-free: the same cost for every `n`.
///
/// Each step divides a remainder below `d` shifted by 16 bits plus the next 16
/// bits of `n`, which fits a `u32` because `d < 2¹⁶`. `d = 0` or `d ≥ 2¹⁶` gives
/// `None`.
#[inline]
pub fn div_u64_small(n: u64, d: u32) -> Option<u64> {
    if d == 0 || d >= 1 << 16 {
        return None;
    }
    let hi = (n >> 32) as u32;
    let lo = n as u32;
    let (q_hi, r) = (hi / d, hi % d);
    let mid = (r << 16) | (lo >> 16);
    let (q_mid, r) = (mid / d, mid % d);
    let low = (r << 16) | (lo & 0xffff);
    let q_lo = low / d;
    Some(((q_hi as u64) << 32) | ((q_mid as u64) << 16) | q_lo as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn div_u64_small_is_the_64_bit_division() {
        let ds = [1u32, 2, 3, 7, 168, 10_000, 65_521, 65_535];
        let mut n: u64 = 0x9E37_79B9_7F4A_7C15;
        let edges = [
            0u64,
            1,
            u32::MAX as u64,
            1 << 32,
            (1 << 32) + 1,
            u64::MAX,
            u64::MAX - 1,
        ];
        for &d in &ds {
            for &e in &edges {
                assert_eq!(div_u64_small(e, d), Some(e / d as u64), "{e} / {d}");
            }
            for _ in 0..10_000 {
                // xorshift64: dividends over the whole range.
                n ^= n << 13;
                n ^= n >> 7;
                n ^= n << 17;
                assert_eq!(div_u64_small(n, d), Some(n / d as u64), "{n} / {d}");
                let small = n >> 40;
                assert_eq!(div_u64_small(small, d), Some(small / d as u64));
            }
        }
    }

    #[test]
    fn div_u64_small_refuses_a_zero_or_wide_divisor() {
        assert_eq!(div_u64_small(5, 0), None);
        assert_eq!(div_u64_small(5, 1 << 16), None);
        assert_eq!(div_u64_small(5, u32::MAX), None);
    }
}
