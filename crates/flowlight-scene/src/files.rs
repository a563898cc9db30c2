//! Reading an input file whole, safely: only a regular file, and only when its size — known
//! before a byte is read — fits under a cap.
//!
//! `std::fs::read` of a name a scene or a config gives blocks forever on a FIFO (opening it
//! waits for a writer), and grows without end on `/dev/zero` or `/dev/urandom` (the OOM
//! killer ends it). Here the kind and size come from `metadata` first; the file is then
//! opened non-blocking (so a file swapped for a FIFO meanwhile cannot block the open either),
//! checked again on the open handle, and read through a `take` of the size it had, so a
//! file that grows while being read cannot grow the buffer past the cap.

use std::io::Read;
use std::path::Path;

/// Largest input file read whole by default: no scene buffer, texture or environment map a
/// renderer of this size takes is larger, and 16 GiB is far past what a 32-bit triangle
/// index can address anyway (4 Gi vertices of 4 bytes).
pub const MAX_INPUT_FILE_BYTES: u64 = 16 << 30;

/// `O_NONBLOCK` on Linux (x86-64 and AArch64 alike); ignored for regular files.
#[cfg(target_os = "linux")]
const O_NONBLOCK: i32 = 0o4000;

/// Reads `path` whole when it is a regular file (symbolic links followed) of at most
/// `max_bytes`, which is also capped by the memory this process may still allocate
/// ([`crate::memory::available_memory`]). The error says what the name is instead (a FIFO,
/// a device, a folder) or how large the file is against the cap.
pub fn read_regular_file(path: &Path, max_bytes: u64) -> std::io::Result<Vec<u8>> {
    let meta = std::fs::metadata(path)?;
    check_kind(&meta)?;
    let cap = crate::memory::available_memory().map_or(max_bytes, |m| m.min(max_bytes));
    let len = meta.len();
    if len > cap {
        return Err(std::io::Error::other(format!(
            "it is {len} bytes, beyond the {cap} bytes an input file may have here (the smaller of {max_bytes} and the memory available)"
        )));
    }
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(O_NONBLOCK);
    }
    let file = options.open(path)?;
    check_kind(&file.metadata()?)?;
    let mut data = Vec::with_capacity(len as usize);
    file.take(len).read_to_end(&mut data)?;
    Ok(data)
}

/// [`read_regular_file`] as UTF-8 text.
pub fn read_regular_text(path: &Path, max_bytes: u64) -> std::io::Result<String> {
    String::from_utf8(read_regular_file(path, max_bytes)?)
        .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidData, e.utf8_error()))
}

fn check_kind(meta: &std::fs::Metadata) -> std::io::Result<()> {
    if meta.is_file() {
        return Ok(());
    }
    let kind = kind_name(meta);
    Err(std::io::Error::other(format!(
        "it is {kind}, not a regular file"
    )))
}

fn kind_name(meta: &std::fs::Metadata) -> &'static str {
    let t = meta.file_type();
    if t.is_dir() {
        return "a folder";
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return "a FIFO (named pipe)";
        }
        if t.is_char_device() {
            return "a character device";
        }
        if t.is_block_device() {
            return "a block device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    "not a regular file"
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn d11_devices_folders_and_fifos_are_refused_without_reading() {
        let dir = std::env::temp_dir().join(format!("flowlight-files-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let zero = read_regular_file(Path::new("/dev/zero"), MAX_INPUT_FILE_BYTES).unwrap_err();
        assert!(zero.to_string().contains("character device"), "{zero}");
        let folder = read_regular_file(&dir, MAX_INPUT_FILE_BYTES).unwrap_err();
        assert!(folder.to_string().contains("folder"), "{folder}");
        let fifo = dir.join("pipe");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        if made.is_ok_and(|s| s.success()) {
            // Would block forever in `std::fs::read`.
            let e = read_regular_file(&fifo, MAX_INPUT_FILE_BYTES).unwrap_err();
            assert!(e.to_string().contains("FIFO"), "{e}");
        }
        let small = dir.join("small.bin");
        std::fs::write(&small, [1u8, 2, 3, 4, 5]).unwrap();
        assert_eq!(read_regular_file(&small, 5).unwrap(), vec![1, 2, 3, 4, 5]);
        let e = read_regular_file(&small, 4).unwrap_err();
        assert!(e.to_string().contains("5 bytes"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
