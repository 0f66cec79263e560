//! The CI comparison of a report with a committed `wcet.json`
//! (`.ci/expected/wcet.json`), in the manner of rtic's `ci/expected/*.size`: what
//! may not grow past a margin, and the symbols that may not appear.

use super::markdown::num;
use super::WcetReport;

/// The quantities [`check_against_expected`] compares: name, JSON pointer into
/// `wcet.json`, unit.
const CHECKED: [(&str, &str, &str); 10] = [
    (".text", "/memory/text_bytes", "bytes"),
    (".rodata", "/memory/rodata_bytes", "bytes"),
    (".data", "/memory/data_bytes", "bytes"),
    (".bss", "/memory/bss_bytes", "bytes"),
    ("static RAM", "/memory/static_ram_bytes", "bytes"),
    ("flash", "/memory/flash_bytes", "bytes"),
    ("stack bound", "/memory/stack_bound_bytes", "bytes"),
    (
        "plan observed max",
        "/tasks/plan/observed_max_instructions",
        "instructions",
    ),
    (
        "plan warm observed max",
        "/tasks/plan/observed_warm_max_instructions",
        "instructions",
    ),
    (
        "control observed max",
        "/tasks/control/observed_max_instructions",
        "instructions",
    ),
];

/// Compares `report` with a committed `wcet.json` (`expected_json`): one
/// human-readable failure per quantity that grew past `expected × (1 + margin)`
/// (section sizes, static RAM, flash, stack bound; plan, warm plan and control
/// observed maxima) and per symbol flag (`allocator`, `soft_double`) that became
/// true. Empty when all is well. `margin` is a fraction (0.05 = 5 %).
pub fn check_against_expected(
    report: &WcetReport,
    expected_json: &str,
    margin: f64,
) -> Vec<String> {
    if !(margin.is_finite() && margin >= 0.0) {
        return vec![format!(
            "the allowed growth margin must be a finite fraction ≥ 0 (e.g. 0.05), got {margin}"
        )];
    }
    let expected: serde_json::Value = match serde_json::from_str(expected_json) {
        Ok(v) => v,
        Err(e) => {
            return vec![format!(
                "the expected wcet.json is not valid JSON ({e}): regenerate it from a report"
            )]
        }
    };
    let actual = match serde_json::to_value(report) {
        Ok(v) => v,
        Err(e) => return vec![format!("cannot serialise the report for comparison: {e}")],
    };
    let mut failures = Vec::new();
    for (name, pointer, unit) in CHECKED {
        if let Some(f) = compare_quantity(&actual, &expected, name, pointer, unit, margin) {
            failures.push(f);
        }
    }
    for flag in ["allocator", "soft_double"] {
        let pointer = format!("/symbols/{flag}");
        let now = actual.pointer(&pointer).and_then(|v| v.as_bool()) == Some(true);
        let before = expected.pointer(&pointer).and_then(|v| v.as_bool()) == Some(true);
        if now && !before {
            failures.push(format!(
                "symbols.{flag} became true: the ECU binary now links {}",
                if flag == "allocator" {
                    format!("a heap allocator ({:?})", report.symbols.allocator_symbols)
                } else {
                    format!(
                        "software double-precision routines ({:?}): an f64 crept in",
                        report.symbols.soft_double_symbols
                    )
                }
            ));
        }
    }
    failures
}

fn compare_quantity(
    actual: &serde_json::Value,
    expected: &serde_json::Value,
    name: &str,
    pointer: &str,
    unit: &str,
    margin: f64,
) -> Option<String> {
    let key = pointer.trim_start_matches('/').replace('/', ".");
    let Some(limit) = expected.pointer(pointer).and_then(|v| v.as_f64()) else {
        return Some(format!(
            "{name}: the expected file has no number at {key}: regenerate it from a current report"
        ));
    };
    let Some(value) = actual.pointer(pointer).and_then(|v| v.as_f64()) else {
        return Some(format!(
            "{name}: this report has no value at {key} (expected {}) — e.g. no warm-started \
             plan activation in the PIL runs",
            num(limit)
        ));
    };
    let allowed = limit * (1.0 + margin);
    (value > allowed).then(|| {
        format!(
            "{name} grew to {} {unit}, expected {} (+{:.1} % allowed, up to {}): {:+.1} % ({key})",
            num(value.round()),
            num(limit.round()),
            margin * 100.0,
            num(allowed.round()),
            (value / limit - 1.0) * 100.0
        )
    })
}
