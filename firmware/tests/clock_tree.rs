//! The clock set-up's register sequence (`firmware::clock_tree`) against a
//! register-level model of the STM32F405's RCC, PWR and flash interface: ready
//! bits that come after some polls or never, a switch status that does not
//! follow, a flash latency that does not take, and the rules of RM0090 the model
//! checks at each access (no PLL reconfigured while on, no clock above what the
//! flash latency, the voltage scale or a bus allows, reserved bits kept). The
//! writes are checked step by step against values written out from RM0090's
//! field tables, not computed by the code under test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use firmware::clock_tree::{
    self, configure, configure_with, ClockError, ClockRegisters, ClockSource, PllConfig,
    PollLimits, Register, FLASH_LATENCY_WS, HSE_HZ, HSI_HZ, PLL, POLL_LIMITS, SYSCLK_HZ,
};
use Register::*;

/// The model's crystal, Hz (the Netduino Plus 2's).
const CRYSTAL_HZ: u64 = 25_000_000;
/// `RCC_CR` from reset: HSION, HSIRDY, HSITRIM 16, a factory HSICAL of 0x78.
const CR_RESET: u32 = 0x0000_7883;
/// `RCC_PLLCFGR` from reset (RM0090: 0x2400_3010; bit 29 is reserved, set).
const PLLCFGR_RESET: u32 = 0x2400_3010;
/// `PWR_CR` from reset on the STM32F405 (VOS = 1: scale 1).
const PWR_CR_RESET: u32 = 0x0000_4000;

/// One access, and how many times in a row it happened (polls merge).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Access {
    Read(Register, u32),
    Write(Register, u32),
}

/// When a ready bit comes: after this many polls of its register once it can
/// (`None`: never).
type Ready = Option<u32>;

/// The STM32F405's clock registers as RM0090 describes them, with ready bits
/// that come when the test says.
struct Stm32f405 {
    cr: u32,
    pllcfgr: u32,
    cfgr: u32,
    apb1enr: u32,
    pwr_cr: u32,
    pwr_csr: u32,
    acr: u32,
    vos_ready: Ready,
    hse_ready: Ready,
    pll_ready: Ready,
    switch_follows: Ready,
    latency_takes: bool,
    /// Polls of the register since the event that starts each wait.
    vos_polls: Option<u32>,
    hse_polls: Option<u32>,
    pll_polls: Option<u32>,
    switch_polls: Option<u32>,
    log: Vec<(Access, u64)>,
    violations: Vec<String>,
}

impl Stm32f405 {
    /// From reset, every ready bit after `after` polls.
    fn from_reset(after: u32) -> Self {
        Self {
            cr: CR_RESET,
            pllcfgr: PLLCFGR_RESET,
            cfgr: 0,
            apb1enr: 0,
            pwr_cr: PWR_CR_RESET,
            pwr_csr: 0,
            acr: 0,
            vos_ready: Some(after),
            hse_ready: Some(after),
            pll_ready: Some(after),
            switch_follows: Some(after),
            latency_takes: true,
            vos_polls: None,
            hse_polls: None,
            pll_polls: None,
            switch_polls: None,
            log: Vec::new(),
            violations: Vec::new(),
        }
    }

    fn record(&mut self, a: Access) {
        match self.log.last_mut() {
            Some((last, n)) if *last == a => *n += 1,
            _ => self.log.push((a, 1)),
        }
    }

    fn writes(&self) -> Vec<(Register, u32)> {
        self.log
            .iter()
            .filter_map(|(a, _)| match *a {
                Access::Write(r, v) => Some((r, v)),
                Access::Read(..) => None,
            })
            .collect()
    }

    /// Reads of `r` in all.
    fn reads_of(&self, r: Register) -> u64 {
        self.log
            .iter()
            .filter(|(a, _)| matches!(a, Access::Read(x, _) if *x == r))
            .map(|(_, n)| n)
            .sum()
    }

    /// Index in the log of the first write of `r` whose value satisfies `f`.
    fn first_write(&self, r: Register, f: impl Fn(u32) -> bool) -> Option<usize> {
        self.log
            .iter()
            .position(|(a, _)| matches!(*a, Access::Write(x, v) if x == r && f(v)))
    }

    fn pwr_clocked(&self) -> bool {
        self.apb1enr & (1 << 28) != 0
    }

    /// The PLL's output for the current `RCC_PLLCFGR`, Hz (`None`: not from the HSE,
    /// or factors out of range).
    fn pll_hz(&self) -> Option<u64> {
        let m = u64::from(self.pllcfgr & 0x3F);
        let n = u64::from((self.pllcfgr >> 6) & 0x1FF);
        let p = 2 * (u64::from((self.pllcfgr >> 16) & 0x3) + 1);
        let from_hse = self.pllcfgr & (1 << 22) != 0;
        (from_hse && (2..=63).contains(&m) && (50..=432).contains(&n))
            .then(|| CRYSTAL_HZ / m * n / p)
    }

    /// HCLK with the clock `sws` (the `SWS` field) selected, Hz.
    fn hclk(&self, sws: u32) -> u64 {
        let sysclk = match sws {
            0 => u64::from(HSI_HZ),
            1 => CRYSTAL_HZ,
            _ => self.pll_hz().unwrap_or(0),
        };
        let hpre = (self.cfgr >> 4) & 0xF;
        let div = if hpre < 8 { 1 } else { 2u64 << (hpre - 8) };
        sysclk / div
    }

    /// RM0090's limits for the clocks now in use.
    fn check_clocks(&mut self, when: &str) {
        let sws = (self.cfgr >> 2) & 0x3;
        let hclk = self.hclk(sws);
        let apb = |bits: u32| -> u64 {
            if bits < 4 {
                1
            } else {
                2 << (bits - 4)
            }
        };
        let pclk1 = hclk / apb((self.cfgr >> 10) & 0x7);
        let pclk2 = hclk / apb((self.cfgr >> 13) & 0x7);
        // RM0090 table 10, 2.7–3.6 V: 30 MHz per wait state.
        let latency = u64::from(self.acr & 0x7);
        if hclk > 30_000_000 * (latency + 1) {
            self.violations.push(format!(
                "{when}: HCLK {hclk} Hz with {latency} flash wait states"
            ));
        }
        if hclk > 168_000_000 {
            self.violations.push(format!("{when}: HCLK {hclk} Hz"));
        }
        if hclk > 144_000_000 && self.pwr_cr & (1 << 14) == 0 {
            self.violations
                .push(format!("{when}: HCLK {hclk} Hz in voltage scale 2"));
        }
        if pclk1 > 42_000_000 || pclk2 > 84_000_000 {
            self.violations
                .push(format!("{when}: APB1 {pclk1} Hz, APB2 {pclk2} Hz"));
        }
    }

    fn read_cr(&mut self) -> u32 {
        let mut cr = self.cr;
        if let Some(p) = self.hse_polls.as_mut() {
            *p += 1;
            if self.hse_ready.is_some_and(|n| *p > n) {
                cr |= 1 << 17;
            }
        }
        let hse_ready = cr & (1 << 17) != 0;
        if let Some(p) = self.pll_polls.as_mut() {
            // The PLL locks only on a running source.
            if hse_ready {
                *p += 1;
                if self.pll_ready.is_some_and(|n| *p > n) && self.pll_hz().is_some() {
                    cr |= 1 << 25;
                }
            }
        }
        self.cr = cr;
        cr
    }

    fn write_cr(&mut self, v: u32) {
        let old = self.cr;
        let sws = (self.cfgr >> 2) & 0x3;
        let mut new = (old & !0x010D_00F9) | (v & 0x010D_00F9);
        if old & (1 << 16) != 0 && v & (1 << 18) != old & (1 << 18) {
            self.violations
                .push("HSEBYP changed with the HSE on".into());
            new = (new & !(1 << 18)) | (old & (1 << 18));
        }
        if v & (1 << 24) == 0 && old & (1 << 24) != 0 && sws == 2 {
            self.violations
                .push("PLL turned off while it clocks the core".into());
            new |= 1 << 24;
        }
        if v & (1 << 16) == 0 && old & (1 << 16) != 0 && (sws == 1 || sws == 2) {
            self.violations
                .push("HSE turned off while it clocks the core".into());
            new |= 1 << 16;
        }
        if v & (1 << 0) == 0 && sws == 0 {
            self.violations
                .push("HSI turned off while it clocks the core".into());
            new |= 1;
        }
        // Ready bits follow their enables.
        if new & (1 << 16) == 0 {
            new &= !(1 << 17);
            self.hse_polls = None;
        } else if old & (1 << 16) == 0 {
            self.hse_polls = Some(0);
        }
        if new & (1 << 24) == 0 {
            new &= !(1 << 25);
            self.pll_polls = None;
        } else if old & (1 << 24) == 0 {
            self.pll_polls = Some(0);
        }
        self.cr = new;
    }

    fn read_cfgr(&mut self) -> u32 {
        let want = self.cfgr & 0x3;
        let now = (self.cfgr >> 2) & 0x3;
        if want != now {
            if let Some(p) = self.switch_polls.as_mut() {
                *p += 1;
                let ready = match want {
                    0 => self.cr & (1 << 1) != 0,
                    1 => self.cr & (1 << 17) != 0,
                    _ => self.cr & (1 << 25) != 0,
                };
                if ready && self.switch_follows.is_some_and(|n| *p > n) {
                    self.cfgr = (self.cfgr & !0xC) | (want << 2);
                    self.switch_polls = None;
                    self.check_clocks("switch");
                }
            }
        }
        self.cfgr
    }

    fn write_cfgr(&mut self, v: u32) {
        // SWS is read-only: the written value of its bits is ignored.
        let old_sw = self.cfgr & 0x3;
        self.cfgr = (v & !0xC) | (self.cfgr & 0xC);
        if v & 0x3 != old_sw {
            self.switch_polls = Some(0);
        }
        self.check_clocks("prescalers");
    }
}

impl ClockRegisters for Stm32f405 {
    fn read(&mut self, r: Register) -> u32 {
        let v = match r {
            RccCr => self.read_cr(),
            RccPllcfgr => self.pllcfgr,
            RccCfgr => self.read_cfgr(),
            RccApb1enr => self.apb1enr,
            PwrCr | PwrCsr if !self.pwr_clocked() => {
                self.violations.push(format!("{r:?} read unclocked"));
                0
            }
            PwrCr => self.pwr_cr,
            PwrCsr => {
                if let Some(p) = self.vos_polls.as_mut() {
                    *p += 1;
                    if self.vos_ready.is_some_and(|n| *p > n) {
                        self.pwr_csr |= 1 << 14;
                    }
                }
                self.pwr_csr
            }
            FlashAcr => self.acr,
        };
        self.record(Access::Read(r, v));
        v
    }

    fn write(&mut self, r: Register, v: u32) {
        self.record(Access::Write(r, v));
        match r {
            RccCr => self.write_cr(v),
            RccPllcfgr => {
                if self.cr & (1 << 24) != 0 {
                    self.violations
                        .push("PLLCFGR written with the PLL on".into());
                } else {
                    if v & !0x0F43_7FFF != PLLCFGR_RESET & !0x0F43_7FFF {
                        self.violations
                            .push(format!("PLLCFGR's reserved bits changed: {v:#010x}"));
                    }
                    self.pllcfgr = v;
                }
            }
            RccCfgr => self.write_cfgr(v),
            RccApb1enr => self.apb1enr = v,
            PwrCr | PwrCsr if !self.pwr_clocked() => {
                self.violations.push(format!("{r:?} written unclocked"));
            }
            PwrCr => {
                if self.cr & (1 << 24) != 0 && (v ^ self.pwr_cr) & (1 << 14) != 0 {
                    self.violations.push("VOS changed with the PLL on".into());
                }
                self.pwr_cr = v;
                self.pwr_csr &= !(1 << 14);
                self.vos_polls = Some(0);
            }
            PwrCsr => {}
            FlashAcr => {
                let latency = if self.latency_takes {
                    v & 0x7
                } else {
                    self.acr & 0x7
                };
                self.acr = (v & !0x7) | latency;
                self.check_clocks("flash latency");
            }
        }
    }
}

/// QEMU 7.2's `netduinoplus2`: RCC, PWR and the flash interface are unimplemented
/// devices, whose reads return 0 and writes do nothing.
#[derive(Default)]
struct Unimplemented {
    log: Vec<Access>,
}

impl ClockRegisters for Unimplemented {
    fn read(&mut self, r: Register) -> u32 {
        self.log.push(Access::Read(r, 0));
        0
    }

    fn write(&mut self, r: Register, v: u32) {
        self.log.push(Access::Write(r, v));
    }
}

const SHORT: PollLimits = PollLimits {
    voltage_scale: 20,
    hse: 30,
    pll: 40,
    switch: 50,
};

#[test]
fn from_reset_the_sequence_follows_rm0090_step_by_step() {
    let mut chip = Stm32f405::from_reset(3);
    assert_eq!(
        configure_with(&mut chip, &SHORT),
        Ok(ClockSource::Pll { hse_hz: 25_000_000 })
    );
    assert!(chip.violations.is_empty(), "{:?}", chip.violations);
    // Every write, in order, with the values RM0090's field tables give.
    assert_eq!(
        chip.writes(),
        [
            // PWREN: PWR's clock.
            (RccApb1enr, 0x1000_0000),
            // VOS = 1: scale 1 (its reset value, written while the PLL is off).
            (PwrCr, 0x0000_4000),
            // HSEON, bypass off.
            (RccCr, CR_RESET | 0x0001_0000),
            // PLLQ 7, PLLSRC HSE, PLLP 00 (÷2), PLLN 336, PLLM 25; reserved bit 29 kept.
            (RccPllcfgr, 0x2740_5419),
            // PLLON (HSERDY read set).
            (RccCr, CR_RESET | 0x0103_0000),
            // LATENCY 5, ICEN, DCEN, PRFTEN off.
            (FlashAcr, 0x0000_0605),
            // PPRE2 100 (÷2), PPRE1 101 (÷4), HPRE 0 (÷1), SW HSI.
            (RccCfgr, 0x0000_9400),
            // SW = PLL.
            (RccCfgr, 0x0000_9402),
            // CSSON (PLLRDY, HSERDY read set).
            (RccCr, CR_RESET | 0x030B_0000),
        ]
    );
    // The read-backs between them: PWREN after its write, VOSRDY, HSERDY and
    // PLLRDY polled until set (3 polls each, then the one that sees it), the
    // latency read back before the switch, SWS after it.
    let step = |r, f: fn(u32) -> bool| chip.first_write(r, f).unwrap();
    let read_after = |i: usize, r: Register| {
        chip.log[i + 1..]
            .iter()
            .position(|(a, _)| matches!(a, Access::Read(x, _) if *x == r))
            .map(|k| k + i + 1)
    };
    let pwren = step(RccApb1enr, |v| v & (1 << 28) != 0);
    assert_eq!(
        chip.log[pwren + 1],
        (Access::Read(RccApb1enr, 0x1000_0000), 1)
    );
    let vos = step(PwrCr, |_| true);
    let hse_on = step(RccCr, |v| v & (1 << 16) != 0);
    assert_eq!(
        chip.log[vos + 1..hse_on - 1],
        [
            (Access::Read(PwrCsr, 0), 3),
            (Access::Read(PwrCsr, 1 << 14), 1)
        ]
    );
    assert_eq!(
        chip.log[hse_on + 1..hse_on + 3],
        [
            (Access::Read(RccCr, CR_RESET | 0x0001_0000), 3),
            (Access::Read(RccCr, CR_RESET | 0x0003_0000), 1)
        ]
    );
    let acr = step(FlashAcr, |_| true);
    let switch = step(RccCfgr, |v| v & 3 == 2);
    assert_eq!(read_after(acr, FlashAcr), Some(acr + 1));
    assert!(acr < switch);
    assert_eq!(
        chip.log[switch + 1..switch + 3],
        [
            (Access::Read(RccCfgr, 0x0000_9402), 3),
            (Access::Read(RccCfgr, 0x0000_940A), 1)
        ]
    );
    // Where it ends: the core on the PLL at 168 MHz, buses at their maxima, the
    // clock security system on.
    assert_eq!((chip.cfgr >> 2) & 3, 2);
    assert_eq!(chip.hclk(2), 168_000_000);
    assert_eq!(chip.cr & (1 << 19), 1 << 19);
    assert_eq!(chip.acr & 7, 5);
}

#[test]
fn qemus_unimplemented_rcc_reads_zero_and_is_left_alone() {
    let mut qemu = Unimplemented::default();
    assert_eq!(configure(&mut qemu), Ok(ClockSource::Fixed));
    // One read of RCC_CR, nothing written (QEMU's `-d unimp` log of the ECU shows
    // the same single read at RCC offset 0).
    assert_eq!(qemu.log, [Access::Read(RccCr, 0)]);
}

#[test]
fn not_from_reset_is_refused_before_any_write() {
    // On the PLL already (a boot loader set the clock), or the PLL on.
    for (cr, cfgr) in [(CR_RESET | 0x0303_0000, 0x8), (CR_RESET | 0x0100_0000, 0)] {
        let mut chip = Stm32f405::from_reset(0);
        chip.cr = cr;
        chip.cfgr = cfgr;
        assert_eq!(configure_with(&mut chip, &SHORT), Err(ClockError::NotOnHsi));
        assert!(chip.writes().is_empty(), "{:?}", chip.log);
    }
}

#[test]
fn a_voltage_scale_that_never_gets_ready_stops_before_the_crystal() {
    let mut chip = Stm32f405::from_reset(0);
    chip.vos_ready = None;
    assert_eq!(
        configure_with(&mut chip, &SHORT),
        Err(ClockError::VoltageScaleTimeout)
    );
    assert_eq!(chip.reads_of(PwrCsr), u64::from(SHORT.voltage_scale));
    assert_eq!(chip.first_write(RccCr, |_| true), None);
    assert!(chip.violations.is_empty(), "{:?}", chip.violations);
}

#[test]
fn no_crystal_times_out_turns_the_hse_off_and_never_switches() {
    let mut chip = Stm32f405::from_reset(0);
    chip.hse_ready = None;
    assert_eq!(
        configure_with(&mut chip, &SHORT),
        Err(ClockError::HseTimeout)
    );
    // The polls after HSEON, then one read before the write that turns it off.
    let hse_on = chip.first_write(RccCr, |v| v & (1 << 16) != 0).unwrap();
    assert_eq!(
        chip.log[hse_on + 1],
        (
            Access::Read(RccCr, CR_RESET | 0x0001_0000),
            u64::from(SHORT.hse) + 1
        )
    );
    assert_eq!(chip.writes().last(), Some(&(RccCr, CR_RESET)));
    assert_eq!(chip.first_write(RccPllcfgr, |_| true), None);
    assert_eq!(chip.first_write(RccCfgr, |_| true), None);
    assert_eq!(chip.cr & ((1 << 16) | (1 << 19) | (1 << 24)), 0);
    assert!(chip.violations.is_empty(), "{:?}", chip.violations);
}

#[test]
fn a_pll_that_never_locks_times_out_and_turns_pll_and_crystal_off() {
    let mut chip = Stm32f405::from_reset(2);
    chip.pll_ready = None;
    assert_eq!(
        configure_with(&mut chip, &SHORT),
        Err(ClockError::PllTimeout)
    );
    let pll_on = chip.first_write(RccCr, |v| v & (1 << 24) != 0).unwrap();
    assert_eq!(
        chip.log[pll_on + 1].1,
        u64::from(SHORT.pll) + 1,
        "{:?}",
        chip.log
    );
    let writes = chip.writes();
    assert_eq!(
        writes[writes.len() - 2..],
        [
            (RccCr, CR_RESET | 0x0003_0000),
            (RccCr, CR_RESET | 0x0002_0000)
        ]
    );
    assert_eq!(chip.cr & ((1 << 16) | (1 << 24)), 0);
    assert_eq!(chip.first_write(FlashAcr, |_| true), None);
    assert_eq!(chip.first_write(RccCfgr, |_| true), None);
    assert!(chip.violations.is_empty(), "{:?}", chip.violations);
}

#[test]
fn a_flash_latency_that_does_not_take_stops_before_the_switch() {
    let mut chip = Stm32f405::from_reset(1);
    chip.latency_takes = false;
    assert_eq!(
        configure_with(&mut chip, &SHORT),
        Err(ClockError::FlashLatency)
    );
    assert_eq!(chip.first_write(RccCfgr, |_| true), None);
    assert_eq!(chip.cr & ((1 << 16) | (1 << 24)), 0);
    assert_eq!((chip.cfgr >> 2) & 3, 0);
    assert!(chip.violations.is_empty(), "{:?}", chip.violations);
}

#[test]
fn a_switch_that_sws_never_confirms_goes_back_to_the_hsi_without_css() {
    let mut chip = Stm32f405::from_reset(1);
    chip.switch_follows = None;
    assert_eq!(
        configure_with(&mut chip, &SHORT),
        Err(ClockError::SwitchTimeout)
    );
    assert_eq!(chip.reads_of(RccCfgr), u64::from(SHORT.switch) + 2);
    assert_eq!(chip.writes().last(), Some(&(RccCfgr, 0x0000_9400)));
    assert_eq!(chip.cr & (1 << 19), 0, "CSS on without the switch");
    assert!(chip.violations.is_empty(), "{:?}", chip.violations);
}

#[test]
fn each_wait_is_bounded_exactly_by_its_limit() {
    // A ready bit seen at the last allowed poll passes; one poll later fails.
    let at = |polls: u32| {
        let mut chip = Stm32f405::from_reset(0);
        chip.switch_follows = Some(polls);
        configure_with(&mut chip, &SHORT)
    };
    assert!(at(SHORT.switch - 1).is_ok());
    assert_eq!(at(SHORT.switch), Err(ClockError::SwitchTimeout));
    let hse_at = |polls: u32| {
        let mut chip = Stm32f405::from_reset(0);
        chip.hse_ready = Some(polls);
        configure_with(&mut chip, &SHORT)
    };
    assert!(hse_at(SHORT.hse - 1).is_ok());
    assert_eq!(hse_at(SHORT.hse), Err(ClockError::HseTimeout));
}

#[test]
fn the_ecus_bounds_are_the_ones_configure_uses() {
    // `configure` waits POLL_LIMITS: a crystal that never starts is polled
    // exactly that often (at least 100 ms at one poll per HSI cycle).
    let mut chip = Stm32f405::from_reset(0);
    chip.hse_ready = None;
    assert_eq!(configure(&mut chip), Err(ClockError::HseTimeout));
    let hse_on = chip.first_write(RccCr, |v| v & (1 << 16) != 0).unwrap();
    assert_eq!(chip.log[hse_on + 1].1, u64::from(POLL_LIMITS.hse) + 1);
    let seconds = |polls: u32| f64::from(polls) / f64::from(HSI_HZ);
    assert!(seconds(POLL_LIMITS.hse) >= 0.1);
    assert!(seconds(POLL_LIMITS.pll) >= 0.002);
    assert!(seconds(POLL_LIMITS.voltage_scale) >= 1.0);
    assert!(seconds(POLL_LIMITS.switch) >= 5.0);
}

#[test]
fn the_model_catches_a_sequence_out_of_rm0090s_order() {
    // Switched to the PLL before the flash latency was raised, with APB1 ÷1.
    let mut chip = Stm32f405::from_reset(0);
    chip.write(RccApb1enr, 1 << 28);
    chip.write(RccCr, CR_RESET | (1 << 16));
    while chip.read(RccCr) & (1 << 17) == 0 {}
    chip.write(RccPllcfgr, 0x2740_5419);
    chip.write(RccCr, CR_RESET | (1 << 16) | (1 << 24));
    while chip.read(RccCr) & (1 << 25) == 0 {}
    chip.write(RccCfgr, 2);
    while chip.read(RccCfgr) & 0xC != 0x8 {}
    // Then the PLL reconfigured while it clocks the core, and turned off.
    chip.write(RccPllcfgr, 0x2740_5419);
    chip.write(RccCr, CR_RESET | (1 << 16));
    let v = chip.violations.join("; ");
    for rule in [
        "0 flash wait states",
        "APB1 168000000 Hz",
        "PLLCFGR written with the PLL on",
        "PLL turned off while it clocks the core",
    ] {
        assert!(v.contains(rule), "{rule}: {v}");
    }
    // PWR untouched without its clock; reserved bits of PLLCFGR.
    let mut chip = Stm32f405::from_reset(0);
    chip.write(PwrCr, PWR_CR_RESET);
    chip.write(RccPllcfgr, 0x0740_5419);
    let v = chip.violations.join("; ");
    assert!(v.contains("PwrCr written unclocked"), "{v}");
    assert!(v.contains("reserved bits"), "{v}");
}

#[test]
fn the_pll_factors_follow_from_the_crystal() {
    assert_eq!(
        PLL,
        PllConfig {
            m: 25,
            n: 336,
            p: 2,
            q: 7
        }
    );
    assert_eq!(HSE_HZ, 25_000_000);
    assert_eq!(SYSCLK_HZ, firmware::timing::ECU_CLOCK_HZ);
    assert_eq!(FLASH_LATENCY_WS, 5);
    assert!(PLL.is_valid_for(HSE_HZ));
    // Other boards: an 8 MHz crystal (VCO input 2 MHz), 26 MHz.
    let eight = PllConfig::for_hse(8_000_000);
    assert_eq!((eight.m, eight.n, eight.p, eight.q), (4, 168, 2, 7));
    assert!(eight.is_valid_for(8_000_000));
    assert!(PllConfig::for_hse(26_000_000).is_valid_for(26_000_000));
    // Crystals the PLL cannot serve exactly, or outside 4–26 MHz.
    for hse in [12_288_000, 3_000_000, 27_000_000, 25_000_001] {
        assert!(!PllConfig::for_hse(hse).is_valid_for(hse), "{hse}");
    }
    // The factors for one crystal are wrong for another.
    assert!(!PLL.is_valid_for(8_000_000));
    assert_eq!(
        PLL.pllcfgr_fields() & !clock_tree::bits::PLLCFGR_FIELDS,
        0,
        "fields only"
    );
}

#[test]
fn clock_error_codes_round_trip_and_are_distinct() {
    for (i, e) in ClockError::ALL.into_iter().enumerate() {
        assert_eq!(usize::from(e.code()), i + 1);
        assert_eq!(ClockError::from_code(e.code()), Some(e));
    }
    let names: std::collections::HashSet<_> = ClockError::ALL.iter().map(|e| e.name()).collect();
    assert_eq!(names.len(), ClockError::ALL.len());
    assert_eq!(ClockError::from_code(0), None);
    assert_eq!(ClockError::from_code(7), None);
}

#[test]
fn the_apb2_clock_follows_the_bits_of_cfgr() {
    use firmware::clock_tree::{apb2_hz, bits, APB2_MAX_HZ, CFGR_PRESCALERS};
    // From reset (and QEMU's RCC, which reads 0): the HSI, no division.
    assert_eq!(apb2_hz(0), HSI_HZ);
    // The configured tree: the PLL, AHB ÷1, APB2 ÷2.
    assert_eq!(apb2_hz(bits::SWS_PLL | CFGR_PRESCALERS), 84_000_000);
    assert_eq!(apb2_hz(bits::SWS_PLL | CFGR_PRESCALERS), APB2_MAX_HZ);
    // A failed switch with the prescalers already set: the HSI ÷2.
    assert_eq!(apb2_hz(bits::SWS_HSI | CFGR_PRESCALERS), HSI_HZ / 2);
    // The crystal directly.
    assert_eq!(apb2_hz(1 << 2), HSE_HZ);
    // Every AHB division (RM0090: no ÷32) and every APB2 division.
    let ahb = [
        (0b1000, 2),
        (0b1001, 4),
        (0b1010, 8),
        (0b1011, 16),
        (0b1100, 64),
    ];
    for (hpre, div) in ahb
        .into_iter()
        .chain([(0b1101, 128), (0b1110, 256), (0b1111, 512)])
    {
        assert_eq!(
            apb2_hz(bits::SWS_PLL | (hpre << 4)),
            168_000_000 / div,
            "HPRE {hpre:04b}"
        );
    }
    for hpre in 0..8 {
        assert_eq!(apb2_hz(bits::SWS_PLL | (hpre << 4)), 168_000_000);
    }
    for (ppre2, div) in [
        (0b000, 1),
        (0b011, 1),
        (0b100, 2),
        (0b101, 4),
        (0b110, 8),
        (0b111, 16),
    ] {
        assert_eq!(
            apb2_hz(bits::SWS_PLL | (ppre2 << 13)),
            168_000_000 / div,
            "PPRE2 {ppre2:03b}"
        );
    }
    // Not APB1's prescaler.
    assert_eq!(apb2_hz(bits::SWS_PLL | bits::PPRE1_DIV4), 168_000_000);
}
