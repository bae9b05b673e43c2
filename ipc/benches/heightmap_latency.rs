//! IPC latency of a `HeightmapFrame` (200 KB) from publish to receive, between two processes.
//!
//! The bench re-runs itself as the publisher (`HERB_BENCH_ROLE=publisher`): it fills a loaned
//! frame in shared memory, stamps it (CLOCK_MONOTONIC) just before `send`, at 200 Hz. This
//! process subscribes, busy-polls, and records `receive time - stamp` with the frame read in
//! place (header and a cell: the receive path copies nothing). In the same run it also times
//! what a copying receive would add (copying the 200 KB frame out of shared memory), for the
//! ratio. Prints p50/p99/max in microseconds.
//!
//! Run: `cargo bench -p herb-ipc --bench heightmap_latency` (`HERB_BENCH_FRAMES`, default 4000).

use hdrhistogram::Histogram;
use herb_ipc::bus::Bus;
use herb_ipc::{Header, HeightmapFrame, Services, monotonic_ns, zeroed_in_place};
use std::time::Duration;

fn frames() -> u64 {
    std::env::var("HERB_BENCH_FRAMES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(4000)
}

fn publisher(prefix: &str) {
    let services = Services::new(prefix).unwrap();
    let bus = Bus::open("bench-pub", &services).unwrap();
    let p = bus
        .publisher::<HeightmapFrame>(&services.heightmap())
        .unwrap();
    // Wait for the subscriber.
    std::thread::sleep(Duration::from_millis(500));
    for seq in 1..=frames() + 50 {
        let mut s = p.loan_uninit().unwrap();
        let f = zeroed_in_place(s.payload_mut());
        f.nx = 222;
        f.ny = 146;
        f.cell_m = 0.35 / 224.0;
        for (i, v) in f.data[..222 * 146].iter_mut().enumerate() {
            *v = (i % 97) as f32 * 1e-3;
        }
        // SAFETY: fully initialised above.
        let mut s = unsafe { s.assume_init() };
        s.payload_mut().header = Header::now(seq);
        s.send().unwrap();
        std::thread::sleep(Duration::from_millis(5));
    }
}

fn main() {
    let prefix = format!("bench{}", std::process::id());
    if std::env::var("HERB_BENCH_ROLE").as_deref() == Ok("publisher") {
        publisher(&std::env::var("HERB_BENCH_PREFIX").unwrap());
        return;
    }
    if std::env::args().any(|a| a == "--list") {
        return;
    }
    let services = Services::new(&prefix).unwrap();
    let bus = Bus::open("bench-sub", &services).unwrap();
    let sub = bus
        .subscriber::<HeightmapFrame>(&services.heightmap())
        .unwrap();
    let mut child = std::process::Command::new(std::env::current_exe().unwrap())
        .env("HERB_BENCH_ROLE", "publisher")
        .env("HERB_BENCH_PREFIX", &prefix)
        .spawn()
        .unwrap();
    let mut zero_copy = Histogram::<u64>::new_with_bounds(1, 1_000_000_000, 3).unwrap();
    let mut copy_cost = zero_copy.clone();
    let mut copy = Box::new(std::mem::MaybeUninit::<HeightmapFrame>::uninit());
    let mut checksum = 0.0f32;
    let mut n = 0;
    while n < frames() {
        if let Ok(Some(s)) = sub.receive() {
            let now = monotonic_ns();
            let f = s.payload();
            if f.header.seq <= 20 {
                continue; // warm-up
            }
            zero_copy.saturating_record(now.saturating_sub(f.header.stamp_ns).max(1));
            checksum += f.data[1000];
            // What copying the frame out of shared memory would add.
            let t0 = monotonic_ns();
            // SAFETY: one frame from the sample into the box; the regions do not overlap.
            unsafe { std::ptr::copy_nonoverlapping(f, copy.as_mut_ptr(), 1) };
            // SAFETY: written just above.
            checksum += unsafe { copy.assume_init_ref() }.data[2000];
            copy_cost.saturating_record((monotonic_ns() - t0).max(1));
            n += 1;
        } else {
            std::hint::spin_loop();
        }
    }
    let _ = child.kill();
    let _ = child.wait();
    let us = |h: &Histogram<u64>, q: f64| h.value_at_quantile(q) as f64 / 1000.0;
    println!(
        "HeightmapFrame ({} KB) publish -> receive, {} frames, zero-copy: p50 {:.2} us, p99 {:.2} us, max {:.2} us",
        std::mem::size_of::<HeightmapFrame>() / 1024,
        zero_copy.len(),
        us(&zero_copy, 0.5),
        us(&zero_copy, 0.99),
        zero_copy.max() as f64 / 1000.0
    );
    println!(
        "copying the frame out of shared memory would add: p50 {:.2} us, p99 {:.2} us ({:.1}x the zero-copy p50)",
        us(&copy_cost, 0.5),
        us(&copy_cost, 0.99),
        us(&copy_cost, 0.5) / us(&zero_copy, 0.5)
    );
    std::hint::black_box(checksum);
}
