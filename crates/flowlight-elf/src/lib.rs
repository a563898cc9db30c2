//! Checks a shared library's ELF file before it is handed to the dynamic loader.
//!
//! `dlopen` maps every `PT_LOAD` segment of a library with `mmap` and then runs its
//! initialisers. A segment whose file range lies beyond the end of the file (a truncated
//! copy, an interrupted download) is mapped anyway; the first touch of a page past the end
//! raises `SIGBUS` and kills the process with no message. [`check_library`] reads the file
//! first and refuses it, with the reason, unless
//!
//! * it starts with the ELF magic `7f 45 4c 46`, is of this host's class (64-bit), byte
//!   order (little-endian), ELF version 1, type `ET_DYN` (a shared object) and machine
//!   (`EM_X86_64` = 62, `EM_AARCH64` = 183);
//! * the program header table lies inside the file and every `PT_LOAD` segment's file range
//!   `[p_offset, p_offset + p_filesz)` does too, with `p_filesz ≤ p_memsz`;
//! * the section header table lies inside the file, and so does every section's contents
//!   (except `SHT_NOBITS`, which has none);
//! * the dynamic symbol table (`SHT_DYNSYM`, with its string table from `sh_link`) defines
//!   the required symbol (`st_shndx ≠ SHN_UNDEF`).
//!
//! All offsets are checked with overflow-safe arithmetic, so any byte string gives `Ok` or
//! an [`ElfError`], never a panic (a fuzz target and a mutation test check this).
//!
//! # What this does not check (the trust boundary)
//!
//! A well-formed file is not a well-behaved one. Loading a library runs its code: its
//! initialisers, then whatever the host calls. Nothing here can tell whether that code is
//! correct or benign, and the file could change between this check and `dlopen`. Plugins
//! and the Embree library are trusted code the user chose; this check only turns the
//! common accidents (truncated, wrong architecture, not a plugin) into clear errors.
//!
//! Reference: *System V ABI*, ch. 4 "Object Files" and ch. 5 "Program Loading" (the
//! `Elf64_Ehdr`, `Elf64_Phdr`, `Elf64_Shdr` and `Elf64_Sym` layouts used below).

use std::fmt;
use std::path::Path;

/// Why a file is not a loadable shared library for this host.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ElfError(pub String);

impl fmt::Display for ElfError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for ElfError {}

fn err<T>(msg: impl Into<String>) -> Result<T, ElfError> {
    Err(ElfError(msg.into()))
}

const ET_DYN: u16 = 3;
const PT_LOAD: u32 = 1;
const SHT_DYNSYM: u32 = 11;
const SHT_NOBITS: u32 = 8;
const SHN_UNDEF: u16 = 0;
const EHDR_SIZE: usize = 64;
const PHDR_SIZE: usize = 56;
const SHDR_SIZE: usize = 64;
const SYM_SIZE: usize = 24;

/// The `e_machine` this process runs on, or `None` where it is not known here.
pub fn host_machine() -> Option<u16> {
    if cfg!(target_arch = "x86_64") {
        Some(62)
    } else if cfg!(target_arch = "aarch64") {
        Some(183)
    } else {
        None
    }
}

fn machine_name(m: u16) -> String {
    match m {
        3 => "x86 (32-bit)".into(),
        40 => "ARM (32-bit)".into(),
        62 => "x86-64".into(),
        183 => "AArch64".into(),
        243 => "RISC-V".into(),
        m => format!("machine {m}"),
    }
}

/// Little-endian reads with bounds checks.
struct Bytes<'a>(&'a [u8]);

impl Bytes<'_> {
    fn slice(&self, off: u64, len: u64) -> Option<&[u8]> {
        let start = usize::try_from(off).ok()?;
        let end = start.checked_add(usize::try_from(len).ok()?)?;
        self.0.get(start..end)
    }
    fn u16(&self, off: u64) -> Option<u16> {
        self.slice(off, 2).map(|b| u16::from_le_bytes([b[0], b[1]]))
    }
    fn u32(&self, off: u64) -> Option<u32> {
        self.slice(off, 4)
            .map(|b| u32::from_le_bytes(b.try_into().unwrap()))
    }
    fn u64(&self, off: u64) -> Option<u64> {
        self.slice(off, 8)
            .map(|b| u64::from_le_bytes(b.try_into().unwrap()))
    }
}

/// `[off, off + len)` lies inside a file of `size` bytes (no overflow).
fn inside(off: u64, len: u64, size: u64) -> bool {
    off.checked_add(len).is_some_and(|end| end <= size)
}

struct Section {
    kind: u32,
    offset: u64,
    size: u64,
    link: u32,
    entsize: u64,
}

/// Checks the bytes of a shared library (see the module documentation) and that its dynamic
/// symbol table defines `symbol`.
pub fn check_bytes(data: &[u8], symbol: &str) -> Result<(), ElfError> {
    let b = Bytes(data);
    let size = data.len() as u64;
    if data.len() < 4 || data[..4] != [0x7f, b'E', b'L', b'F'] {
        return err(format!(
            "not an ELF file (no ELF magic in its first 4 of {size} bytes)"
        ));
    }
    if data.len() < EHDR_SIZE {
        return err(format!(
            "truncated: {size} bytes, shorter than the 64-byte ELF header"
        ));
    }
    if data[4] != 2 {
        return err(format!(
            "ELF class {} ({}), this host needs 64-bit",
            data[4],
            if data[4] == 1 { "32-bit" } else { "invalid" }
        ));
    }
    if data[5] != 1 {
        return err(format!(
            "ELF byte order {} ({}), this host needs little-endian",
            data[5],
            if data[5] == 2 {
                "big-endian"
            } else {
                "invalid"
            }
        ));
    }
    if data[6] != 1 {
        return err(format!("ELF version {} (expected 1)", data[6]));
    }
    let e_type = b.u16(16).unwrap();
    if e_type != ET_DYN {
        return err(format!(
            "ELF type {e_type} ({}), not a shared library (ET_DYN)",
            match e_type {
                1 => "relocatable object",
                2 => "executable",
                4 => "core dump",
                _ => "unknown",
            }
        ));
    }
    let machine = b.u16(18).unwrap();
    if let Some(host) = host_machine() {
        if machine != host {
            return err(format!(
                "built for {}, this host is {}",
                machine_name(machine),
                machine_name(host)
            ));
        }
    }
    let phoff = b.u64(32).unwrap();
    let shoff = b.u64(40).unwrap();
    let phentsize = b.u16(54).unwrap() as u64;
    let phnum = b.u16(56).unwrap() as u64;
    let shentsize = b.u16(58).unwrap() as u64;
    let shnum = b.u16(60).unwrap() as u64;

    // Program headers: the segments dlopen maps.
    if phnum == 0 {
        return err("no program headers: nothing to load");
    }
    if phentsize != PHDR_SIZE as u64 {
        return err(format!(
            "program header entry size {phentsize} (expected {PHDR_SIZE})"
        ));
    }
    if !inside(phoff, phnum * phentsize, size) {
        return err(format!(
            "truncated: the program header table (offset {phoff}, {phnum} entries) ends past the file's {size} bytes"
        ));
    }
    let mut loads = 0;
    for i in 0..phnum {
        let h = phoff + i * phentsize;
        if b.u32(h) != Some(PT_LOAD) {
            continue;
        }
        loads += 1;
        let offset = b.u64(h + 8).unwrap();
        let filesz = b.u64(h + 32).unwrap();
        let memsz = b.u64(h + 40).unwrap();
        if !inside(offset, filesz, size) {
            return err(format!(
                "truncated: loadable segment {i} needs bytes {offset}..{} but the file has {size}",
                offset.saturating_add(filesz)
            ));
        }
        if filesz > memsz {
            return err(format!(
                "loadable segment {i} has {filesz} bytes in the file but {memsz} in memory"
            ));
        }
    }
    if loads == 0 {
        return err("no loadable (PT_LOAD) segment");
    }

    // Section headers: where the dynamic symbol table is.
    if shnum == 0 || shoff == 0 {
        return err("no section headers: cannot look up the symbol table");
    }
    if shentsize != SHDR_SIZE as u64 {
        return err(format!(
            "section header entry size {shentsize} (expected {SHDR_SIZE})"
        ));
    }
    if !inside(shoff, shnum * shentsize, size) {
        return err(format!(
            "truncated: the section header table (offset {shoff}, {shnum} entries) ends past the file's {size} bytes"
        ));
    }
    let sections: Vec<Section> = (0..shnum)
        .map(|i| {
            let h = shoff + i * shentsize;
            Section {
                kind: b.u32(h + 4).unwrap(),
                offset: b.u64(h + 24).unwrap(),
                size: b.u64(h + 32).unwrap(),
                link: b.u32(h + 40).unwrap(),
                entsize: b.u64(h + 56).unwrap(),
            }
        })
        .collect();
    for (i, s) in sections.iter().enumerate() {
        if s.kind != SHT_NOBITS && s.kind != 0 && !inside(s.offset, s.size, size) {
            return err(format!(
                "truncated: section {i} needs bytes {}..{} but the file has {size}",
                s.offset,
                s.offset.saturating_add(s.size)
            ));
        }
    }
    let Some(dynsym) = sections.iter().find(|s| s.kind == SHT_DYNSYM) else {
        return err("no dynamic symbol table (.dynsym): it exports nothing");
    };
    if dynsym.entsize != SYM_SIZE as u64 {
        return err(format!(
            "dynamic symbol entry size {} (expected {SYM_SIZE})",
            dynsym.entsize
        ));
    }
    let Some(strtab) = sections.get(dynsym.link as usize) else {
        return err(format!(
            "the dynamic symbol table links to string table {}, which does not exist",
            dynsym.link
        ));
    };
    let strings = b
        .slice(strtab.offset, strtab.size)
        .ok_or_else(|| ElfError("the dynamic string table lies outside the file".into()))?;
    let want = symbol.as_bytes();
    for k in 0..dynsym.size / SYM_SIZE as u64 {
        let s = dynsym.offset + k * SYM_SIZE as u64;
        let name_off = b.u32(s).unwrap() as usize;
        let shndx = b.u16(s + 6).unwrap();
        let Some(rest) = strings.get(name_off..) else {
            continue;
        };
        let name = rest.split(|&c| c == 0).next().unwrap_or_default();
        if name == want && shndx != SHN_UNDEF {
            return Ok(());
        }
    }
    err(format!("does not export `{symbol}`"))
}

/// Largest library file read for the check: Embree's own is about 20 MB, a plugin a few.
pub const MAX_LIBRARY_BYTES: u64 = 1 << 30;

/// The bytes of the library at `path`: only a regular file (a FIFO named like a plugin would
/// block the read forever, a device would never end it) of at most [`MAX_LIBRARY_BYTES`].
fn read_library(path: &Path) -> Result<Vec<u8>, ElfError> {
    use std::io::Read;
    let meta = std::fs::metadata(path).map_err(|e| ElfError(format!("cannot read: {e}")))?;
    if !meta.is_file() {
        return Err(ElfError(
            "not a regular file (a FIFO, a device or a folder): cannot be a library".into(),
        ));
    }
    if meta.len() > MAX_LIBRARY_BYTES {
        return Err(ElfError(format!(
            "{} bytes, beyond the {MAX_LIBRARY_BYTES} a library may have",
            meta.len()
        )));
    }
    let file = std::fs::File::open(path).map_err(|e| ElfError(format!("cannot read: {e}")))?;
    let mut data = Vec::with_capacity(meta.len() as usize);
    file.take(meta.len())
        .read_to_end(&mut data)
        .map_err(|e| ElfError(format!("cannot read: {e}")))?;
    Ok(data)
}

/// Reads the file at `path` and checks it with [`check_bytes`]. The message names the cause
/// but not the file (callers prefix it). On platforms whose libraries are not ELF, only that
/// the file can be read is checked.
pub fn check_library(path: &Path, symbol: &str) -> Result<(), ElfError> {
    let data = read_library(path)?;
    if cfg!(target_os = "linux")
        && cfg!(target_endian = "little")
        && cfg!(target_pointer_width = "64")
    {
        check_bytes(&data, symbol)
    } else {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A minimal shared object: ELF header, one PT_LOAD covering the whole file, sections
    /// [null, .dynstr, .dynsym] whose one symbol is `sym` (defined in section 1 when
    /// `defined`).
    pub(crate) fn tiny_so(sym: &str, defined: bool) -> Vec<u8> {
        let strtab: Vec<u8> = [&[0u8][..], sym.as_bytes(), &[0]].concat();
        let str_off = 64 + 56;
        let sym_off = str_off + strtab.len();
        let sh_off = sym_off + 2 * SYM_SIZE;
        let total = sh_off + 3 * SHDR_SIZE;
        let mut f = vec![0u8; total];
        f[..4].copy_from_slice(b"\x7fELF");
        f[4] = 2;
        f[5] = 1;
        f[6] = 1;
        f[16..18].copy_from_slice(&ET_DYN.to_le_bytes());
        f[18..20].copy_from_slice(&host_machine().unwrap_or(62).to_le_bytes());
        f[20..24].copy_from_slice(&1u32.to_le_bytes());
        f[32..40].copy_from_slice(&64u64.to_le_bytes());
        f[40..48].copy_from_slice(&(sh_off as u64).to_le_bytes());
        f[52..54].copy_from_slice(&64u16.to_le_bytes());
        f[54..56].copy_from_slice(&56u16.to_le_bytes());
        f[56..58].copy_from_slice(&1u16.to_le_bytes());
        f[58..60].copy_from_slice(&64u16.to_le_bytes());
        f[60..62].copy_from_slice(&3u16.to_le_bytes());
        // PT_LOAD: whole file.
        let p = 64;
        f[p..p + 4].copy_from_slice(&PT_LOAD.to_le_bytes());
        f[p + 32..p + 40].copy_from_slice(&(total as u64).to_le_bytes());
        f[p + 40..p + 48].copy_from_slice(&(total as u64).to_le_bytes());
        f[str_off..str_off + strtab.len()].copy_from_slice(&strtab);
        // Symbol 1 (symbol 0 is the null symbol).
        let s = sym_off + SYM_SIZE;
        f[s..s + 4].copy_from_slice(&1u32.to_le_bytes());
        f[s + 6..s + 8].copy_from_slice(&(defined as u16).to_le_bytes());
        let sh =
            |f: &mut Vec<u8>, i: usize, kind: u32, off: usize, size: usize, link: u32, ent: u64| {
                let h = sh_off + i * SHDR_SIZE;
                f[h + 4..h + 8].copy_from_slice(&kind.to_le_bytes());
                f[h + 24..h + 32].copy_from_slice(&(off as u64).to_le_bytes());
                f[h + 32..h + 40].copy_from_slice(&(size as u64).to_le_bytes());
                f[h + 40..h + 44].copy_from_slice(&link.to_le_bytes());
                f[h + 56..h + 64].copy_from_slice(&ent.to_le_bytes());
            };
        sh(&mut f, 1, 3, str_off, strtab.len(), 0, 0);
        sh(
            &mut f,
            2,
            SHT_DYNSYM,
            sym_off,
            2 * SYM_SIZE,
            1,
            SYM_SIZE as u64,
        );
        f
    }

    #[test]
    fn a_well_formed_library_with_the_symbol_passes() {
        let f = tiny_so("flowlight_plugin_declaration", true);
        assert_eq!(check_bytes(&f, "flowlight_plugin_declaration"), Ok(()));
    }

    #[test]
    fn each_defect_is_named() {
        let good = tiny_so("flowlight_plugin_declaration", true);
        let sym = "flowlight_plugin_declaration";
        let patch = |at: usize, bytes: &[u8]| {
            let mut f = good.clone();
            f[at..at + bytes.len()].copy_from_slice(bytes);
            f
        };
        let cases: Vec<(&str, Vec<u8>, &str)> = vec![
            ("empty", Vec::new(), "not an ELF file"),
            ("text", b"#!/bin/sh\necho hi\n".to_vec(), "not an ELF file"),
            (
                "header cut",
                good[..40].to_vec(),
                "shorter than the 64-byte ELF header",
            ),
            ("32-bit", patch(4, &[1]), "32-bit"),
            ("big-endian", patch(5, &[2]), "big-endian"),
            (
                "executable",
                patch(16, &2u16.to_le_bytes()),
                "not a shared library",
            ),
            (
                "other machine",
                patch(18, &243u16.to_le_bytes()),
                "built for RISC-V",
            ),
            (
                "truncated",
                good[..good.len() - 1].to_vec(),
                "truncated: loadable segment 0",
            ),
            ("undefined symbol", tiny_so(sym, false), "does not export"),
            (
                "other symbol",
                tiny_so("something_else", true),
                "does not export",
            ),
        ];
        for (what, bytes, expected) in cases {
            let e = check_bytes(&bytes, sym).expect_err(what);
            assert!(e.0.contains(expected), "{what}: {e}");
        }
    }

    #[test]
    fn section_table_past_the_end_is_refused() {
        let mut f = tiny_so("x", true);
        // A PT_LOAD covering only the headers, and the file cut inside the section table.
        f[64 + 32..64 + 40].copy_from_slice(&64u64.to_le_bytes());
        f[64 + 40..64 + 48].copy_from_slice(&64u64.to_le_bytes());
        let n = f.len() - 10;
        let e = check_bytes(&f[..n], "x").unwrap_err();
        assert!(e.0.contains("section header table"), "{e}");
    }

    /// Mutation fuzzing in CI (the `fuzz/` target beside this crate does the same with libFuzzer): flipped
    /// bytes, overwritten words and truncations of a valid file never panic, and whatever is
    /// accepted has its loadable segments inside the file.
    #[test]
    fn mutated_files_never_panic() {
        let good = tiny_so("flowlight_plugin_declaration", true);
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for _ in 0..20_000 {
            let mut f = good.clone();
            for _ in 0..1 + next() % 4 {
                let at = (next() % f.len() as u64) as usize;
                match next() % 3 {
                    0 => f[at] ^= 1 << (next() % 8),
                    1 => {
                        let v = next().to_le_bytes();
                        let n = (f.len() - at).min(8);
                        f[at..at + n].copy_from_slice(&v[..n]);
                    }
                    _ => f.truncate(at),
                }
                if f.is_empty() {
                    break;
                }
            }
            if check_bytes(&f, "flowlight_plugin_declaration").is_ok() {
                let b = Bytes(&f);
                let (phoff, phnum) = (b.u64(32).unwrap(), b.u16(56).unwrap() as u64);
                for i in 0..phnum {
                    let h = phoff + i * 56;
                    if b.u32(h) == Some(PT_LOAD) {
                        assert!(inside(
                            b.u64(h + 8).unwrap(),
                            b.u64(h + 32).unwrap(),
                            f.len() as u64
                        ));
                    }
                }
            }
        }
    }

    #[test]
    fn this_test_binary_is_checked_like_a_library() {
        // The test executable is ELF but (usually) ET_DYN as a PIE; it exports no plugin
        // declaration either way.
        let exe = std::env::current_exe().unwrap();
        let e = check_library(&exe, "flowlight_plugin_declaration").unwrap_err();
        assert!(
            e.0.contains("does not export") || e.0.contains("not a shared library"),
            "{e}"
        );
    }
}
