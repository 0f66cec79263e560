//! Writing the report: `wcet.json` and its human-readable companion `wcet.md`
//! (goals with verdicts, task timing, memory, stack, runs).

use super::goals::Goal;
use super::WcetReport;
use anyhow::{Context, Result};
use std::fmt::Write as _;
use std::path::Path;

/// Writes `wcet.json` and `wcet.md` into `dir` (created if missing).
pub fn write_report(dir: &Path, r: &WcetReport) -> Result<()> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create the report folder {}", dir.display()))?;
    let json = serde_json::to_string_pretty(r).context("cannot serialise the report")?;
    let path = dir.join("wcet.json");
    std::fs::write(&path, json + "\n")
        .with_context(|| format!("cannot write {}", path.display()))?;
    let markdown = render_markdown(r).context("cannot format wcet.md")?;
    let path = dir.join("wcet.md");
    std::fs::write(&path, markdown).with_context(|| format!("cannot write {}", path.display()))?;
    Ok(())
}

/// `met (12.5 % below)` or `MISSED by 3 bytes (+0.4 %)`.
fn goal_verdict(g: &Goal) -> String {
    let Some(value) = g.value else {
        return "**MISSED**: no value (nothing measured, or no bound within the limit)".to_string();
    };
    let relative = |d: f64| {
        if g.goal > 0.0 {
            format!(" ({:+.1} %)", d / g.goal * 100.0)
        } else {
            String::new()
        }
    };
    if g.met {
        format!(
            "met, {} {} to spare{}",
            num(g.goal - value),
            g.unit,
            relative(value - g.goal)
        )
    } else {
        format!(
            "**MISSED** by {} {}{}",
            num(value - g.goal),
            g.unit,
            relative(value - g.goal)
        )
    }
}

/// A number without a fractional part if it has none, else with 2 decimals.
pub(super) fn num(v: f64) -> String {
    if v.fract() == 0.0 && v.abs() < 1e15 {
        format!("{v:.0}")
    } else {
        format!("{v:.2}")
    }
}

fn opt_num(v: Option<f64>) -> String {
    v.map_or_else(|| "—".to_string(), num)
}

fn render_markdown(r: &WcetReport) -> Result<String, std::fmt::Error> {
    let mut s = String::new();
    writeln!(s, "# Worst-case timing and memory of the ECU\n")?;
    writeln!(
        s,
        "ELF `{}`, clock {} MHz. Static bounds from the binary (`static.md` beside \
         this file: control-flow graphs, loop bounds, IPET, the processor and memory \
         model); observations from the PIL runs.\n",
        r.elf,
        num(r.clock_hz as f64 / 1e6),
    )?;
    writeln!(
        s,
        "Core clock {} MHz from {}, set by `{}`; on QEMU's netduinoplus2 (no RCC: it reads 0) \
         the set-up returns {}, the machine's fixed clock.\n",
        num(r.clock.sysclk_hz as f64 / 1e6),
        r.clock.source,
        r.clock
            .configured_in
            .as_deref()
            .unwrap_or("no function of the ELF"),
        r.clock.in_qemu,
    )?;
    render_goals(&mut s, r)?;
    render_tasks(&mut s, r)?;
    render_memory(&mut s, r)?;
    render_stack(&mut s, r)?;
    render_runs(&mut s, r)?;
    writeln!(
        s,
        "## Cycles per instruction of the traced run\n\n{:.3} cycles/instruction over the \
         traced code: an average for information, not a bound. {}",
        r.traced_cycles_per_instruction, r.traced_cpi_method
    )?;
    Ok(s)
}

fn render_goals(s: &mut String, r: &WcetReport) -> std::fmt::Result {
    writeln!(
        s,
        "## Goals\n\n| goal | value | at most | verdict |\n|---|---:|---:|---|"
    )?;
    for g in &r.goals {
        writeln!(
            s,
            "| {} | {} | {} {} | {} |",
            g.name,
            opt_num(g.value),
            num(g.goal),
            g.unit,
            goal_verdict(g)
        )?;
    }
    writeln!(s)
}

fn render_tasks(s: &mut String, r: &WcetReport) -> std::fmt::Result {
    writeln!(
        s,
        "## Tasks\n\nObserved: instructions on the ECU in the PIL runs. Static: the IPET \
         bound of the whole task and of its job (the part the budget limits), in cycles of \
         the stated model; response time bound against the deadline; tightness = static \
         bound / largest traced activation in the same cycles.\n"
    )?;
    writeln!(
        s,
        "| task | observed p50 | observed max | warm max | cold max | static bound (instr.) | \
         static bound (cycles) | job bound (cycles) | budget (cycles) | response time bound (µs) | \
         deadline (µs) | tightness |"
    )?;
    writeln!(
        s,
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    )?;
    let opt_u = |v: Option<u64>| opt_num(v.map(|v| v as f64));
    for (name, t) in [("plan", &r.tasks.plan), ("control", &r.tasks.control)] {
        let st = &t.statics;
        writeln!(
            s,
            "| {name} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            num(t.observed_p50_instructions.round()),
            num(t.observed_max_instructions.round()),
            opt_num(t.observed_warm_max_instructions.map(f64::round)),
            opt_num(t.observed_cold_max_instructions.map(f64::round)),
            opt_u(st.static_bound_instructions),
            opt_u(st.static_bound_cycles),
            opt_u(st.job_static_bound_cycles),
            num(t.budget_cycles.round()),
            st.response_time_bound_us
                .map_or_else(|| "none within".to_string(), |v| format!("{v:.0}")),
            opt_num(st.deadline_us),
            opt_num(st.tightness),
        )?;
    }
    let w = &r.tasks.plan_window;
    writeln!(
        s,
        "\nA plan activation adopts a new window of the road instead of planning: \
         observed max {} instructions, static bound (`ecu::window_job`) {} cycles against the \
         plan budget {} (the plan task's bound and response time are the larger of planning \
         and adopting). Loops: {} reached, {} without a bound; unresolved indirect calls {}, \
         recursions {}.\n",
        num(w.observed_max_instructions.round()),
        opt_u(w.static_bound_cycles),
        num(w.budget_cycles.round()),
        r.coverage.loops.len(),
        r.coverage.unbounded_loops,
        r.coverage.unresolved_indirect_calls.len(),
        r.coverage.recursions.len(),
    )
}

fn render_memory(s: &mut String, r: &WcetReport) -> std::fmt::Result {
    let m = &r.memory;
    writeln!(s, "## Memory\n\n| quantity | bytes |\n|---|---:|")?;
    let e = &m.sections;
    let rows = [
        (".vector_table", e.vector_table_bytes),
        (".text", e.text_bytes),
        (".rodata", e.rodata_bytes),
        (".data", e.data_bytes),
        (".bss (incl. .uninit)", e.bss_bytes),
        ("  of which .uninit", e.uninit_bytes),
        (
            "**flash** (vector table + text + rodata + data)",
            m.flash_bytes,
        ),
        ("**static RAM** (data + bss + uninit)", m.static_ram_bytes),
        ("**stack bound** (static)", m.stack_bound_bytes),
        (
            "stack high-water mark (painted, PIL runs)",
            m.stack_high_water_bytes,
        ),
        ("stack region", m.stack_size_bytes),
    ];
    for (name, bytes) in rows {
        writeln!(s, "| {name} | {bytes} |")?;
    }
    writeln!(
        s,
        "\nSymbols: allocator {} {:?}; software double precision {} {:?}.\n",
        if r.symbols.allocator {
            "**linked**"
        } else {
            "absent"
        },
        r.symbols.allocator_symbols,
        if r.symbols.soft_double {
            "**linked**"
        } else {
            "absent"
        },
        r.symbols.soft_double_symbols
    )?;
    match r.caps {
        Some(c) => writeln!(
            s,
            "Caps the binary was built with (its `.ecu_caps` section): {} QP iterations, {} cold-start pass(es), {} refactorization(s) per plan activation, a working set of {} rows.\n",
            c.qp_max_iterations, c.cold_start_passes, c.qp_max_refactorizations, c.working_set
        ),
        None => writeln!(s, "Caps: the ELF has no `.ecu_caps` section.\n"),
    }
}

fn render_stack(s: &mut String, r: &WcetReport) -> std::fmt::Result {
    writeln!(
        s,
        "## Stack bound: {} B ({})\n",
        r.memory.stack_bound_bytes,
        if r.memory.stack_sound {
            "sound"
        } else {
            "not sound: see what it misses"
        }
    )?;
    writeln!(
        s,
        "| level | counted | deepest root | depth (B) | exception entry (B) | worst path |"
    )?;
    writeln!(s, "|---|---|---|---:|---:|---|")?;
    for level in &r.stack.levels {
        let deepest = level.roots.iter().max_by_key(|root| root.depth_bytes);
        let (root, depth, path) = deepest.map_or((String::new(), 0, String::new()), |root| {
            let path: Vec<String> = root
                .worst_path
                .iter()
                .map(|e| format!("`{}` ({} B)", e.function, e.frame_bytes))
                .collect();
            (root.root.clone(), root.depth_bytes, path.join(" → "))
        });
        writeln!(
            s,
            "| {} | {} | {root} | {depth} | {} | {path} |",
            level.name,
            level.counted.label(),
            level.exception_frame_bytes
        )?;
    }
    writeln!(
        s,
        "\nRoots (`memory.stack_roots`):\n\n| root | function | vector-table entries | counted | depth (B) |\n|---|---|---|---|---:|"
    )?;
    for root in &r.memory.stack_roots {
        writeln!(
            s,
            "| {} | `{}` | {} | {} | {} |",
            root.name,
            root.symbol,
            compact_exceptions(&root.exceptions),
            root.counted.label(),
            root.depth_bytes
        )?;
    }
    writeln!(s, "\n{}\n", r.memory.stack_method)?;
    if !r.memory.stack_misses.is_empty() {
        writeln!(s, "Not in the bound ({}):\n", r.memory.stack_misses.len())?;
        for miss in &r.memory.stack_misses {
            writeln!(s, "- `{miss}`")?;
        }
        writeln!(s)?;
    }
    Ok(())
}

/// Exception names with runs of consecutive interrupts joined: `SVCall, IRQ 0–36,
/// IRQ 39`; `—` for none.
fn compact_exceptions(names: &[String]) -> String {
    let irq = |n: &String| n.strip_prefix("IRQ ").and_then(|k| k.parse::<u32>().ok());
    let mut out: Vec<String> = Vec::new();
    let mut run: Option<(u32, u32)> = None;
    let close = |run: &mut Option<(u32, u32)>, out: &mut Vec<String>| match run.take() {
        Some((a, b)) if a == b => out.push(format!("IRQ {a}")),
        Some((a, b)) => out.push(format!("IRQ {a}–{b}")),
        None => {}
    };
    for name in names {
        match (irq(name), run) {
            (Some(k), Some((a, b))) if k == b + 1 => run = Some((a, k)),
            (Some(k), _) => {
                close(&mut run, &mut out);
                run = Some((k, k));
            }
            (None, _) => {
                close(&mut run, &mut out);
                out.push(name.clone());
            }
        }
    }
    close(&mut run, &mut out);
    if out.is_empty() {
        "—".to_string()
    } else {
        out.join(", ")
    }
}

fn render_runs(s: &mut String, r: &WcetReport) -> std::fmt::Result {
    writeln!(
        s,
        "## PIL runs\n\n| folder | completed | plan activations | plan failures | \
         plan misses | control misses | stack high water (B) |\n|---|---|---:|---:|---:|---:|---:|"
    )?;
    for run in &r.runs {
        writeln!(
            s,
            "| `{}` | {} | {} | {} | {} | {} | {} |",
            run.dir,
            if run.completed { "yes" } else { "**no**" },
            run.plan_activations,
            run.plan_failures,
            run.plan_deadline_misses,
            run.control_deadline_misses,
            run.stack_high_water_bytes
        )?;
    }
    writeln!(s)
}
