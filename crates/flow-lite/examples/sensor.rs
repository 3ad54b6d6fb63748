//! A temperature sensor written the way a board's sketch is (`setup` once, then `loop_once` forever), run on the
//! host over a serial device: FlowProtocol through flow-lite alone, in two fixed buffers.
//!
//! ```text
//! cargo run -p flow-lite --example sensor -- /dev/ttyUSB0 [TOKEN] [--count N]
//! ```
//!
//! The token is the second argument or `FLOW_TOKEN`. It logs in as `sensor`, creates the stream channel
//! `Sensor.temperature` (`{"mime":"application/json"}`) and publishes a small JSON reading every 100 ms; with
//! `--count N` it stops after N readings, waits for the hub to have read them (a ping) and exits 0.

use std::fs::{File, OpenOptions};
use std::io::{ErrorKind, Read, Write};
use std::process::ExitCode;
use std::time::{Duration, Instant};

use flow_lite::client::{Client, Link};
use flow_lite::message::ChanId;

const CHANNEL: &str = "Sensor.temperature";
const HEADER: &str = r#"{"mime":"application/json"}"#;
const PERIOD: Duration = Duration::from_millis(100);

/// The serial device as a flow-lite link.
struct Serial(File);

impl Link for Serial {
    type Error = std::io::Error;

    fn write(&mut self, bytes: &[u8]) -> Result<(), Self::Error> {
        self.0.write_all(bytes)?;
        self.0.flush()
    }

    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        match self.0.read(buf) {
            // A terminal in raw mode with `min 0 time 5` returns 0 after half a second of silence.
            Ok(n) => Ok(n),
            Err(e) if matches!(e.kind(), ErrorKind::Interrupted | ErrorKind::WouldBlock) => Ok(0),
            Err(e) => Err(e),
        }
    }
}

/// Logs in and creates the publisher; returns its channel.
fn setup(client: &mut Client<'_, Serial>, token: &str) -> Result<ChanId, String> {
    let session = client
        .login(token, "sensor")
        .map_err(|e| format!("login: {e} {}", client.last_message()))?;
    let chan = client
        .publisher(CHANNEL, HEADER)
        .map_err(|e| format!("creating {CHANNEL}: {e} {}", client.last_message()))?;
    eprintln!(
        "sensor: connection {} publishes {CHANNEL} as channel {chan}",
        session.conn
    );
    Ok(chan)
}

/// Publishes reading number `n`.
fn loop_once(client: &mut Client<'_, Serial>, chan: ChanId, n: u64) -> Result<(), String> {
    // A slow sawtooth around 21 °C: enough to see it move on a plot.
    let celsius = 21.0 + ((n % 40) as f64 - 20.0) / 20.0;
    let reading = format!(r#"{{"celsius":{celsius:.2},"n":{n}}}"#);
    client
        .publish(chan, reading.as_bytes())
        .map_err(|e| format!("publishing: {e}"))
}

struct Args {
    device: String,
    token: String,
    count: Option<u64>,
}

fn args() -> Result<Args, String> {
    let mut positional = Vec::new();
    let mut count = None;
    let mut it = std::env::args().skip(1);
    while let Some(arg) = it.next() {
        if arg == "--count" {
            let n = it.next().ok_or("--count needs a number")?;
            count = Some(
                n.parse()
                    .map_err(|_| format!("--count {n}: not a number"))?,
            );
        } else {
            positional.push(arg);
        }
    }
    let mut positional = positional.into_iter();
    let device = positional
        .next()
        .ok_or("usage: sensor DEVICE [TOKEN] [--count N]")?;
    let token = match positional.next() {
        Some(token) => token,
        None => std::env::var("FLOW_TOKEN")
            .map_err(|_| "no token: give it as the second argument or FLOW_TOKEN")?,
    };
    Ok(Args {
        device,
        token,
        count,
    })
}

/// Puts the terminal in raw mode (no echo, no line editing, no signals) with reads that give up after 0.5 s.
fn raw_mode(device: &str) {
    let status = std::process::Command::new("stty")
        .args(["-F", device, "raw", "-echo", "min", "0", "time", "5"])
        .status();
    match status {
        Ok(s) if s.success() => {}
        // Not a terminal (a pipe in a test), or no stty: go on, the link still works if the bytes pass as they are.
        other => eprintln!("sensor: stty on {device} failed ({other:?}); going on"),
    }
}

fn run() -> Result<(), String> {
    let args = args()?;
    raw_mode(&args.device);
    let file = OpenOptions::new()
        .read(true)
        .write(true)
        .open(&args.device)
        .map_err(|e| format!("opening {}: {e}", args.device))?;
    // The buffers a board would have: 1 KiB each way.
    let (mut rx, mut tx) = ([0u8; 1024], [0u8; 1024]);
    let mut client = Client::new(Serial(file), &mut rx, &mut tx);
    // 60 reads of at most 0.5 s: a request waits up to half a minute.
    client.set_read_limit(60);
    let chan = setup(&mut client, &args.token)?;
    let mut next = Instant::now();
    let mut n = 0;
    while args.count.is_none_or(|count| n < count) {
        loop_once(&mut client, chan, n)?;
        n += 1;
        next += PERIOD;
        if let Some(wait) = next.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
    }
    // The pong comes after the hub has read every reading sent before it.
    if let Err(e) = client.ping() {
        eprintln!("sensor: no pong after the last reading: {e}");
    }
    eprintln!(
        "sensor: {n} readings sent, {} damaged packets received",
        client.damaged()
    );
    Ok(())
}

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("sensor: {e}");
            ExitCode::FAILURE
        }
    }
}
