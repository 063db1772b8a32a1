//! `piezo record --port DEV --seconds S --out FILE.csv`: capture a run on the board and write
//! it as a CSV record (`t,u,y,r,flags`) that the model tools read ([`host_tests::board`]: the
//! serial line's set-up and the exchange are described there).

use clap::Args;
use host_tests::board::capture::{Options, record, write_csv};
use host_tests::board::link::{SerialLink, setup_port};
use host_tests::io::checks;
use std::path::PathBuf;
use std::time::Duration;

/// Arguments of `piezo record`.
#[derive(Args, Debug)]
pub struct RecordArgs {
    /// Serial device of the board (the ST-LINK virtual COM port), e.g. /dev/ttyACM0.
    #[arg(long)]
    pub port: PathBuf,
    /// Seconds to record at the loop rate (the board holds 50000 samples: 1 s at 50 kHz;
    /// within 1e-6..3600 s).
    #[arg(long)]
    pub seconds: f64,
    /// CSV file to write (columns t,u,y,r,flags).
    #[arg(long)]
    pub out: PathBuf,
    /// Run `stty -F PORT BAUD raw -echo min 0 time 1` first (Linux); otherwise set the port up
    /// yourself.
    #[arg(long)]
    pub baud: Option<u32>,
    /// Seconds without any byte from the board before a step is given up (0.001..3600 s).
    #[arg(long, default_value_t = 5.0)]
    pub timeout: f64,
    /// How many times missing ranges are asked for again.
    #[arg(long, default_value_t = 3)]
    pub retries: u32,
}

/// Run `piezo record`.
pub fn run(a: &RecordArgs) -> anyhow::Result<()> {
    checks::within("--timeout", a.timeout, 1e-3, 3600.0, "s")?;
    checks::within("--seconds", a.seconds, 1e-6, 3600.0, "s")?;
    if let Some(baud) = a.baud {
        setup_port(&a.port, baud)?;
    }
    let mut link = SerialLink::open(&a.port)?;
    let opts = Options {
        timeout: Duration::from_secs_f64(a.timeout),
        retries: a.retries,
        poll: Duration::from_millis(100),
    };
    let rec = record(&mut link, a.seconds, &opts)?;
    write_csv(&rec, &a.out)?;
    let r = &rec.report;
    println!(
        "wrote {} samples at {} Hz to {} ({} frames ok, {} corrupted, {} lost, {} duplicated, {} resend requests)",
        rec.records.len(),
        rec.rate_hz,
        a.out.display(),
        r.frames_ok,
        r.frames_corrupted,
        r.frames_lost,
        r.frames_duplicated,
        r.resend_requests
    );
    Ok(())
}
