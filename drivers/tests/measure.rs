//! Measurements, ignored by default. Run:
//! `cargo test -p softtouch-drivers --release --test measure -- --ignored --nocapture`

mod common;

use softtouch_drivers::gripper::GripperCommand;
use softtouch_drivers::hande::{self, HandE, HandEConfig, HandEService};
use softtouch_drivers::netft::{
    NetFtClient, NetFtConfig, NetFtServer, Scaling, ServerConfig, StreamMode,
};
use softtouch_drivers::{ForceSensor, Gripper, TokioClock};
use std::sync::Arc;
use std::time::{Duration, Instant};

async fn netft_rate(mode: StreamMode, rate_hz: f64, secs: f64) {
    let mut cfg = ServerConfig::at(([127, 0, 0, 1], 0).into());
    cfg.calibration_bind = None;
    cfg.records_per_datagram = 10;
    let server = NetFtServer::bind(common::PatternSensor::new(rate_hz), cfg)
        .await
        .expect("bind");
    let addr = server.rdt_addr().expect("addr");
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    let task = tokio::spawn(server.run(async move {
        let _ = rx.await;
    }));
    let mut c_cfg = NetFtConfig::new(addr, rate_hz);
    c_cfg.scaling = Scaling::Given {
        counts_per_force: 1e6,
        counts_per_torque: 1e6,
    };
    c_cfg.mode = mode;
    let mut c = NetFtClient::connect(c_cfg, Arc::new(TokioClock::new()))
        .await
        .expect("connect");
    c.start().await.expect("start");
    let mut out = Vec::with_capacity(1 << 20);
    let t0 = Instant::now();
    while t0.elapsed().as_secs_f64() < secs {
        c.read(&mut out).await.expect("read");
    }
    let el = t0.elapsed().as_secs_f64();
    c.stop().await.expect("stop");
    let _ = tx.send(());
    let stats = task.await.expect("join").expect("server");
    println!(
        "net-ft {mode:?} at {rate_hz} Hz offered: {:.0} readings/s received over {el:.1} s, lost {} ({} server records sent)",
        out.len() as f64 / el,
        c.lost_readings(),
        stats.records_sent
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "measurement: run with --ignored --nocapture"]
async fn netft_sustained_rate_on_loopback() {
    netft_rate(StreamMode::RealTime, 7000.0, 3.0).await;
    netft_rate(StreamMode::Buffered, 7000.0, 3.0).await;
    netft_rate(StreamMode::RealTime, 50_000.0, 3.0).await;
    netft_rate(StreamMode::Buffered, 200_000.0, 3.0).await;
}

#[tokio::test]
#[ignore = "measurement: run with --ignored --nocapture"]
async fn hande_round_trip_per_command() {
    use softtouch_schemas::defaults;
    let rig =
        softtouch_sim::SimRig::new(&defaults::rig(), &defaults::scene(), 1, TokioClock::new())
            .expect("rig");
    let service = HandEService::new(rig.gripper, 9);
    let (a, b) = tokio::io::duplex(1024);
    tokio::spawn(hande::serve_rtu(service.clone(), b, std::future::pending()));
    let config = HandEConfig {
        min_interval: Duration::ZERO,
        ..HandEConfig::default()
    };
    let mut g = HandE::new(a, config.clone(), Arc::new(TokioClock::new()));
    g.activate().await.expect("activate");
    let n = 2000;
    let t0 = Instant::now();
    for i in 0..n {
        if i % 2 == 0 {
            g.status().await.expect("status");
        } else {
            g.command(GripperCommand {
                position: (i % 256) as u8,
                speed: 128,
                force: 50,
            })
            .await
            .expect("cmd");
        }
    }
    let per = t0.elapsed().as_secs_f64() / f64::from(n) * 1e6;
    println!(
        "hand-e over an in-memory pipe, pacing off: {per:.1} µs per transaction (the wire at 115200 baud adds ~1.4 ms per 16-byte exchange; the gripper allows one per 5 ms)"
    );
    if let Some(pair) = common::pty_pair() {
        let rig =
            softtouch_sim::SimRig::new(&defaults::rig(), &defaults::scene(), 1, TokioClock::new())
                .expect("rig");
        let sp = hande::open_port(&pair.b).expect("b");
        tokio::spawn(hande::serve_serial(
            HandEService::new(rig.gripper, 9),
            sp,
            std::future::pending(),
        ));
        let mut g = HandE::new(
            hande::open_port(&pair.a).expect("a"),
            config,
            Arc::new(TokioClock::new()),
        );
        g.activate().await.expect("activate");
        let t0 = Instant::now();
        for _ in 0..500 {
            g.status().await.expect("status");
        }
        println!(
            "hand-e over a socat pty pair: {:.1} µs per status read",
            t0.elapsed().as_secs_f64() / 500.0 * 1e6
        );
    }
}
