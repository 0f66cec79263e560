//! Source locations of the binary's addresses, from its DWARF line table: the
//! inlining chain of an address, and the frame in the target's own sources
//! ([`crate::target::Target::source_labels`]).

use crate::WcetError;
use std::path::Path;

/// The DWARF line table of an ELF and the source folders that are the target's.
pub struct SourceLines {
    loader: addr2line::Loader,
    labels: Vec<&'static str>,
}

impl SourceLines {
    /// Reads `elf`'s line table; `labels` are the target's source folders from
    /// the workspace root (`firmware/src`).
    pub fn new(elf: &Path, labels: &[&'static str]) -> Result<Self, WcetError> {
        let loader = addr2line::Loader::new(elf).map_err(|e| WcetError::Dwarf {
            path: elf.to_path_buf(),
            message: e.to_string(),
        })?;
        Ok(Self {
            loader,
            labels: labels.to_vec(),
        })
    }

    /// The workspace-relative path (`qp/src/factor.rs`) of a source file the
    /// DWARF line table names by its absolute path, if it is in one of the
    /// target's source folders.
    pub fn source_path<'f>(&self, file: &'f str) -> Option<&'f str> {
        source_path(&self.labels, file)
    }

    /// Every frame of `address`'s inlining chain, innermost first.
    pub fn frames(&self, address: u32) -> Vec<(String, u32)> {
        let mut out = Vec::new();
        if let Ok(mut fr) = self.loader.find_frames(u64::from(address)) {
            while let Ok(Some(frame)) = fr.next() {
                if let Some(loc) = frame.location {
                    out.push((loc.file.unwrap_or("?").to_string(), loc.line.unwrap_or(0)));
                }
            }
        }
        out
    }

    /// Source location of `address`: the innermost frame in the target's own
    /// sources if any, else the innermost frame.
    pub fn location(&self, address: u32) -> (String, u32) {
        let chain = self.frames(address);
        chain
            .iter()
            .find(|(file, _)| self.source_path(file).is_some())
            .or(chain.first())
            .cloned()
            .unwrap_or_else(|| ("?".into(), 0))
    }

    /// The source path from the workspace on (`firmware/src/mpc.rs`,
    /// `qp/src/factor.rs`), or the file name with its crate folder for a
    /// dependency.
    pub fn short_path(&self, file: &str) -> String {
        if let Some(p) = self.source_path(file) {
            return p.to_string();
        }
        // A crate from the registry: from its `name-version` folder on.
        if let Some(i) = file.find("/registry/src/") {
            if let Some((_, rest)) = file[i + "/registry/src/".len()..].split_once('/') {
                return rest.to_string();
            }
        }
        let parts: Vec<&str> = file.rsplit('/').take(3).collect();
        parts.into_iter().rev().collect::<Vec<_>>().join("/")
    }
}

/// The workspace-relative path of `file` if it is under one of `labels`.
pub fn source_path<'f>(labels: &[&str], file: &'f str) -> Option<&'f str> {
    labels.iter().find_map(|label| {
        let i = file.find(&format!("/{label}/"))?;
        file.get(i + 1..)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_source_path_starts_at_its_folder_and_a_registry_crate_is_none() {
        let labels = ["firmware/src", "qp/src"];
        assert_eq!(
            source_path(&labels, "/w/qp/src/factor.rs"),
            Some("qp/src/factor.rs")
        );
        assert_eq!(
            source_path(&labels, "/w/firmware/src/bin/ecu.rs"),
            Some("firmware/src/bin/ecu.rs")
        );
        assert_eq!(
            source_path(&labels, "/r/registry/src/i/qp-0.1.0/src/lib.rs"),
            None
        );
    }
}
