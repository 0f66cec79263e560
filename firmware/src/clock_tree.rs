//! The ECU's clock tree: the STM32F405 taken from its reset clock (the 16 MHz
//! internal RC oscillator, HSI) to [`SYSCLK_HZ`] from the board's crystal, in the
//! order the reference manual (RM0090) prescribes, every wait bounded.
//!
//! ```text
//! HSE (crystal, HSE_HZ) ─÷M→ 1 or 2 MHz ─×N→ VCO 336 MHz ─÷P=2→ SYSCLK 168 MHz ─÷1→ HCLK 168 MHz (core, SysTick, flash)
//!                                                       └─÷Q=7→ 48 MHz (USB OTG FS, SDIO, RNG)       ├─÷4→ APB1 42 MHz (its maximum)
//!                                                                                                   └─÷2→ APB2 84 MHz (its maximum)
//! ```
//!
//! [`configure`] runs the sequence through [`ClockRegisters`], one word read or
//! write of a named register at a time, so that the host checks it step by step
//! against a register-level model (`firmware/tests/clock_tree.rs`) and the ECU
//! runs the same code on the registers themselves:
//!
//! 1. `RCC_CR` read: all zero means there is no RCC to configure (below), and
//!    nothing is written. Otherwise the core must run on the HSI with the PLL off
//!    (as from reset), or the sequence refuses ([`ClockError::NotOnHsi`]).
//! 2. The PWR interface's clock on (`RCC_APB1ENR.PWREN`), read back (the bus
//!    needs that delay before PWR is accessed).
//! 3. Voltage scale 1 (`PWR_CR.VOS`, needed above 144 MHz; written while the PLL
//!    is off, as RM0090 requires), then `PWR_CSR.VOSRDY`.
//! 4. The HSE on (a crystal: bypass off), then `RCC_CR.HSERDY`.
//! 5. The PLL's factors ([`PLL`]) and source (HSE) in `RCC_PLLCFGR`, its
//!    reserved bits kept; the PLL on, then `RCC_CR.PLLRDY`.
//! 6. Flash latency raised to [`FLASH_LATENCY_WS`] before the faster clock is
//!    selected (RM0090 §3.5.1), with the ART accelerator's instruction and data
//!    caches on and its prefetch off, as the timing analysis models the flash
//!    (`host-sim wcet`'s memory model); read back: the switch waits until the
//!    latency is the one written.
//! 7. The bus prescalers (AHB ÷1, APB1 ÷4, APB2 ÷2), written while the core
//!    still runs on the HSI, so no bus ever runs above its maximum.
//! 8. `SW` = PLL, then `SWS` read until it says PLL: the switch is read back.
//! 9. The clock security system on (`RCC_CR.CSSON`): should the HSE fail from now
//!    on, the hardware switches the core to the HSI and raises an NMI (the ECU's
//!    NMI handler puts the actuators in the safe state and sends a fault frame).
//!
//! Each wait polls its ready bit at most a constant number of times
//! ([`POLL_LIMITS`]) and fails with its own [`ClockError`]; a failed sequence turns
//! off what it turned on where the hardware allows it and leaves the core on the
//! HSI: the caller must not run the control loop then (the ECU refuses its set-up
//! with [`crate::link::SetupError::ClockFailed`]).
//!
//! **No RCC.** QEMU's `netduinoplus2` (7.2) maps the RCC, PWR and flash interface
//! as unimplemented devices: reads return 0 and writes are ignored, and its core
//! clock is fixed at 168 MHz. On silicon `RCC_CR` cannot read 0 while code runs:
//! the oscillator that clocks the core is on and ready, so its `…RDY` bit is set
//! (from reset, `HSION` and `HSIRDY`). An all-zero `RCC_CR` therefore means a
//! machine whose clock is fixed: [`ClockSource::Fixed`], nothing written. Any
//! other value goes through the whole sequence and its checks.
//!
//! **Another board.** The crystal is [`HSE_HZ`] and nothing else: the PLL's
//! factors follow from it ([`PllConfig::for_hse`]) and a crystal they cannot
//! serve (not a whole number of MHz, outside 4–26 MHz) fails to compile. A board
//! whose HSE is an external clock rather than a crystal also sets `HSEBYP`, which
//! this sequence clears.

use crate::timing::ECU_CLOCK_HZ;

/// The board's crystal (HSE), Hz: the Netduino Plus 2, whose STM32F405 QEMU's
/// `netduinoplus2` models, has a 25 MHz crystal (MicroPython's board definition
/// for it: PLLM 25, PLLN 336, PLLP 2, PLLQ 7). The one constant another board
/// changes.
pub const HSE_HZ: u32 = 25_000_000;

/// The internal RC oscillator (HSI), Hz: the core's clock from reset, and while
/// the sequence waits.
pub const HSI_HZ: u32 = 16_000_000;

/// The system clock the sequence sets (SYSCLK = HCLK, the core's), Hz: the
/// ECU's clock ([`crate::timing::ECU_CLOCK_HZ`]).
pub const SYSCLK_HZ: u32 = ECU_CLOCK_HZ;

/// The PLL's 48 MHz output (USB OTG FS, SDIO, RNG), Hz.
pub const PLL48_HZ: u32 = 48_000_000;

/// AHB prescaler: HCLK = SYSCLK / 1.
pub const AHB_DIV: u32 = 1;
/// APB1 prescaler: PCLK1 = HCLK / 4 = 42 MHz, APB1's maximum.
pub const APB1_DIV: u32 = 4;
/// APB2 prescaler: PCLK2 = HCLK / 2 = 84 MHz, APB2's maximum.
pub const APB2_DIV: u32 = 2;

/// Highest APB1 clock (STM32F405 datasheet), Hz.
pub const APB1_MAX_HZ: u32 = 42_000_000;
/// Highest APB2 clock, Hz.
pub const APB2_MAX_HZ: u32 = 84_000_000;

/// Flash wait states at [`SYSCLK_HZ`] (RM0090 table 10, 2.7–3.6 V: one per
/// 30 MHz of HCLK, 5 for 150–168 MHz): `⌈HCLK / 30 MHz⌉ − 1`.
pub const FLASH_LATENCY_WS: u32 = (SYSCLK_HZ / AHB_DIV).div_ceil(30_000_000) - 1;

/// The main PLL's factors (RM0090 §6.3.2, `RCC_PLLCFGR`): VCO input = HSE / `m`,
/// VCO = input × `n`, SYSCLK = VCO / `p`, 48 MHz clock = VCO / `q`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PllConfig {
    /// Input divider `PLLM` (2–63).
    pub m: u32,
    /// VCO multiplier `PLLN` (50–432).
    pub n: u32,
    /// SYSCLK divider `PLLP` (2, 4, 6 or 8).
    pub p: u32,
    /// 48 MHz divider `PLLQ` (2–15).
    pub q: u32,
}

impl PllConfig {
    /// The factors for a crystal of `hse_hz` Hz: VCO input 2 MHz (RM0090's
    /// recommendation, less PLL jitter) when the crystal is a multiple of 2 MHz,
    /// else 1 MHz; VCO at twice [`SYSCLK_HZ`], `p` = 2, `q` for [`PLL48_HZ`].
    /// Whether they are usable is [`PllConfig::is_valid_for`]'s answer.
    pub const fn for_hse(hse_hz: u32) -> Self {
        let vco_in = if hse_hz.is_multiple_of(2_000_000) {
            2_000_000
        } else {
            1_000_000
        };
        let vco = 2 * SYSCLK_HZ;
        Self {
            m: hse_hz / vco_in,
            n: vco / vco_in,
            p: 2,
            q: vco / PLL48_HZ,
        }
    }

    /// Whether these factors are within RM0090's ranges for a crystal of `hse_hz`
    /// Hz (4–26 MHz) and give exactly [`SYSCLK_HZ`] and [`PLL48_HZ`]: VCO input
    /// 1–2 MHz, VCO 100–432 MHz, each factor in its field's range.
    pub const fn is_valid_for(&self, hse_hz: u32) -> bool {
        let (m, n, p, q) = (self.m as u64, self.n as u64, self.p as u64, self.q as u64);
        let hse = hse_hz as u64;
        let factors = m >= 2
            && m <= 63
            && n >= 50
            && n <= 432
            && (p == 2 || p == 4 || p == 6 || p == 8)
            && q >= 2
            && q <= 15;
        if !factors || hse < 4_000_000 || hse > 26_000_000 {
            return false;
        }
        let vco_in_exact = hse.is_multiple_of(m);
        let vco_in = hse / m;
        let vco = vco_in * n;
        vco_in_exact
            && vco_in >= 1_000_000
            && vco_in <= 2_000_000
            && vco >= 100_000_000
            && vco <= 432_000_000
            && vco.is_multiple_of(p)
            && vco / p == SYSCLK_HZ as u64
            && vco.is_multiple_of(q)
            && vco / q == PLL48_HZ as u64
    }

    /// The `RCC_PLLCFGR` fields of these factors with the HSE as the PLL's source
    /// (`PLLSRC`), the reserved bits zero.
    pub const fn pllcfgr_fields(&self) -> u32 {
        (self.m << bits::PLLM_SHIFT)
            | (self.n << bits::PLLN_SHIFT)
            | ((self.p / 2 - 1) << bits::PLLP_SHIFT)
            | bits::PLLSRC_HSE
            | (self.q << bits::PLLQ_SHIFT)
    }
}

/// The PLL's factors for [`HSE_HZ`] (for the 25 MHz crystal: M 25, N 336, P 2,
/// Q 7).
pub const PLL: PllConfig = PllConfig::for_hse(HSE_HZ);

// The build fails on a crystal the PLL cannot serve, and on prescalers that
// overclock a bus.
const _: () = assert!(PLL.is_valid_for(HSE_HZ));
const _: () = assert!(SYSCLK_HZ <= 168_000_000 && AHB_DIV == 1);
const _: () = assert!(SYSCLK_HZ / AHB_DIV / APB1_DIV <= APB1_MAX_HZ);
const _: () = assert!(SYSCLK_HZ / AHB_DIV / APB2_DIV <= APB2_MAX_HZ);
const _: () = assert!(FLASH_LATENCY_WS <= 7);

/// The registers the sequence reads and writes (RM0090's names; their addresses
/// are the device's, e.g. the `stm32f4` PAC's).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Register {
    /// `RCC_CR`: oscillators and PLL on/ready, clock security system.
    RccCr,
    /// `RCC_PLLCFGR`: the main PLL's factors and source.
    RccPllcfgr,
    /// `RCC_CFGR`: system clock switch and its status, bus prescalers.
    RccCfgr,
    /// `RCC_APB1ENR`: APB1 peripheral clocks (PWR's).
    RccApb1enr,
    /// `PWR_CR`: voltage scaling.
    PwrCr,
    /// `PWR_CSR`: voltage scaling ready.
    PwrCsr,
    /// `FLASH_ACR`: flash latency, ART accelerator.
    FlashAcr,
}

/// Word access to the clock tree's registers: the ECU's are the device's, the
/// host's a model of them.
pub trait ClockRegisters {
    /// The register's value (32 bits).
    fn read(&mut self, register: Register) -> u32;
    /// Writes the register (32 bits).
    fn write(&mut self, register: Register, value: u32);
}

/// Register fields (RM0090 §5.4, §6.3, §3.9), as masks or shifts.
pub mod bits {
    /// `RCC_CR.HSION`: the HSI on.
    pub const HSION: u32 = 1 << 0;
    /// `RCC_CR.HSIRDY`: the HSI ready.
    pub const HSIRDY: u32 = 1 << 1;
    /// `RCC_CR.HSEON`: the HSE on.
    pub const HSEON: u32 = 1 << 16;
    /// `RCC_CR.HSERDY`: the HSE ready.
    pub const HSERDY: u32 = 1 << 17;
    /// `RCC_CR.HSEBYP`: the HSE bypassed by an external clock (no crystal).
    pub const HSEBYP: u32 = 1 << 18;
    /// `RCC_CR.CSSON`: the clock security system on.
    pub const CSSON: u32 = 1 << 19;
    /// `RCC_CR.PLLON`: the main PLL on.
    pub const PLLON: u32 = 1 << 24;
    /// `RCC_CR.PLLRDY`: the main PLL locked.
    pub const PLLRDY: u32 = 1 << 25;

    /// `RCC_PLLCFGR.PLLM`: bits 5:0.
    pub const PLLM_SHIFT: u32 = 0;
    /// `RCC_PLLCFGR.PLLN`: bits 14:6.
    pub const PLLN_SHIFT: u32 = 6;
    /// `RCC_PLLCFGR.PLLP`: bits 17:16 (0 for ÷2, 1 ÷4, 2 ÷6, 3 ÷8).
    pub const PLLP_SHIFT: u32 = 16;
    /// `RCC_PLLCFGR.PLLSRC`: bit 22, set for the HSE.
    pub const PLLSRC_HSE: u32 = 1 << 22;
    /// `RCC_PLLCFGR.PLLQ`: bits 27:24.
    pub const PLLQ_SHIFT: u32 = 24;
    /// Every field of `RCC_PLLCFGR` (the rest is reserved, kept at its value).
    pub const PLLCFGR_FIELDS: u32 = 0x3F | (0x1FF << 6) | (0x3 << 16) | PLLSRC_HSE | (0xF << 24);

    /// `RCC_CFGR.SW`: bits 1:0, the system clock selected.
    pub const SW_MASK: u32 = 0x3;
    /// `RCC_CFGR.SWS`: bits 3:2, the system clock in use.
    pub const SWS_MASK: u32 = 0x3 << 2;
    /// `SW`/`SWS` value of the HSI.
    pub const SW_HSI: u32 = 0;
    /// `SW` value of the PLL.
    pub const SW_PLL: u32 = 2;
    /// `SWS` value of the HSI.
    pub const SWS_HSI: u32 = SW_HSI << 2;
    /// `SWS` value of the PLL.
    pub const SWS_PLL: u32 = SW_PLL << 2;
    /// `RCC_CFGR.HPRE`: bits 7:4, AHB prescaler (0: ÷1).
    pub const HPRE_MASK: u32 = 0xF << 4;
    /// `HPRE` for ÷1.
    pub const HPRE_DIV1: u32 = 0;
    /// `RCC_CFGR.PPRE1`: bits 12:10, APB1 prescaler.
    pub const PPRE1_MASK: u32 = 0x7 << 10;
    /// `PPRE1` for ÷4 (`101`).
    pub const PPRE1_DIV4: u32 = 0b101 << 10;
    /// `RCC_CFGR.PPRE2`: bits 15:13, APB2 prescaler.
    pub const PPRE2_MASK: u32 = 0x7 << 13;
    /// `PPRE2` for ÷2 (`100`).
    pub const PPRE2_DIV2: u32 = 0b100 << 13;

    /// `RCC_APB1ENR.PWREN`: the PWR interface's clock.
    pub const PWREN: u32 = 1 << 28;
    /// `PWR_CR.VOS`: regulator voltage scale 1 (set) or 2.
    pub const VOS: u32 = 1 << 14;
    /// `PWR_CSR.VOSRDY`: the voltage scale is ready.
    pub const VOSRDY: u32 = 1 << 14;

    /// `FLASH_ACR.LATENCY`: bits 2:0, wait states.
    pub const LATENCY_MASK: u32 = 0x7;
    /// `FLASH_ACR.PRFTEN`: prefetch.
    pub const PRFTEN: u32 = 1 << 8;
    /// `FLASH_ACR.ICEN`: instruction cache.
    pub const ICEN: u32 = 1 << 9;
    /// `FLASH_ACR.DCEN`: data cache.
    pub const DCEN: u32 = 1 << 10;
}

/// The value [`configure`] writes to `FLASH_ACR`: [`FLASH_LATENCY_WS`] wait
/// states, instruction and data caches on, prefetch off (the timing analysis'
/// memory model: a prefetch in flight could delay a branch's fetch, which the
/// model does not charge).
pub const FLASH_ACR: u32 = FLASH_LATENCY_WS | bits::ICEN | bits::DCEN;

/// The bus prescaler fields [`configure`] writes to `RCC_CFGR` (AHB ÷1, APB1
/// ÷4, APB2 ÷2).
pub const CFGR_PRESCALERS: u32 = bits::HPRE_DIV1 | bits::PPRE1_DIV4 | bits::PPRE2_DIV2;
const _: () = assert!(APB1_DIV == 4 && APB2_DIV == 2);

/// The most polls of each ready bit before its wait fails. Each is a time of
/// ST's HAL (its `HSE_STARTUP_TIMEOUT`, `PLL_TIMEOUT_VALUE`,
/// `PWR_VOSRDY_TIMEOUT_VALUE`, `CLOCKSWITCH_TIMEOUT_VALUE`) in cycles of the HSI
/// the core runs on while it waits: a poll takes at least one cycle, so a wait
/// that fails has lasted at least that time.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PollLimits {
    /// `PWR_CSR.VOSRDY`, polls.
    pub voltage_scale: u32,
    /// `RCC_CR.HSERDY`, polls.
    pub hse: u32,
    /// `RCC_CR.PLLRDY`, polls.
    pub pll: u32,
    /// `RCC_CFGR.SWS` = PLL, polls.
    pub switch: u32,
}

/// Polls in `ms` milliseconds at one poll per HSI cycle.
const fn polls_in_ms(ms: u32) -> u32 {
    ms * (HSI_HZ / 1_000)
}

/// The ECU's bounds: VOSRDY within 1 s, HSERDY within 100 ms, PLLRDY within
/// 2 ms, the switch within 5 s.
pub const POLL_LIMITS: PollLimits = PollLimits {
    voltage_scale: polls_in_ms(1_000),
    hse: polls_in_ms(100),
    pll: polls_in_ms(2),
    switch: polls_in_ms(5_000),
};

/// What clocks the core after [`configure`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ClockSource {
    /// The PLL from the crystal (`hse_hz`, Hz) at [`SYSCLK_HZ`]: the sequence ran.
    Pll {
        /// The crystal, Hz.
        hse_hz: u32,
    },
    /// A clock the machine fixes, with no RCC to configure (`RCC_CR` read all
    /// zero: QEMU's `netduinoplus2`, whose core clock is 168 MHz). Nothing was
    /// written.
    Fixed,
}

/// Why the sequence stopped (the core is left on the HSI, 16 MHz).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ClockError {
    /// The core did not run on the HSI with the PLL off when the sequence began
    /// (not from reset): nothing was written.
    NotOnHsi,
    /// `PWR_CSR.VOSRDY` did not come within [`PollLimits::voltage_scale`] polls.
    VoltageScaleTimeout,
    /// `RCC_CR.HSERDY` did not come within [`PollLimits::hse`] polls (no crystal,
    /// or a dead one); the HSE is turned off again.
    HseTimeout,
    /// `RCC_CR.PLLRDY` did not come within [`PollLimits::pll`] polls; the PLL and
    /// the HSE are turned off again.
    PllTimeout,
    /// `FLASH_ACR` did not read back the latency written; the PLL and the HSE are
    /// turned off again.
    FlashLatency,
    /// `RCC_CFGR.SWS` did not say PLL within [`PollLimits::switch`] polls; `SW`
    /// is set back to the HSI.
    SwitchTimeout,
}

impl ClockError {
    /// Every variant, in code order.
    pub const ALL: [ClockError; 6] = [
        ClockError::NotOnHsi,
        ClockError::VoltageScaleTimeout,
        ClockError::HseTimeout,
        ClockError::PllTimeout,
        ClockError::FlashLatency,
        ClockError::SwitchTimeout,
    ];

    /// Its code (1–6; the `Ready` frame's detail of
    /// [`crate::link::SetupError::ClockFailed`]).
    pub const fn code(self) -> u16 {
        match self {
            ClockError::NotOnHsi => 1,
            ClockError::VoltageScaleTimeout => 2,
            ClockError::HseTimeout => 3,
            ClockError::PllTimeout => 4,
            ClockError::FlashLatency => 5,
            ClockError::SwitchTimeout => 6,
        }
    }

    /// The variant of a code; `None` for unknown codes.
    pub const fn from_code(code: u16) -> Option<ClockError> {
        match code {
            1 => Some(ClockError::NotOnHsi),
            2 => Some(ClockError::VoltageScaleTimeout),
            3 => Some(ClockError::HseTimeout),
            4 => Some(ClockError::PllTimeout),
            5 => Some(ClockError::FlashLatency),
            6 => Some(ClockError::SwitchTimeout),
            _ => None,
        }
    }

    /// Its name, for logs.
    pub const fn name(self) -> &'static str {
        match self {
            ClockError::NotOnHsi => "NotOnHsi",
            ClockError::VoltageScaleTimeout => "VoltageScaleTimeout",
            ClockError::HseTimeout => "HseTimeout",
            ClockError::PllTimeout => "PllTimeout",
            ClockError::FlashLatency => "FlashLatency",
            ClockError::SwitchTimeout => "SwitchTimeout",
        }
    }
}

/// Sets the clock tree from reset to [`SYSCLK_HZ`] from the crystal (module
/// docs: the steps), every wait bounded by [`POLL_LIMITS`]. Not inlined: the
/// timing report names it as the function that sets the core clock
/// (`wcet.json`'s `clock.configured_in`).
#[inline(never)]
pub fn configure<R: ClockRegisters>(regs: &mut R) -> Result<ClockSource, ClockError> {
    configure_with(regs, &POLL_LIMITS)
}

/// [`configure`] with other bounds on the waits (`limits`): the host's tests use
/// short ones.
pub fn configure_with<R: ClockRegisters>(
    regs: &mut R,
    limits: &PollLimits,
) -> Result<ClockSource, ClockError> {
    use bits::*;
    use Register::*;
    // 1. No RCC, or not from reset.
    let cr = regs.read(RccCr);
    if cr == 0 {
        return Ok(ClockSource::Fixed);
    }
    let cfgr = regs.read(RccCfgr);
    if cfgr & SWS_MASK != SWS_HSI || cr & PLLON != 0 || cr & HSIRDY == 0 {
        return Err(ClockError::NotOnHsi);
    }
    // 2. PWR's clock, read back.
    let apb1enr = regs.read(RccApb1enr);
    regs.write(RccApb1enr, apb1enr | PWREN);
    let _ = regs.read(RccApb1enr);
    // 3. Voltage scale 1 while the PLL is off.
    let pwr_cr = regs.read(PwrCr);
    regs.write(PwrCr, pwr_cr | VOS);
    if !wait_for(regs, PwrCsr, VOSRDY, VOSRDY, limits.voltage_scale) {
        return Err(ClockError::VoltageScaleTimeout);
    }
    // 4. The crystal.
    let cr = regs.read(RccCr);
    regs.write(RccCr, (cr & !HSEBYP) | HSEON);
    if !wait_for(regs, RccCr, HSERDY, HSERDY, limits.hse) {
        let cr = regs.read(RccCr);
        regs.write(RccCr, cr & !HSEON);
        return Err(ClockError::HseTimeout);
    }
    // 5. The PLL from the crystal.
    let pllcfgr = regs.read(RccPllcfgr);
    regs.write(
        RccPllcfgr,
        (pllcfgr & !PLLCFGR_FIELDS) | PLL.pllcfgr_fields(),
    );
    let cr = regs.read(RccCr);
    regs.write(RccCr, cr | PLLON);
    if !wait_for(regs, RccCr, PLLRDY, PLLRDY, limits.pll) {
        turn_off_pll_and_hse(regs);
        return Err(ClockError::PllTimeout);
    }
    // 6. Flash latency before the switch, read back.
    regs.write(FlashAcr, FLASH_ACR);
    if regs.read(FlashAcr) & LATENCY_MASK != FLASH_LATENCY_WS {
        turn_off_pll_and_hse(regs);
        return Err(ClockError::FlashLatency);
    }
    // 7. Bus prescalers, still on the HSI.
    let cfgr = regs.read(RccCfgr);
    let cfgr = (cfgr & !(HPRE_MASK | PPRE1_MASK | PPRE2_MASK)) | CFGR_PRESCALERS;
    regs.write(RccCfgr, cfgr);
    // 8. The switch, read back.
    regs.write(RccCfgr, (cfgr & !SW_MASK) | SW_PLL);
    if !wait_for(regs, RccCfgr, SWS_MASK, SWS_PLL, limits.switch) {
        regs.write(RccCfgr, (cfgr & !SW_MASK) | SW_HSI);
        return Err(ClockError::SwitchTimeout);
    }
    // 9. The clock security system.
    let cr = regs.read(RccCr);
    regs.write(RccCr, cr | CSSON);
    Ok(ClockSource::Pll { hse_hz: HSE_HZ })
}

/// Polls `register` until its bits under `mask` equal `want`, at most `polls`
/// times; whether they did.
fn wait_for<R: ClockRegisters>(
    regs: &mut R,
    register: Register,
    mask: u32,
    want: u32,
    polls: u32,
) -> bool {
    for _ in 0..polls {
        if regs.read(register) & mask == want {
            return true;
        }
    }
    false
}

/// After a failed wait with the core still on the HSI: the PLL off, then the HSE.
fn turn_off_pll_and_hse<R: ClockRegisters>(regs: &mut R) {
    use bits::*;
    let cr = regs.read(Register::RccCr);
    regs.write(Register::RccCr, cr & !PLLON);
    regs.write(Register::RccCr, cr & !(PLLON | HSEON));
}

/// The APB2 clock (PCLK2, USART1's kernel clock) that the bits of `RCC_CFGR`
/// `cfgr` give, Hz: the system clock in use (`SWS`: the HSI, the crystal
/// [`HSE_HZ`], or the PLL's [`SYSCLK_HZ`]), divided by the AHB (`HPRE`) and APB2
/// (`PPRE2`) prescalers (RM0090 §7.3.3). After [`configure`] succeeded it is
/// [`SYSCLK_HZ`] / [`AHB_DIV`] / [`APB2_DIV`], 84 MHz; after a failure it is what
/// the sequence left (the HSI, with the prescalers it may already have set), so a
/// peripheral's baud rate can follow the clock the core actually runs on.
pub const fn apb2_hz(cfgr: u32) -> u32 {
    let sysclk = match (cfgr & bits::SWS_MASK) >> 2 {
        0 => HSI_HZ,
        1 => HSE_HZ,
        2 => SYSCLK_HZ,
        // Not allowed (RM0090): taken as the HSI, the clock from reset.
        _ => HSI_HZ,
    };
    let hpre = (cfgr & bits::HPRE_MASK) >> 4;
    // HPRE 0xxx: ÷1; 1000..1111: ÷2, 4, 8, 16, 64, 128, 256, 512 (no ÷32).
    let ahb_shift = match hpre {
        0..=7 => 0,
        8..=11 => hpre - 7,
        _ => hpre - 6,
    };
    let ppre2 = (cfgr & bits::PPRE2_MASK) >> 13;
    // PPRE2 0xx: ÷1; 100..111: ÷2, 4, 8, 16.
    let apb_shift = if ppre2 < 4 { 0 } else { ppre2 - 3 };
    (sysclk >> ahb_shift) >> apb_shift
}
