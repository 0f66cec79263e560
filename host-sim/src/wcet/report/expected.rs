//! The CI comparison of a report with the committed expected values
//! (`.ci/expected/wcet.json`), and the named step that writes them
//! (`.ci/bless-expected`, i.e. `host-sim wcet --write-expected FILE`).
//!
//! The file holds, for each quantity it checks (section sizes, flash, static RAM,
//! the stack bound, the observed instruction maxima, the static bounds, the
//! allocator and soft-double flags), two numbers:
//!
//! * `value`: the figure of the report the file was blessed from. The check fails
//!   on any difference (the file is *stale*): every commit that moves a figure
//!   carries the re-blessed file, so its diff shows the change;
//! * `baseline`: what growth is measured from. Blessing lowers it to the value when
//!   the value falls, keeps it when the value grows within the margin, and raises
//!   it only when told why (`--accept-growth REASON`, recorded beside it). The
//!   check fails when a figure grew past `baseline × (1 + margin)` (a
//!   *regression*), and so does blessing without a reason: re-measuring alone no
//!   longer moves the reference, so growth in small steps adds up against it.

use serde::{Deserialize, Serialize};
use serde_json::Value;
use std::path::Path;

use super::markdown::num;
use super::WcetReport;

/// The named step that rewrites the expected values (CI's PIL lap and report on
/// the current ELF, then `host-sim wcet --write-expected`).
pub const BLESS_COMMAND: &str = ".ci/bless-expected";

/// One quantity the check compares.
struct Checked {
    /// What it is, for a reader.
    name: &'static str,
    /// Its JSON pointer into `wcet.json` (the file names it as `memory.text_bytes`).
    pointer: &'static str,
    /// Its unit; `flag` for a boolean read as 0 (false) or 1 (true).
    unit: &'static str,
}

const fn q(name: &'static str, pointer: &'static str, unit: &'static str) -> Checked {
    Checked {
        name,
        pointer,
        unit,
    }
}

/// The quantities the check compares, in the file's order.
const CHECKED: [Checked; 18] = [
    q(".text", "/memory/text_bytes", "bytes"),
    q(".rodata (in flash)", "/memory/rodata_bytes", "bytes"),
    q(".data", "/memory/data_bytes", "bytes"),
    q(".bss", "/memory/bss_bytes", "bytes"),
    q("static RAM", "/memory/static_ram_bytes", "bytes"),
    q("flash", "/memory/flash_bytes", "bytes"),
    q("stack bound", "/memory/stack_bound_bytes", "bytes"),
    q(
        "plan observed max",
        "/tasks/plan/observed_max_instructions",
        "instructions",
    ),
    q(
        "plan warm observed max",
        "/tasks/plan/observed_warm_max_instructions",
        "instructions",
    ),
    q(
        "control observed max",
        "/tasks/control/observed_max_instructions",
        "instructions",
    ),
    q(
        "window adoption observed max",
        "/tasks/plan_window/observed_max_instructions",
        "instructions",
    ),
    q(
        "plan task static bound",
        "/tasks/plan/static_bound_cycles",
        "cycles",
    ),
    q(
        "plan_job static bound",
        "/tasks/plan/job_static_bound_cycles",
        "cycles",
    ),
    q(
        "window_job static bound",
        "/tasks/plan_window/static_bound_cycles",
        "cycles",
    ),
    q(
        "control task static bound",
        "/tasks/control/static_bound_cycles",
        "cycles",
    ),
    q(
        "control_job static bound",
        "/tasks/control/job_static_bound_cycles",
        "cycles",
    ),
    q("heap allocator linked", "/symbols/allocator", "flag"),
    q(
        "software double-precision linked",
        "/symbols/soft_double",
        "flag",
    ),
];

fn checked() -> impl Iterator<Item = &'static Checked> {
    CHECKED.iter()
}

/// The expected-values file, as [`bless`] writes it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExpectedFile {
    /// What the file is, how it is checked and how to change it.
    pub about: String,
    /// One entry per checked quantity.
    pub quantities: Vec<ExpectedQuantity>,
}

/// One checked quantity of [`ExpectedFile`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExpectedQuantity {
    /// Its key in `wcet.json` (`memory.text_bytes`).
    pub key: String,
    /// What it is.
    pub name: String,
    /// Its unit (`flag`: 0 false, 1 true).
    pub unit: String,
    /// The report's figure when blessed, rounded to an integer.
    pub value: i64,
    /// What growth is measured from: the lowest value blessed since growth past
    /// the margin was last accepted.
    pub baseline: i64,
    /// Why the baseline was last raised (`--accept-growth`); `null` while it is the
    /// lowest value blessed.
    pub accepted_growth: Option<String>,
}

impl Checked {
    /// `memory.text_bytes`.
    fn key(&self) -> String {
        self.pointer.trim_start_matches('/').replace('/', ".")
    }

    /// The report's figure, rounded (a flag as 0 or 1); an error naming the key
    /// when the report has none.
    fn figure(&self, report: &Value) -> Result<i64, String> {
        match report.pointer(self.pointer) {
            Some(Value::Bool(b)) => Ok(i64::from(*b)),
            Some(v) => match v.as_f64() {
                Some(x) if x.is_finite() => Ok(x.round() as i64),
                _ => Err(format!(
                    "{}: the report has no number at {} (e.g. no warm-started plan activation in \
                     the PIL runs, or no static bound)",
                    self.name,
                    self.key()
                )),
            },
            None => Err(format!(
                "{}: the report has no {} (the report's fields and this check's list differ)",
                self.name,
                self.key()
            )),
        }
    }

    /// `value` in the quantity's unit.
    fn show(&self, value: i64) -> String {
        if self.unit == "flag" {
            if value == 0 { "false" } else { "true" }.to_string()
        } else {
            format!("{} {}", num(value as f64), self.unit)
        }
    }
}

/// The percentage `to` is above `from`; `+∞ %` from zero.
fn change_pct(from: i64, to: i64) -> String {
    if from == 0 {
        if to == 0 { "+0.0 %" } else { "+∞ %" }.to_string()
    } else {
        format!("{:+.1} %", (to as f64 / from as f64 - 1.0) * 100.0)
    }
}

/// Whether `value` grew past `baseline × (1 + margin)`.
fn grew_past(value: i64, baseline: i64, margin: f64) -> bool {
    value as f64 > baseline as f64 * (1.0 + margin)
}

/// What a check found: figures that grew past their baseline by more than the
/// margin, and figures that differ from the file's values (the file is stale).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Mismatches {
    /// One line per figure over `baseline × (1 + margin)`.
    pub regressions: Vec<String>,
    /// One line per figure that differs from the blessed value.
    pub stale: Vec<String>,
}

impl Mismatches {
    /// Nothing grew and nothing changed.
    pub fn is_empty(&self) -> bool {
        self.regressions.is_empty() && self.stale.is_empty()
    }

    /// The failure message: what differs, by how much, and how to re-bless `file`
    /// deliberately.
    pub fn explain(&self, file: &Path, margin: f64) -> String {
        let mut s = String::new();
        if !self.regressions.is_empty() {
            s += &format!(
                "figures grew more than {:.1} % past their baseline in {}:\n  {}\n",
                margin * 100.0,
                file.display(),
                self.regressions.join("\n  ")
            );
        }
        if !self.stale.is_empty() {
            s += &format!(
                "figures differ from the values blessed in {}:\n  {}\n",
                file.display(),
                self.stale.join("\n  ")
            );
        }
        s += &format!(
            "If the change is deliberate, re-bless the file and commit its diff with the change: \
             `{BLESS_COMMAND}` (CI's PIL lap and report on the current ELF, then \
             `host-sim wcet --write-expected {}`)",
            file.display()
        );
        if !self.regressions.is_empty() {
            s += "; growth past the baseline needs a reason: \
                  `.ci/bless-expected --accept-growth \"why it grew\"`";
        }
        s
    }
}

fn parse_file(text: &str) -> Result<ExpectedFile, String> {
    serde_json::from_str(text).map_err(|e| {
        format!(
            "not an expected-values file written by `{BLESS_COMMAND}` (`host-sim wcet \
             --write-expected`): {e}. Re-bless it; to start a new baseline from the current \
             report, remove the file first"
        )
    })
}

fn check_margin(margin: f64) -> Result<(), String> {
    if margin.is_finite() && margin >= 0.0 {
        Ok(())
    } else {
        Err(format!(
            "the allowed growth margin must be a finite fraction ≥ 0 (e.g. 0.05), got {margin}"
        ))
    }
}

/// Compares `report` with an expected-values file's text: a regression for each
/// figure over `baseline × (1 + margin)`, a stale line for each figure that
/// differs from the blessed value. An error when the file or the margin is not
/// usable.
pub fn check_against_expected(
    report: &WcetReport,
    expected_json: &str,
    margin: f64,
) -> Result<Mismatches, String> {
    let report = serde_json::to_value(report)
        .map_err(|e| format!("cannot serialise the report for comparison: {e}"))?;
    check_value(&report, expected_json, margin)
}

/// [`check_against_expected`] on the report's JSON.
fn check_value(report: &Value, expected_json: &str, margin: f64) -> Result<Mismatches, String> {
    check_margin(margin)?;
    let file = parse_file(expected_json)?;
    let mut m = Mismatches::default();
    for c in checked() {
        let key = c.key();
        let Some(e) = file.quantities.iter().find(|e| e.key == key) else {
            m.stale.push(format!("{}: the file has no {key}", c.name));
            continue;
        };
        let value = match c.figure(report) {
            Ok(v) => v,
            Err(why) => {
                m.regressions.push(why);
                continue;
            }
        };
        if grew_past(value, e.baseline, margin) {
            m.regressions.push(if c.unit == "flag" {
                format!(
                    "{} became true ({key}){}",
                    c.name,
                    linked_symbols(report, c)
                )
            } else {
                format!(
                    "{} grew to {}, {} over its baseline {} ({key})",
                    c.name,
                    c.show(value),
                    change_pct(e.baseline, value),
                    c.show(e.baseline)
                )
            });
        } else if value != e.value {
            m.stale.push(format!(
                "{} is {}, blessed {} ({}) ({key})",
                c.name,
                c.show(value),
                c.show(e.value),
                change_pct(e.value, value)
            ));
        }
    }
    for e in &file.quantities {
        if !checked().any(|c| c.key() == e.key) {
            m.stale
                .push(format!("{}: no longer checked ({})", e.name, e.key));
        }
    }
    Ok(m)
}

/// For a flag that became true, the symbols that set it.
fn linked_symbols(report: &Value, c: &Checked) -> String {
    let list = format!("{}_symbols", c.pointer);
    report
        .pointer(&list)
        .map(|v| format!(": {v}"))
        .unwrap_or_default()
}

/// The text of the expected-values file for `report`, from the `previous` file's
/// text if there is one: each baseline lowered to the value when it fell, kept
/// when the value grew within `margin`, raised to the value with `accept_growth`
/// as the reason when it grew past it. An error, naming the quantities and how
/// to accept them, when one grew past the margin without a reason; or when the
/// report lacks a figure or the previous file is not one.
pub fn bless(
    report: &WcetReport,
    previous: Option<&str>,
    margin: f64,
    accept_growth: Option<&str>,
) -> Result<String, String> {
    let value = serde_json::to_value(report)
        .map_err(|e| format!("cannot serialise the report for the expected values: {e}"))?;
    bless_value(&value, previous, margin, accept_growth)
}

/// [`bless`] on the report's JSON.
fn bless_value(
    report: &Value,
    previous: Option<&str>,
    margin: f64,
    accept_growth: Option<&str>,
) -> Result<String, String> {
    check_margin(margin)?;
    if let Some(reason) = accept_growth {
        if reason.trim().is_empty() {
            return Err(
                "--accept-growth needs a reason (why the figures grew), not an empty one"
                    .to_string(),
            );
        }
    }
    let previous = previous.map(parse_file).transpose()?;
    let mut quantities = Vec::new();
    let mut refused = Vec::new();
    for c in checked() {
        let key = c.key();
        let value = c.figure(report)?;
        let before = previous
            .as_ref()
            .and_then(|p| p.quantities.iter().find(|e| e.key == key));
        let (baseline, accepted_growth) = match before {
            None => (value, None),
            Some(e) if value < e.baseline => (value, None),
            Some(e) if !grew_past(value, e.baseline, margin) => {
                (e.baseline, e.accepted_growth.clone())
            }
            Some(e) => match accept_growth {
                Some(reason) => (value, Some(reason.trim().to_string())),
                None => {
                    refused.push(format!(
                        "{}: {} → {} ({} over the baseline)",
                        c.name,
                        c.show(e.baseline),
                        c.show(value),
                        change_pct(e.baseline, value)
                    ));
                    (e.baseline, e.accepted_growth.clone())
                }
            },
        };
        quantities.push(ExpectedQuantity {
            key,
            name: c.name.to_string(),
            unit: c.unit.to_string(),
            value,
            baseline,
            accepted_growth,
        });
    }
    if !refused.is_empty() {
        return Err(format!(
            "grew more than {:.1} % past the baseline:\n  {}\nNot written. If the growth is \
             deliberate, say why: `{BLESS_COMMAND} --accept-growth \"why it grew\"` (recorded \
             in the file beside the new baseline)",
            margin * 100.0,
            refused.join("\n  ")
        ));
    }
    let file = ExpectedFile {
        about: format!(
            "Written by `{BLESS_COMMAND}` (`host-sim wcet --write-expected`); do not edit by \
             hand. CI (`host-sim wcet --expected`) fails when a figure differs from `value` \
             (re-bless, so the commit shows the change) or grew more than the margin past \
             `baseline` (a regression: re-bless with `--accept-growth REASON`). Blessing \
             lowers a baseline when its value falls and raises it only with a reason."
        ),
        quantities,
    };
    serde_json::to_string_pretty(&file)
        .map(|s| s + "\n")
        .map_err(|e| format!("cannot serialise the expected values: {e}"))
}

/// `host-sim wcet --expected FILE`: an error explaining what differs when the
/// report does not match the file.
pub fn check_file(report: &WcetReport, file: &Path, margin: f64) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(file).map_err(|e| {
        anyhow::anyhow!(
            "cannot read the expected values {} ({e}): write them with `{BLESS_COMMAND}`",
            file.display()
        )
    })?;
    let m = check_against_expected(report, &text, margin)
        .map_err(|e| anyhow::anyhow!("{}: {e}", file.display()))?;
    if !m.is_empty() {
        anyhow::bail!(
            "the report does not match the expected values:\n{}",
            m.explain(file, margin)
        );
    }
    println!(
        "the report matches {} (no figure past its baseline + {:.1} %)",
        file.display(),
        margin * 100.0
    );
    Ok(())
}

/// `host-sim wcet --write-expected FILE`: blesses `report` into `file`, from the
/// file already there if any.
pub fn write_file(
    report: &WcetReport,
    file: &Path,
    margin: f64,
    accept_growth: Option<&str>,
) -> anyhow::Result<()> {
    let previous = match std::fs::read_to_string(file) {
        Ok(text) => Some(text),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
        Err(e) => anyhow::bail!("cannot read {} ({e})", file.display()),
    };
    let text = bless(report, previous.as_deref(), margin, accept_growth)
        .map_err(|e| anyhow::anyhow!("{}: {e}", file.display()))?;
    if let Some(dir) = file.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .map_err(|e| anyhow::anyhow!("cannot create {} ({e})", dir.display()))?;
    }
    std::fs::write(file, text)
        .map_err(|e| anyhow::anyhow!("cannot write {} ({e})", file.display()))?;
    println!(
        "blessed {}{}",
        file.display(),
        if previous.is_some() {
            ""
        } else {
            " (new: every baseline is its value)"
        }
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    /// A report's JSON with every checked figure: `.text` 100,000 B, the rest
    /// below.
    fn report() -> Value {
        json!({
            "memory": {
                "text_bytes": 100_000, "rodata_bytes": 0, "data_bytes": 46_000,
                "bss_bytes": 2_000, "static_ram_bytes": 48_000, "flash_bytes": 146_424,
                "stack_bound_bytes": 8_000
            },
            "tasks": {
                "plan": {
                    "observed_max_instructions": 700_000.4,
                    "observed_warm_max_instructions": 420_000.0,
                    "static_bound_cycles": 14_600_000,
                    "job_static_bound_cycles": 14_500_000
                },
                "control": {
                    "observed_max_instructions": 1_480.0,
                    "static_bound_cycles": 130_000,
                    "job_static_bound_cycles": 4_990
                },
                "plan_window": {
                    "observed_max_instructions": 700_000.4,
                    "static_bound_cycles": 13_000_000
                }
            },
            "symbols": {
                "allocator": false, "soft_double": false,
                "allocator_symbols": [], "soft_double_symbols": []
            }
        })
    }

    fn set(v: &mut Value, pointer: &str, x: Value) -> Result<(), String> {
        let slot = v
            .pointer_mut(pointer)
            .ok_or_else(|| format!("the fixture has no {pointer}"))?;
        *slot = x;
        Ok(())
    }

    fn bless_of(v: &Value, previous: Option<&str>, accept: Option<&str>) -> Result<String, String> {
        bless_value(v, previous, 0.05, accept)
    }

    fn entry(file: &str, key: &str) -> Result<ExpectedQuantity, String> {
        parse_file(file)?
            .quantities
            .into_iter()
            .find(|e| e.key == key)
            .ok_or_else(|| format!("no {key} in {file}"))
    }

    #[test]
    fn a_blessed_file_holds_each_checked_figure_of_the_report() -> Result<(), String> {
        let file = bless_of(&report(), None, None)?;
        let parsed = parse_file(&file)?;
        let keys: Vec<&str> = parsed.quantities.iter().map(|e| e.key.as_str()).collect();
        assert_eq!(keys.len(), 18, "{keys:?}");
        assert_eq!(keys[0], "memory.text_bytes");
        assert!(keys.contains(&"symbols.soft_double"), "{keys:?}");
        let plan = entry(&file, "tasks.plan.observed_max_instructions")?;
        assert_eq!((plan.value, plan.baseline), (700_000, 700_000));
        assert_eq!(plan.accepted_growth, None);
        assert_eq!(entry(&file, "memory.stack_bound_bytes")?.value, 8_000);
        assert_eq!(entry(&file, "symbols.allocator")?.value, 0);
        // The check passes on the report it was blessed from.
        assert_eq!(check_value(&report(), &file, 0.05)?, Mismatches::default());
        Ok(())
    }

    #[test]
    fn any_changed_figure_makes_the_file_stale() -> Result<(), String> {
        let file = bless_of(&report(), None, None)?;
        for (pointer, x, name) in [
            (
                "/memory/stack_bound_bytes",
                json!(8_001),
                "stack bound is 8001 bytes, blessed 8000",
            ),
            (
                "/memory/text_bytes",
                json!(99_000),
                ".text is 99000 bytes, blessed 100000 bytes (-1.0 %)",
            ),
            (
                "/tasks/control/job_static_bound_cycles",
                json!(4_991),
                "control_job static bound is 4991 cycles",
            ),
        ] {
            let mut now = report();
            set(&mut now, pointer, x)?;
            let m = check_value(&now, &file, 0.05)?;
            assert!(m.regressions.is_empty(), "{m:?}");
            assert!(
                m.stale.len() == 1 && m.stale[0].contains(name),
                "{pointer}: {m:?}"
            );
            let message = m.explain(Path::new(".ci/expected/wcet.json"), 0.05);
            assert!(
                message.contains(BLESS_COMMAND) && !message.contains("--accept-growth"),
                "{message}"
            );
        }
        Ok(())
    }

    #[test]
    fn growth_past_the_margin_is_a_regression_that_says_by_how_much() -> Result<(), String> {
        let file = bless_of(&report(), None, None)?;
        let mut now = report();
        // .text 100,000 → 105,300 B: +5.3 %, over the 5 % allowed.
        set(&mut now, "/memory/text_bytes", json!(105_300))?;
        let m = check_value(&now, &file, 0.05)?;
        assert_eq!(m.stale, Vec::<String>::new());
        assert_eq!(
            m.regressions,
            vec![".text grew to 105300 bytes, +5.3 % over its baseline 100000 bytes (memory.text_bytes)"]
        );
        let message = m.explain(Path::new("F"), 0.05);
        assert!(message.contains("--accept-growth"), "{message}");
        // Within a 6 % margin it is only a change of the blessed value.
        let m = check_value(&now, &file, 0.06)?;
        assert!(m.regressions.is_empty() && m.stale.len() == 1, "{m:?}");
        Ok(())
    }

    #[test]
    fn a_symbol_flag_that_becomes_true_is_a_regression_naming_the_symbols() -> Result<(), String> {
        let file = bless_of(&report(), None, None)?;
        let mut now = report();
        set(&mut now, "/symbols/soft_double", json!(true))?;
        set(
            &mut now,
            "/symbols/soft_double_symbols",
            json!(["__aeabi_dmul"]),
        )?;
        let m = check_value(&now, &file, 0.05)?;
        assert!(
            m.regressions.len() == 1
                && m.regressions[0].starts_with("software double-precision linked became true")
                && m.regressions[0].contains("__aeabi_dmul"),
            "{m:?}"
        );
        let refused = bless_of(&now, Some(&file), None).err().unwrap_or_default();
        assert!(
            refused.contains("software double-precision") && refused.contains("--accept-growth"),
            "{refused}"
        );
        Ok(())
    }

    #[test]
    fn blessing_refuses_growth_past_the_baseline_without_a_reason() -> Result<(), String> {
        let first = bless_of(&report(), None, None)?;
        let mut grown = report();
        set(&mut grown, "/memory/stack_bound_bytes", json!(8_500))?;
        let refused = bless_of(&grown, Some(&first), None)
            .err()
            .unwrap_or_default();
        assert!(
            refused.contains("stack bound: 8000 bytes → 8500 bytes (+6.2 % over the baseline)")
                && refused.contains("--accept-growth"),
            "{refused}"
        );
        let accepted = bless_of(&grown, Some(&first), Some("a larger frame buffer"))?;
        let e = entry(&accepted, "memory.stack_bound_bytes")?;
        assert_eq!((e.value, e.baseline), (8_500, 8_500));
        assert_eq!(e.accepted_growth.as_deref(), Some("a larger frame buffer"));
        // Only the quantity that grew past the margin carries the reason.
        assert_eq!(entry(&accepted, "memory.text_bytes")?.accepted_growth, None);
        assert!(check_value(&grown, &accepted, 0.05)?.is_empty());
        let empty = bless_of(&grown, Some(&first), Some("  "))
            .err()
            .unwrap_or_default();
        assert!(empty.contains("needs a reason"), "{empty}");
        Ok(())
    }

    #[test]
    fn growth_in_small_blessed_steps_adds_up_against_the_baseline() -> Result<(), String> {
        // Three blesses of +2 % each: the first two stay within 5 % of the
        // baseline, the third (+6.1 % over it) is refused, and CI fails on it.
        let mut file = bless_of(&report(), None, None)?;
        let mut text = 100_000.0_f64;
        for step in 1..=3 {
            text *= 1.02;
            let mut now = report();
            set(&mut now, "/memory/text_bytes", json!(text.round()))?;
            match bless_of(&now, Some(&file), None) {
                Ok(next) if step < 3 => {
                    let e = entry(&next, "memory.text_bytes")?;
                    assert_eq!((e.value, e.baseline), (text.round() as i64, 100_000));
                    file = next;
                }
                Err(refused) if step == 3 => {
                    assert!(refused.contains("+6.1 % over the baseline"), "{refused}");
                    let m = check_value(&now, &file, 0.05)?;
                    assert_eq!(m.regressions.len(), 1, "{m:?}");
                }
                other => return Err(format!("step {step}: {other:?}")),
            }
        }
        Ok(())
    }

    #[test]
    fn a_fall_lowers_the_baseline_so_growth_back_counts_from_it() -> Result<(), String> {
        let first = bless_of(&report(), None, None)?;
        let mut shrunk = report();
        set(&mut shrunk, "/memory/text_bytes", json!(90_000))?;
        // A fall is no regression, but the file is stale until re-blessed.
        let m = check_value(&shrunk, &first, 0.05)?;
        assert!(m.regressions.is_empty() && m.stale.len() == 1, "{m:?}");
        let lowered = bless_of(&shrunk, Some(&first), None)?;
        let e = entry(&lowered, "memory.text_bytes")?;
        assert_eq!((e.value, e.baseline), (90_000, 90_000));
        // Back to 100,000 B: +11.1 % over the lowered baseline.
        let m = check_value(&report(), &lowered, 0.05)?;
        assert!(
            m.regressions.len() == 1 && m.regressions[0].contains("+11.1 %"),
            "{m:?}"
        );
        Ok(())
    }

    #[test]
    fn unusable_files_figures_and_margins_are_errors_that_say_what_to_do() -> Result<(), String> {
        let file = bless_of(&report(), None, None)?;
        let not_json = check_value(&report(), "{not json", 0.05)
            .err()
            .unwrap_or_default();
        assert!(not_json.contains(BLESS_COMMAND), "{not_json}");
        // A whole report is not an expected-values file (the format before this one).
        let whole = check_value(&report(), &report().to_string(), 0.05)
            .err()
            .unwrap_or_default();
        assert!(whole.contains("remove the file first"), "{whole}");
        let negative = check_value(&report(), &file, -0.1)
            .err()
            .unwrap_or_default();
        assert!(negative.contains("margin"), "{negative}");
        // A report without a warm activation has no warm maximum to compare.
        let mut cold = report();
        set(
            &mut cold,
            "/tasks/plan/observed_warm_max_instructions",
            Value::Null,
        )?;
        let m = check_value(&cold, &file, 0.05)?;
        assert!(
            m.regressions.len() == 1 && m.regressions[0].contains("no warm-started"),
            "{m:?}"
        );
        let refused = bless_of(&cold, None, None).err().unwrap_or_default();
        assert!(refused.contains("plan warm observed max"), "{refused}");
        // A quantity the file lacks, or one no longer checked, makes it stale.
        let mut parsed = parse_file(&file)?;
        parsed.quantities[0].key = "memory.gone_bytes".into();
        let edited = serde_json::to_string(&parsed).map_err(|e| e.to_string())?;
        let m = check_value(&report(), &edited, 0.05)?;
        assert!(
            m.stale
                .iter()
                .any(|s| s.contains("the file has no memory.text_bytes"))
                && m.stale.iter().any(|s| s.contains("no longer checked")),
            "{m:?}"
        );
        Ok(())
    }

    #[test]
    fn the_committed_file_is_one_this_check_reads_with_every_quantity() -> Result<(), String> {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../.ci/expected/wcet.json");
        let text =
            std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        let file = parse_file(&text)?;
        let keys: Vec<String> = file.quantities.iter().map(|e| e.key.clone()).collect();
        let wanted: Vec<String> = checked().map(Checked::key).collect();
        assert_eq!(
            keys,
            wanted,
            "re-bless {} with {BLESS_COMMAND}",
            path.display()
        );
        // Blessing keeps each value within the margin above its baseline (CI's
        // margin, the one `.ci/wcet-report` passes); a hand edit may not.
        for e in &file.quantities {
            assert!(
                e.baseline <= e.value && !grew_past(e.value, e.baseline, 0.05),
                "{e:?}: re-bless {} with {BLESS_COMMAND}",
                path.display()
            );
        }
        Ok(())
    }
}
