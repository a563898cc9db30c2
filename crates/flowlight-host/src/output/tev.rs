//! Streaming the film to a running [tev](https://github.com/Tom94/tev) over its TCP IPC
//! protocol, as pbrt-v4's `--display-server` does.
//!
//! tev listens on 127.0.0.1:14158 by default. Every packet is
//!
//! ```text
//! u32 total length in bytes (little-endian, the 4 bytes included) · u8 type · payload
//! ```
//!
//! with strings as UTF-8 bytes ended by a NUL, integers little-endian and booleans one byte.
//! Two types are sent:
//!
//! * **CreateImage** (type 4): grab_focus u8, image name, width i32, height i32, channel
//!   count i32, the channel names;
//! * **UpdateImage, version 2** (type 5): grab_focus u8, image name, channel count i32, the
//!   channel names, x i32, y i32, w i32, h i32, then each channel's w·h f32 values in row
//!   order, one channel after the other. tev has read this version since 2019 and still
//!   does next to its version 3 (type 6, explicit offsets and strides), so one encoding
//!   serves old and new viewers (tev's `src/Ipc.cpp`, `IpcPacket::interpretAsUpdateImage`).
//!
//! The image is sent as R, G, B (linear radiance, as in the EXR) in tiles of at most
//! [`TILE`]² pixels, so that no packet is larger than ~200 KiB.

use flowlight_core::spectrum::Rgb;
use std::io::{self, Write};
use std::net::{TcpStream, ToSocketAddrs};
use std::time::Duration;

/// tev's default address.
pub const DEFAULT_ADDRESS: &str = "127.0.0.1:14158";
/// Side of the tiles an image is sent in.
pub const TILE: u32 = 128;
/// Packet types (tev's `IpcPacket::EType`).
pub const CREATE_IMAGE: u8 = 4;
pub const UPDATE_IMAGE_V2: u8 = 5;
/// The channels sent.
pub const CHANNELS: [&str; 3] = ["R", "G", "B"];

/// A packet being written: the length is patched in by [`Packet::finish`].
struct Packet(Vec<u8>);

impl Packet {
    fn new(kind: u8) -> Packet {
        let mut bytes = vec![0u8; 4];
        bytes.push(kind);
        Packet(bytes)
    }
    fn u8(&mut self, v: u8) -> &mut Self {
        self.0.push(v);
        self
    }
    fn i32(&mut self, v: i32) -> &mut Self {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    fn f32(&mut self, v: f32) -> &mut Self {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    /// A NUL-terminated string (an interior NUL would end it early: names have none).
    fn str(&mut self, s: &str) -> &mut Self {
        self.0.extend(s.bytes().filter(|&b| b != 0));
        self.0.push(0);
        self
    }
    fn finish(mut self) -> Vec<u8> {
        let n = self.0.len() as u32;
        self.0[..4].copy_from_slice(&n.to_le_bytes());
        self.0
    }
}

/// The CreateImage packet of an RGB image `name` of `width` × `height` pixels.
pub fn create_image_packet(name: &str, width: u32, height: u32, grab_focus: bool) -> Vec<u8> {
    let mut p = Packet::new(CREATE_IMAGE);
    p.u8(grab_focus as u8)
        .str(name)
        .i32(width as i32)
        .i32(height as i32)
        .i32(CHANNELS.len() as i32);
    for c in CHANNELS {
        p.str(c);
    }
    p.finish()
}

/// The UpdateImage (version 2) packet of the `w` × `h` tile at (`x`, `y`) of `image`
/// (`width` pixels a row), as R, G, B planes.
pub fn update_image_packet(
    name: &str,
    image: &[Rgb],
    width: u32,
    (x, y, w, h): (u32, u32, u32, u32),
) -> Vec<u8> {
    let mut p = Packet::new(UPDATE_IMAGE_V2);
    p.u8(0).str(name).i32(CHANNELS.len() as i32);
    for c in CHANNELS {
        p.str(c);
    }
    p.i32(x as i32).i32(y as i32).i32(w as i32).i32(h as i32);
    p.0.reserve(12 * (w * h) as usize);
    for c in 0..3 {
        for row in y..y + h {
            for col in x..x + w {
                let v = image[(row * width + col) as usize].to_array()[c];
                p.f32(v);
            }
        }
    }
    p.finish()
}

/// The tiles an image of `width` × `height` is sent in: (x, y, w, h), row by row.
pub fn tiles(width: u32, height: u32) -> Vec<(u32, u32, u32, u32)> {
    let mut out = Vec::new();
    for y in (0..height).step_by(TILE as usize) {
        for x in (0..width).step_by(TILE as usize) {
            out.push((x, y, TILE.min(width - x), TILE.min(height - y)));
        }
    }
    out
}

/// A connection to tev showing one image.
pub struct TevClient {
    stream: TcpStream,
    name: String,
    width: u32,
    height: u32,
}

impl TevClient {
    /// Connects to tev at `address` (HOST:PORT) within `timeout` and creates the image
    /// `name` of `width` × `height` pixels (focused in tev).
    pub fn connect(
        address: &str,
        name: &str,
        width: u32,
        height: u32,
        timeout: Duration,
    ) -> io::Result<TevClient> {
        let mut last = io::Error::new(
            io::ErrorKind::AddrNotAvailable,
            format!("{address} resolves to no address"),
        );
        for addr in address.to_socket_addrs()? {
            match TcpStream::connect_timeout(&addr, timeout) {
                Ok(stream) => {
                    stream.set_write_timeout(Some(timeout))?;
                    stream.set_nodelay(true)?;
                    let mut client = TevClient {
                        stream,
                        name: name.to_string(),
                        width,
                        height,
                    };
                    client
                        .stream
                        .write_all(&create_image_packet(name, width, height, true))?;
                    return Ok(client);
                }
                Err(e) => last = e,
            }
        }
        Err(last)
    }

    /// Sends the whole `image` (`width` × `height` of [`TevClient::connect`]), tile by tile.
    pub fn send_image(&mut self, image: &[Rgb]) -> io::Result<()> {
        if image.len() != (self.width * self.height) as usize {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                "the image does not have the size tev was given",
            ));
        }
        for tile in tiles(self.width, self.height) {
            let packet = update_image_packet(&self.name, image, self.width, tile);
            self.stream.write_all(&packet)?;
        }
        self.stream.flush()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packets_carry_their_length_type_and_fields() {
        let p = create_image_packet("a", 3, 2, true);
        assert_eq!(
            u32::from_le_bytes(p[..4].try_into().unwrap()) as usize,
            p.len()
        );
        assert_eq!(p[4], CREATE_IMAGE);
        assert_eq!(&p[5..8], &[1, b'a', 0]);
        assert_eq!(i32::from_le_bytes(p[8..12].try_into().unwrap()), 3);
        assert_eq!(i32::from_le_bytes(p[12..16].try_into().unwrap()), 2);
        assert_eq!(i32::from_le_bytes(p[16..20].try_into().unwrap()), 3);
        assert_eq!(&p[20..], b"R\0G\0B\0");
        let img: Vec<Rgb> = (0..6).map(|i| Rgb::new(i as f32, 10.0, 20.0)).collect();
        let u = update_image_packet("a", &img, 3, (1, 0, 2, 2));
        assert_eq!(
            u32::from_le_bytes(u[..4].try_into().unwrap()) as usize,
            u.len()
        );
        assert_eq!(u[4], UPDATE_IMAGE_V2);
        // Header: focus, "a\0", 3, "R\0G\0B\0", x y w h; then 3 planes of 4 floats.
        let data = &u[5 + 1 + 2 + 4 + 6 + 16..];
        assert_eq!(data.len(), 3 * 4 * 4);
        let first: Vec<f32> = data[..16]
            .chunks(4)
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
            .collect();
        assert_eq!(first, [1.0, 2.0, 4.0, 5.0]);
    }

    #[test]
    fn tiles_cover_the_image_once() {
        let t = tiles(300, 130);
        assert_eq!(t.len(), 3 * 2);
        let area: u32 = t.iter().map(|&(_, _, w, h)| w * h).sum();
        assert_eq!(area, 300 * 130);
        assert_eq!(t[5], (256, 128, 44, 2));
    }
}
