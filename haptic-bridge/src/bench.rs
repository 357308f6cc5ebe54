//! `nanopush-haptic bench-transport`: the iceoryx2 link's latency between two processes, with
//! the payload, the configuration and the node set-up of the real link, on services of its own.
//!
//! The parent publishes a ping stamped with `CLOCK_MONOTONIC` and busy-waits for the pong; the
//! child (the same binary with `--echo`) busy-waits for each ping, stamps its arrival and answers
//! at once. One-way = the child's arrival stamp − the send stamp (one clock for the machine);
//! round trip = the pong's arrival − the send stamp.

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use clap::Args;
use nanopush_haptic::latency::Histogram;
use nanopush_proto::haptic::{HapticState, IpcNode, ipc_node, monotonic_ns};

type Ipc = iceoryx2::service::ipc::Service;
type Publisher = iceoryx2::port::publisher::Publisher<Ipc, HapticState, ()>;
type Subscriber = iceoryx2::port::subscriber::Subscriber<Ipc, HapticState, ()>;

const PING: &str = "nanopush/bench/ping";
const PONG: &str = "nanopush/bench/pong";

/// Arguments of `bench-transport`.
#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Round trips to measure, in [100, 10000000].
    #[arg(long, default_value_t = 100_000)]
    samples: u64,
    /// Be the echoing child (started by the parent).
    #[arg(long, hide = true)]
    echo: bool,
}

fn ports(node: &IpcNode, out: &str, inp: &str) -> anyhow::Result<(Publisher, Subscriber)> {
    let service = |name: &str| -> anyhow::Result<_> {
        let n: iceoryx2::prelude::ServiceName = name.try_into().map_err(|e| anyhow::anyhow!("{e:?}"))?;
        node.service_builder(&n)
            .publish_subscribe::<HapticState>()
            .open_or_create()
            .map_err(|e| anyhow::anyhow!("service {name}: {e:?}"))
    };
    let publisher = service(out)?
        .publisher_builder()
        .create()
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let subscriber = service(inp)?
        .subscriber_builder()
        .create()
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    Ok((publisher, subscriber))
}

fn send(p: &Publisher, s: HapticState) -> anyhow::Result<()> {
    let sample = p.loan_uninit().map_err(|e| anyhow::anyhow!("{e:?}"))?;
    sample.write_payload(s).send().map_err(|e| anyhow::anyhow!("{e:?}"))?;
    Ok(())
}

/// Busy-waits for a sample with sequence number `seq` (older ones are skipped), at most `limit`.
fn wait_for(s: &Subscriber, seq: u64, limit: Duration) -> anyhow::Result<Option<HapticState>> {
    let start = Instant::now();
    loop {
        while let Some(sample) = s.receive().map_err(|e| anyhow::anyhow!("{e:?}"))? {
            if sample.seq == seq {
                return Ok(Some(*sample));
            }
        }
        if start.elapsed() > limit {
            return Ok(None);
        }
        std::hint::spin_loop();
    }
}

fn echo() -> anyhow::Result<String> {
    let node = ipc_node("nanopush-bench-echo").map_err(|e| anyhow::anyhow!("{e}"))?;
    let (publisher, subscriber) = ports(&node, PONG, PING)?;
    let mut idle = Instant::now();
    loop {
        while let Some(sample) = subscriber.receive().map_err(|e| anyhow::anyhow!("{e:?}"))? {
            let arrived = monotonic_ns();
            let mut pong = *sample;
            if pong.seq == u64::MAX {
                return Ok(String::new());
            }
            pong.latency_ns = arrived;
            send(&publisher, pong)?;
            idle = Instant::now();
        }
        if idle.elapsed() > Duration::from_secs(10) {
            bail!("no ping for 10 s");
        }
        std::hint::spin_loop();
    }
}

/// Runs the benchmark (or the echo side of it).
pub fn run(a: &BenchArgs) -> anyhow::Result<String> {
    if a.echo {
        return echo();
    }
    if !(100..=10_000_000).contains(&a.samples) {
        bail!("--samples {} is out of range; allowed: [100, 10000000]", a.samples);
    }
    let node = ipc_node("nanopush-bench").map_err(|e| anyhow::anyhow!("{e}"))?;
    let (publisher, subscriber) = ports(&node, PING, PONG)?;
    let exe = std::env::current_exe().context("finding this executable")?;
    let mut child = Command::new(exe)
        .args(["bench-transport", "--echo"])
        .stdin(Stdio::null())
        .spawn()
        .context("starting the echo process")?;
    // Wait until the echo answers (its ports exist).
    let mut ready = false;
    for _ in 0..500 {
        send(
            &publisher,
            HapticState {
                seq: 0,
                ..Default::default()
            },
        )?;
        if wait_for(&subscriber, 0, Duration::from_millis(10))?.is_some() {
            ready = true;
            break;
        }
    }
    if !ready {
        let _ = child.kill();
        let _ = child.wait();
        bail!("the echo process did not answer within 5 s");
    }
    let measured = measure(a.samples, &publisher, &subscriber);
    let _ = send(
        &publisher,
        HapticState {
            seq: u64::MAX,
            ..Default::default()
        },
    );
    // Reaped whatever happened (the echo also ends by itself after 10 s without a ping).
    let deadline = Instant::now() + Duration::from_secs(2);
    while child.try_wait().ok().flatten().is_none() {
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            break;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    let (one_way, round_trip, lost) = measured?;
    Ok(format!(
        "iceoryx2 transport, {} round trips ({lost} lost):\n  one-way    {}\n  round trip {}\n",
        a.samples,
        one_way.summary(),
        round_trip.summary()
    ))
}

/// The ping-pong itself: one-way and round-trip histograms, and the pongs lost.
fn measure(
    samples: u64,
    publisher: &Publisher,
    subscriber: &Subscriber,
) -> anyhow::Result<(Histogram, Histogram, u64)> {
    let (mut one_way, mut round_trip) = (Histogram::default(), Histogram::default());
    let mut lost = 0u64;
    for seq in 1..=samples {
        let sent = monotonic_ns();
        send(
            publisher,
            HapticState {
                seq,
                time_ns: sent,
                ..Default::default()
            },
        )?;
        match wait_for(subscriber, seq, Duration::from_millis(100))? {
            Some(pong) => {
                let back = monotonic_ns();
                one_way.record(pong.latency_ns.saturating_sub(sent));
                round_trip.record(back - sent);
            }
            None => lost += 1,
        }
    }
    Ok((one_way, round_trip, lost))
}
