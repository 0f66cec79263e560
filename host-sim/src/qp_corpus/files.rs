//! The corpus on disk: `qp_0000.json`, `qp_0001.json`, … in solve order.

use std::path::{Path, PathBuf};

use anyhow::{ensure, Context, Result};

use crate::qp_corpus::entry::CorpusEntry;

/// Writes the corpus as `dir/qp_0000.json`, … (creating `dir`).
pub fn write_corpus(dir: &Path, entries: &[CorpusEntry]) -> Result<()> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create the output directory {}", dir.display()))?;
    for (k, e) in entries.iter().enumerate() {
        let path = dir.join(format!("qp_{k:04}.json"));
        let file = std::fs::File::create(&path)
            .with_context(|| format!("cannot create {}", path.display()))?;
        let mut w = std::io::BufWriter::new(file);
        serde_json::to_writer(&mut w, e)
            .with_context(|| format!("cannot write {}", path.display()))?;
        std::io::Write::flush(&mut w)
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}

/// Reads every `qp_*.json` of `dir`, in file-name order.
pub fn read_corpus(dir: &Path) -> Result<Vec<CorpusEntry>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("cannot read the corpus directory {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("qp_") && n.ends_with(".json"))
        })
        .collect();
    files.sort();
    ensure!(
        !files.is_empty(),
        "no qp_*.json in {} (write a corpus with `host-sim qp-corpus --out DIR`)",
        dir.display()
    );
    files
        .iter()
        .map(|p| {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("cannot read {}", p.display()))?;
            let e: CorpusEntry = serde_json::from_str(&text)
                .with_context(|| format!("{} is not a corpus QP", p.display()))?;
            e.native
                .check()
                .with_context(|| format!("in {}", p.display()))?;
            Ok(e)
        })
        .collect()
}
