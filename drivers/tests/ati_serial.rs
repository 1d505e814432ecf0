//! The ATI serial driver against the simulated controller (in-memory pipe and a real
//! pty pair) and against hand-made peers.
#![allow(clippy::float_cmp)]

mod common;

use common::{PatternSensor, pattern};
use softtouch_drivers::ati_serial::{self, AtiSerial, AtiSerialConfig, peer};
use softtouch_drivers::{Clock, DeviceError, ForceSensor, TokioClock};
use softtouch_schemas::FtReading;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;
use tokio::io::{AsyncReadExt, AsyncWriteExt, DuplexStream};

const CPF: f64 = 1000.0;
const CPT: f64 = 1_000_000.0;

fn clock() -> Arc<dyn Clock> {
    Arc::new(TokioClock::new())
}

fn config() -> AtiSerialConfig {
    let mut c = AtiSerialConfig::new(CPF, CPT);
    c.reply_timeout = Duration::from_millis(300);
    c.read_timeout = Duration::from_millis(300);
    c
}

async fn exercise<T>(mut c: AtiSerial<T>, biases: &std::sync::atomic::AtomicU32)
where
    T: tokio::io::AsyncRead + tokio::io::AsyncWrite + Unpin + Send,
{
    let one = c.query().await.expect("QR");
    assert!(one.status.is_ok());
    c.start().await.expect("QS");
    let mut out: Vec<FtReading> = Vec::new();
    while out.len() < 100 {
        c.read(&mut out).await.expect("read");
    }
    for r in &out {
        // The pattern's values are whole counts at these scales.
        let s = (r.wrench_in_sensor.force_n[0] * 1000.0).round();
        let want = pattern(s as u64);
        assert!(
            (r.wrench_in_sensor.force_n[1] - want.force_n[1]).abs() < 1e-9,
            "{r:?}"
        );
        assert!((r.wrench_in_sensor.torque_nm[2] - want.torque_nm[2]).abs() < 1e-9);
    }
    for w in out.windows(2) {
        assert_eq!(w[1].rdt_sequence, w[0].rdt_sequence + 1);
    }
    c.bias().await.expect("bias while streaming");
    assert_eq!(biases.load(Ordering::SeqCst), 1);
    let n = out.len();
    while out.len() < n + 20 {
        c.read(&mut out).await.expect("read after bias");
    }
    c.stop().await.expect("stop");
    assert_eq!(c.lost_readings(), 0);
    assert!(
        matches!(c.command("XX").await, Err(DeviceError::Fault { .. })),
        "unknown commands are refused"
    );
    c.command("CD A").await.expect("still talking");
}

#[tokio::test(start_paused = true)]
async fn streams_from_the_simulated_controller_over_an_in_memory_pipe() {
    let (a, b) = tokio::io::duplex(4096);
    let sensor = PatternSensor::new(1000.0);
    let biases = sensor.biases.clone();
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    let server = tokio::spawn(peer::serve(sensor, b, CPF, CPT, async move {
        let _ = rx.await;
    }));
    let c = AtiSerial::new(a, config(), clock())
        .await
        .expect("configure");
    exercise(c, &biases).await;
    let _ = tx.send(());
    assert!(server.await.expect("join").expect("peer") >= 120);
}

#[tokio::test]
async fn streams_from_the_simulated_controller_over_a_pty_pair() {
    let Some(pair) = common::pty_pair() else {
        return;
    };
    let client_port = ati_serial::open_port(&pair.a, 38400).expect("open pty a");
    let peer_port = ati_serial::open_port(&pair.b, 38400).expect("open pty b");
    let sensor = PatternSensor::new(500.0);
    let biases = sensor.biases.clone();
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    let server = tokio::spawn(peer::serve(sensor, peer_port, CPF, CPT, async move {
        let _ = rx.await;
    }));
    let c = AtiSerial::new(client_port, config(), clock())
        .await
        .expect("configure");
    exercise(c, &biases).await;
    let _ = tx.send(());
    server.await.expect("join").expect("peer");
}

/// A hand-made controller: answers the configuration commands, then runs `script`.
async fn scripted(script: &'static [u8], then_silent: bool) -> AtiSerial<DuplexStream> {
    scripted_with(script, then_silent, config()).await
}

/// [`scripted`] with a client config of the caller's.
async fn scripted_with(
    script: &'static [u8],
    then_silent: bool,
    config: AtiSerialConfig,
) -> AtiSerial<DuplexStream> {
    let (a, mut b) = tokio::io::duplex(4096);
    tokio::spawn(async move {
        let mut buf = [0u8; 64];
        let mut prompts = 0;
        // The wake-up CR, CD A and CD R.
        while prompts < 3 {
            let n = b.read(&mut buf).await.expect("read");
            let crs = buf[..n].iter().filter(|&&c| c == b'\r').count();
            for _ in 0..crs {
                b.write_all(b">").await.expect("prompt");
            }
            prompts += crs;
        }
        let _ = b.read(&mut buf).await; // QS
        b.write_all(script).await.expect("script");
        if then_silent {
            tokio::time::sleep(Duration::from_secs(3600)).await;
        }
    });
    AtiSerial::new(a, config, clock()).await.expect("configure")
}

#[tokio::test(start_paused = true)]
async fn garbled_lines_count_as_lost_and_keep_the_good_readings_before_them() {
    let mut c = scripted(
        b"0,1000,0,0,0,0,0\r\n0,1,2\r\n\xff\xfe\x00garbage\r\n0,2000,0,0,0,0,0\r\n12,3000,0,0,0,0,0\r\n",
        true,
    )
    .await;
    c.start().await.expect("start");
    // As callers read: a batch that comes with an error is dropped, so a good
    // reading read before a garbled line in the same call must come back with Ok.
    let mut out = Vec::new();
    let mut errors = 0;
    while out.len() < 3 {
        let mut batch = Vec::new();
        match c.read(&mut batch).await {
            Ok(n) => {
                assert_eq!(n, batch.len());
                out.extend(batch);
            }
            Err(DeviceError::Protocol { .. }) => errors += 1,
            Err(e) => panic!("{e}"),
        }
    }
    assert_eq!(errors, 1, "only the garbled line read alone is an error");
    assert_eq!(c.lost_readings(), 2);
    assert_eq!(
        out.iter().map(|r| r.rdt_sequence).collect::<Vec<_>>(),
        [1, 4, 5],
        "gaps show the lost lines"
    );
    assert_eq!(out[1].wrench_in_sensor.force_n[0], 2.0);
    assert!(
        out[2].status.is_fault(),
        "a non-zero error field is a fault status"
    );
    assert_eq!(c.stats().faulted, 1);
}

#[tokio::test(start_paused = true)]
async fn a_controller_that_stops_answering_times_out() {
    let mut c = scripted(b"0,1,2,3,4,5,6\r\n", true).await;
    c.start().await.expect("start");
    let mut out = Vec::new();
    c.read(&mut out).await.expect("one record");
    let e = c.read(&mut out).await.expect_err("silence");
    assert!(
        matches!(
            e,
            DeviceError::Timeout {
                timeout_ms: 300,
                ..
            }
        ),
        "{e}"
    );
}

#[tokio::test(start_paused = true)]
async fn an_endless_line_is_a_protocol_error_not_a_hang() {
    let mut c = scripted(&[b'7'; 400], true).await;
    c.start().await.expect("start");
    let e = c.read(&mut Vec::new()).await.expect_err("too long");
    assert!(matches!(e, DeviceError::Protocol { .. }), "{e}");
}

#[tokio::test(start_paused = true)]
async fn a_controller_that_never_prompts_fails_to_configure_with_a_timeout() {
    let (a, _b) = tokio::io::duplex(64);
    let e = AtiSerial::new(a, config(), clock())
        .await
        .expect_err("silent");
    assert!(matches!(e, DeviceError::Timeout { .. }), "{e}");
    let (a, b) = tokio::io::duplex(64);
    drop(b);
    let e = AtiSerial::new(a, config(), clock())
        .await
        .expect_err("closed");
    assert!(e.is_link(), "{e}");
}

/// Vendor bytes, not our formatter: a resolved ASCII record as the controller prints it
/// (error field, then Fx … Tz in counts, right-aligned in comma-separated fields, CR LF),
/// decoded by our client with the rig's counts per unit.
#[tokio::test(start_paused = true)]
async fn a_literal_ascii_record_decodes_through_our_client() {
    let mut c = scripted(
        b"   0,   -123,    456,  -7890,     12,    -34,     56\r\n",
        true,
    )
    .await;
    c.start().await.expect("start");
    let mut out = Vec::new();
    while out.is_empty() {
        c.read(&mut out).await.expect("read");
    }
    let r = out[0];
    assert!(r.status.is_ok());
    assert_eq!(r.wrench_in_sensor.force_n, [-0.123, 0.456, -7.89]);
    assert_eq!(
        r.wrench_in_sensor.torque_nm,
        [12.0 / CPT, -34.0 / CPT, 56.0 / CPT]
    );
    assert_eq!(c.lost_readings(), 0);
}

/// The rig's latency is taken off every stamp: a record that arrives at 1 s on the
/// client's clock, from a link with 7 ms of latency, is stamped 0.993 s.
#[tokio::test(start_paused = true)]
async fn a_configured_latency_is_subtracted_from_the_stamps() {
    let mut stamps = Vec::new();
    for latency_ms in [0, 7] {
        let mut cfg = config();
        cfg.latency = Duration::from_millis(latency_ms);
        let mut c = scripted_with(b"0,1,2,3,4,5,6\r\n", true, cfg).await;
        c.start().await.expect("start");
        tokio::time::sleep(Duration::from_secs(1)).await;
        let mut out = Vec::new();
        while out.is_empty() {
            c.read(&mut out).await.expect("read");
        }
        stamps.push(out[0].t.0);
    }
    assert!(stamps[0] >= 1_000_000_000, "{stamps:?}");
    assert_eq!(stamps[0] - stamps[1], 7_000_000, "{stamps:?}");
}
