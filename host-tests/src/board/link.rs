//! The serial link to the board.
//!
//! The board's command line and capture stream share the ST-LINK virtual COM port. The port
//! is opened as a plain file with `std` (no serial crate, no system library), so the line must
//! be set up beforehand, raw and at the firmware's baud rate:
//!
//! ```text
//! stty -F /dev/ttyACM0 921600 raw -echo min 0 time 1
//! ```
//! (`--baud 921600` runs exactly this `stty` line first, on Linux: [`setup_port`].) Raw mode
//! matters: a terminal in canonical mode rewrites CR/LF and echoes bytes back to the board.
//! Whatever the line does to the bytes, the frames' CRC-32 catches it and the frame is
//! reported corrupted.

use std::fs::{File, OpenOptions};
use std::io::{Read, Write};
use std::path::Path;
use std::sync::mpsc;
use std::time::Duration;

use anyhow::{Context, bail};

/// A byte link to the board.
pub trait Link {
    /// Sends one command line (the line ending is added).
    fn send_line(&mut self, line: &str) -> anyhow::Result<()>;
    /// The bytes that arrive within `timeout` (empty if none).
    fn recv(&mut self, timeout: Duration) -> anyhow::Result<Vec<u8>>;
}

/// The serial port as a [`Link`]: a reader thread feeds a channel so reads can time out.
pub struct SerialLink {
    write: File,
    rx: mpsc::Receiver<std::io::Result<Vec<u8>>>,
}

impl SerialLink {
    /// Opens `port` (set up beforehand: [`setup_port`]) and starts its reader thread.
    pub fn open(port: &Path) -> anyhow::Result<Self> {
        let f = OpenOptions::new()
            .read(true)
            .write(true)
            .open(port)
            .with_context(|| format!("opening {}", port.display()))?;
        let mut reader = f.try_clone()?;
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            let mut buf = [0u8; 4096];
            loop {
                match reader.read(&mut buf) {
                    // `min 0 time 1`: a read returns 0 after 0.1 s of silence.
                    Ok(0) => std::thread::sleep(Duration::from_millis(1)),
                    Ok(n) => {
                        if tx.send(Ok(buf[..n].to_vec())).is_err() {
                            return;
                        }
                    }
                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                    Err(e) => {
                        let _ = tx.send(Err(e));
                        return;
                    }
                }
            }
        });
        Ok(Self { write: f, rx })
    }
}

impl Link for SerialLink {
    fn send_line(&mut self, line: &str) -> anyhow::Result<()> {
        self.write.write_all(line.as_bytes())?;
        self.write.write_all(b"\n")?;
        self.write.flush()?;
        Ok(())
    }

    fn recv(&mut self, timeout: Duration) -> anyhow::Result<Vec<u8>> {
        match self.rx.recv_timeout(timeout) {
            Ok(Ok(b)) => Ok(b),
            Ok(Err(e)) => Err(e).context("reading the serial port"),
            Err(mpsc::RecvTimeoutError::Timeout) => Ok(vec![]),
            Err(mpsc::RecvTimeoutError::Disconnected) => bail!("the serial port closed"),
        }
    }
}

/// Runs `stty -F PORT BAUD raw -echo min 0 time 1` (Linux) to set the line up.
pub fn setup_port(port: &Path, baud: u32) -> anyhow::Result<()> {
    let status = std::process::Command::new("stty")
        .arg("-F")
        .arg(port)
        .args([&baud.to_string(), "raw", "-echo", "min", "0", "time", "1"])
        .status()
        .context("running stty")?;
    if !status.success() {
        bail!("stty could not set up {}", port.display());
    }
    Ok(())
}
