//! Any byte string given to the plugin loader's ELF check yields `Ok` or an error, never a
//! panic, and a file it accepts has every loadable segment inside it.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if flowlight_elf::check_bytes(data, "flowlight_plugin_declaration").is_ok() {
        let u16_at = |o: usize| u16::from_le_bytes([data[o], data[o + 1]]) as u64;
        let u64_at = |o: usize| u64::from_le_bytes(data[o..o + 8].try_into().unwrap());
        let (phoff, phnum) = (u64_at(32), u16_at(56));
        for i in 0..phnum {
            let h = (phoff + i * 56) as usize;
            if data[h..h + 4] == [1, 0, 0, 0] {
                let end = u64_at(h + 8).checked_add(u64_at(h + 32)).unwrap();
                assert!(end <= data.len() as u64);
            }
        }
    }
});
