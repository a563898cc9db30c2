//! The plugin loader's header check (`flowlight_elf::check_bytes`, the entry point of the
//! libFuzzer target in `crates/flowlight-elf/fuzz`) over a corpus of mutated **real** plugin
//! files, so CI exercises it on stable Rust: a built `libflowlight_mcpt.so` cut at every
//! 64-byte boundary, and with random bytes flipped.
//!
//! Properties, each computed independently of the checker from the intact file's own
//! headers:
//!
//! * nothing panics;
//! * a truncation that cuts a `PT_LOAD` segment or the section header table (`dlopen` of
//!   such a file dies of `SIGBUS`) is refused, and the intact file is accepted;
//! * whatever is accepted after byte flips has every `PT_LOAD` file range inside the file.

use std::path::PathBuf;

const SYMBOL: &str = "flowlight_plugin_declaration";

/// A plugin the workspace builds beside the `flowlight` executable.
fn real_plugin() -> Vec<u8> {
    let dir = PathBuf::from(env!("CARGO_BIN_EXE_flowlight"))
        .parent()
        .unwrap()
        .to_path_buf();
    let path = dir.join("libflowlight_mcpt.so");
    std::fs::read(&path).unwrap_or_else(|e| {
        panic!(
            "{}: {e}; build the plugins first (cargo build -p flowlight-mcpt)",
            path.display()
        )
    })
}

fn u16_at(d: &[u8], o: usize) -> u64 {
    u16::from_le_bytes([d[o], d[o + 1]]) as u64
}
fn u32_at(d: &[u8], o: usize) -> u32 {
    u32::from_le_bytes(d[o..o + 4].try_into().unwrap())
}
fn u64_at(d: &[u8], o: usize) -> u64 {
    u64::from_le_bytes(d[o..o + 8].try_into().unwrap())
}

/// File ranges [offset, end) of the `PT_LOAD` segments, read without bounds checks beyond
/// what an intact file needs (only called on accepted or intact files).
fn load_segments(d: &[u8]) -> Vec<(u64, u64)> {
    let (phoff, phnum) = (u64_at(d, 32) as usize, u16_at(d, 56) as usize);
    (0..phnum)
        .map(|i| phoff + i * 56)
        .filter(|&h| u32_at(d, h) == 1)
        .map(|h| (u64_at(d, h + 8), u64_at(d, h + 8) + u64_at(d, h + 32)))
        .collect()
}

/// The least length a file must keep to be loadable: the ends of its loadable segments
/// and of its section header table.
fn needed_length(d: &[u8]) -> u64 {
    let (shoff, shnum) = (u64_at(d, 40), u16_at(d, 60));
    load_segments(d)
        .iter()
        .map(|&(_, end)| end)
        .chain([shoff + shnum * 64])
        .max()
        .unwrap()
}

#[test]
fn truncations_at_every_64_byte_boundary_are_refused() {
    let good = real_plugin();
    flowlight_elf::check_bytes(&good, SYMBOL).expect("the intact plugin is accepted");
    let needed = needed_length(&good);
    assert!(needed <= good.len() as u64 && needed > 64);
    let mut refused = 0;
    for n in (0..good.len()).step_by(64) {
        let r = flowlight_elf::check_bytes(&good[..n], SYMBOL);
        if (n as u64) < needed {
            let e = r.expect_err(&format!(
                "a cut at {n} of {} bytes was accepted",
                good.len()
            ));
            assert!(!e.0.is_empty());
            refused += 1;
        }
    }
    assert_eq!(refused, (needed as usize).div_ceil(64));
}

#[test]
fn flipped_bytes_never_panic_and_accepted_files_are_loadable() {
    let mut f = real_plugin();
    let len = f.len() as u64;
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let (mut accepted, mut refused) = (0u32, 0u32);
    for round in 0..3000 {
        // Half the rounds aim at the headers (where a flip changes the verdict), half
        // anywhere in the file. Flips are undone after each round: no copy of the file.
        let span = if round % 2 == 0 { 4096.min(len) } else { len };
        let flips: Vec<(usize, u8)> = (0..1 + next() % 4)
            .map(|_| ((next() % span) as usize, 1u8 << (next() % 8)))
            .collect();
        for &(at, bit) in &flips {
            f[at] ^= bit;
        }
        match flowlight_elf::check_bytes(&f, SYMBOL) {
            Ok(()) => {
                accepted += 1;
                for (start, end) in load_segments(&f) {
                    assert!(
                        start <= end && end <= len,
                        "segment {start}..{end} of {len}"
                    );
                }
            }
            Err(e) => {
                assert!(!e.0.is_empty());
                refused += 1;
            }
        }
        for &(at, bit) in flips.iter().rev() {
            f[at] ^= bit;
        }
    }
    // Both verdicts occur: the corpus does reach the checks (not all flips land in padding,
    // not all break the file).
    assert!(
        accepted > 0 && refused > 0,
        "{accepted} accepted, {refused} refused"
    );
}
