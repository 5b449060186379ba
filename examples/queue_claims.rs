//! Claim latency of the job queue with many jobs queued (issue 17, item 5): enqueues `--jobs` jobs in a store
//! (`--store sqlite:DIR` or `postgres://…`), then times `--claims` claims one after another, each finished at once
//! so the queue stays as deep. Prints one JSON line: enqueue rate, claim p50/p99/max in milliseconds.
//! Run by `bench/replicas.py`; by hand: `cargo run --release --example queue_claims -- --store URL`.

use clap::Parser;
use kac::service::jobs::{JobProgress, JobView, Status};
use kac_engine::EngineConfig as Config;
use std::time::{Duration, Instant};

#[derive(Parser)]
struct Args {
    #[command(flatten)]
    config: Config,
    /// Jobs queued before the claims are timed.
    #[arg(long, default_value_t = 10_000)]
    jobs: usize,
    /// Claims timed.
    #[arg(long, default_value_t = 500)]
    claims: usize,
}

fn view(i: usize) -> JobView {
    JobView {
        id: format!("{i:032x}"),
        shape_id: "bench".into(),
        analysis: "spectrum".into(),
        status: Status::Enqueued,
        progress: JobProgress { phase: "queued".into(), converged: 0, wanted: 0 },
        created_at: kac::service::jobs::now(),
        started_at: None,
        finished_at: None,
        error: None,
        result: None,
        request: serde_json::json!({ "analysis": "spectrum", "k": 10 }),
    }
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

fn main() {
    let a = Args::parse();
    let backend = kac::service::store::open(&a.config).expect("open the store");
    let q = backend.queue;
    let t = Instant::now();
    for i in 0..a.jobs + a.claims {
        q.enqueue(view(i), kac_engine::store::Lane::Run, usize::MAX).expect("enqueue");
    }
    let enqueue_s = t.elapsed().as_secs_f64();
    let mut ms = vec![];
    for i in 0..a.claims {
        let owner = format!("bench:{i}");
        let t = Instant::now();
        let mut v = q.claim(&owner, Duration::from_secs(30)).expect("claim").expect("a queued job");
        ms.push(t.elapsed().as_secs_f64() * 1e3);
        v.status = Status::Succeeded;
        assert!(q.finish(&v.id, &owner, &v).expect("finish"));
    }
    ms.sort_by(f64::total_cmp);
    let (enqueued, _) = q.depth().expect("depth");
    println!(
        "{}",
        serde_json::json!({
            "queued": a.jobs, "enqueued_after": enqueued, "claims": a.claims,
            "enqueue_per_s": ((a.jobs + a.claims) as f64 / enqueue_s).round(),
            "claim_ms": { "p50": percentile(&ms, 0.5), "p99": percentile(&ms, 0.99), "max": ms[ms.len() - 1] },
        })
    );
}
