//! The Net F/T client against the simulated server and against hand-made peers, on
//! 127.0.0.1 with ports picked by the OS. Real (not paused) time with short timeouts:
//! these tests use real sockets.
#![allow(clippy::float_cmp)]

mod common;

use common::{PatternSensor, pattern};
use softtouch_drivers::netft::codec::{self, Calibration, Command, RawRecord};
use softtouch_drivers::netft::{
    NetFtClient, NetFtConfig, NetFtServer, Scaling, ServerConfig, StreamMode,
};
use softtouch_drivers::{Clock, DeviceError, ForceSensor, TokioClock};
use softtouch_schemas::{FtReading, FtStatus};
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, UdpSocket};
use tokio::sync::oneshot;

fn local() -> SocketAddr {
    ([127, 0, 0, 1], 0).into()
}

fn clock() -> Arc<dyn Clock> {
    Arc::new(TokioClock::new())
}

struct Running {
    rdt: SocketAddr,
    cal: SocketAddr,
    stop: oneshot::Sender<()>,
    task: tokio::task::JoinHandle<Result<softtouch_drivers::netft::ServerStats, DeviceError>>,
}

async fn spawn_server<S: ForceSensor + 'static>(sensor: S, records_per_datagram: usize) -> Running {
    let mut cfg = ServerConfig::at(local());
    cfg.calibration = Calibration {
        force_unit: 2,
        torque_unit: 4,
        counts_per_force: 1_000_000,
        counts_per_torque: 1000,
        scale: [1; 6],
    };
    cfg.records_per_datagram = records_per_datagram;
    let server = NetFtServer::bind(sensor, cfg).await.expect("bind");
    let rdt = server.rdt_addr().expect("rdt addr");
    let cal = server
        .calibration_addr()
        .expect("cal addr")
        .expect("cal bound");
    let (stop, rx) = oneshot::channel::<()>();
    let task = tokio::spawn(server.run(async move {
        let _ = rx.await;
    }));
    Running {
        rdt,
        cal,
        stop,
        task,
    }
}

fn client_config(rdt: SocketAddr, cal: SocketAddr, rate_hz: f64) -> NetFtConfig {
    let mut c = NetFtConfig::new(rdt, rate_hz);
    c.scaling = Scaling::CalibrationRequest(cal);
    c.reply_timeout = Duration::from_millis(200);
    c
}

async fn read_at_least(s: &mut impl ForceSensor, n: usize) -> Vec<FtReading> {
    let mut out = Vec::new();
    while out.len() < n {
        s.read(&mut out).await.expect("read");
    }
    out
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-6
}

#[tokio::test]
async fn a_bias_is_confirmed_by_the_readings_going_to_zero_and_none_are_lost() {
    let sensor = PatternSensor::new(2000.0);
    let biases = sensor.biases.clone();
    let srv = spawn_server(sensor, 1).await;
    let mut c = NetFtClient::connect(client_config(srv.rdt, srv.cal, 2000.0), clock())
        .await
        .expect("connect");
    c.start().await.expect("start");
    let before = read_at_least(&mut c, 50).await;
    assert!((before[10].wrench_in_sensor.force_n[2] - 1.5).abs() < 1e-6);
    c.bias().await.expect("confirmed");
    assert_eq!(biases.load(Ordering::SeqCst), 1);
    assert_eq!(c.stats().bias_commands, 1);
    // The readings the confirmation read come next, in sequence, and end near zero.
    let after = read_at_least(&mut c, 20).await;
    let last_before = before.last().expect("some").rdt_sequence;
    assert!(after[0].rdt_sequence > last_before);
    assert_eq!(
        c.lost_readings(),
        0,
        "no gap: the held readings were handed out"
    );
    let newest = after.last().expect("some").wrench_in_sensor;
    assert!(newest.force_n[2].abs() < 1e-6, "{newest:?}");
    let _ = srv.stop.send(());
}

#[tokio::test]
async fn a_bias_the_sensor_never_applies_is_an_error_naming_the_offset() {
    let mut sensor = PatternSensor::new(2000.0);
    sensor.ignore_bias = true;
    let biases = sensor.biases.clone();
    let srv = spawn_server(sensor, 1).await;
    let mut cfg = client_config(srv.rdt, srv.cal, 2000.0);
    cfg.reply_timeout = Duration::from_millis(50);
    let mut c = NetFtClient::connect(cfg, clock()).await.expect("connect");
    c.start().await.expect("start");
    let _ = read_at_least(&mut c, 20).await;
    let e = c.bias().await.expect_err("not confirmed");
    assert!(e.is_fault(), "{e}");
    let text = e.to_string();
    assert!(
        text.contains("bias not confirmed after 3 command(s)") && text.contains("1.5"),
        "{text}"
    );
    assert_eq!(biases.load(Ordering::SeqCst), 3, "sent three times");
    // The stream goes on: a later read still delivers.
    assert!(!read_at_least(&mut c, 5).await.is_empty());
    let _ = srv.stop.send(());
}

#[tokio::test]
async fn client_streams_from_the_simulated_server_end_to_end() {
    let sensor = PatternSensor::new(2000.0);
    let biases = sensor.biases.clone();
    let srv = spawn_server(sensor, 10).await;
    let mut c = NetFtClient::connect(client_config(srv.rdt, srv.cal, 2000.0), clock())
        .await
        .expect("connect");
    // Calibration came from the server: N and N·mm, converted to N·m.
    assert_eq!(c.scaling(), (1e6, 1e6));
    c.start().await.expect("start");
    let got = read_at_least(&mut c, 300).await;
    assert_eq!(
        got[0].rdt_sequence, 1,
        "rdt_sequence starts at 1 for each request"
    );
    for (i, r) in got.iter().enumerate() {
        let want = pattern(u64::from(r.ft_sequence));
        for k in 0..3 {
            assert!(
                close(r.wrench_in_sensor.force_n[k], want.force_n[k]),
                "{r:?}"
            );
            assert!(
                close(r.wrench_in_sensor.torque_nm[k], want.torque_nm[k]),
                "{r:?}"
            );
        }
        assert_eq!(r.status, FtStatus::OK);
        if i > 0 {
            assert_eq!(r.rdt_sequence, got[i - 1].rdt_sequence + 1);
            assert_eq!(r.ft_sequence, got[i - 1].ft_sequence + 1);
            assert!(r.t >= got[i - 1].t, "host stamps never go backwards");
        }
    }
    assert_eq!(c.lost_readings(), 0);
    c.bias().await.expect("bias");
    let _ = read_at_least(&mut c, 10).await;
    assert_eq!(
        biases.load(Ordering::SeqCst),
        1,
        "bias reached the served sensor"
    );
    c.stop().await.expect("stop");
    assert!(matches!(
        c.read(&mut Vec::new()).await,
        Err(DeviceError::InvalidCommand { .. })
    ));
    let _ = srv.stop.send(());
    let stats = srv.task.await.expect("join").expect("server ran");
    assert!(
        stats.records_sent >= 300 && stats.commands >= 2,
        "{stats:?}"
    );
}

#[tokio::test]
async fn buffered_mode_back_dates_records_within_a_datagram() {
    let srv = spawn_server(PatternSensor::new(5000.0), 10).await;
    let mut cfg = client_config(srv.rdt, srv.cal, 5000.0);
    cfg.mode = StreamMode::Buffered;
    let mut c = NetFtClient::connect(cfg, clock()).await.expect("connect");
    c.start().await.expect("start");
    let got = read_at_least(&mut c, 500).await;
    for w in got.windows(2) {
        assert_eq!(w[1].rdt_sequence, w[0].rdt_sequence + 1);
    }
    assert_eq!(c.lost_readings(), 0);
    c.stop().await.expect("stop");
    let _ = srv.stop.send(());
    let stats = srv.task.await.expect("join").expect("server");
    assert!(
        stats.datagrams_sent * 2 < stats.records_sent,
        "several records per datagram: {stats:?}"
    );
}

#[tokio::test]
async fn readings_the_sensor_loses_are_counted_from_sequence_gaps() {
    let mut sensor = PatternSensor::new(2000.0);
    sensor.lose_every = Some(10);
    sensor.fault_every = Some((25, FtStatus::SATURATED.0));
    let srv = spawn_server(sensor, 10).await;
    let mut c = NetFtClient::connect(client_config(srv.rdt, srv.cal, 2000.0), clock())
        .await
        .expect("connect");
    c.start().await.expect("start");
    let got = read_at_least(&mut c, 400).await;
    let span = u64::from(got.last().expect("some").rdt_sequence - got[0].rdt_sequence) + 1;
    assert_eq!(
        span,
        got.len() as u64 + c.lost_readings(),
        "every gap is counted"
    );
    assert!(c.lost_readings() >= 40);
    // Faulted readings are delivered and counted; the status is latched.
    assert!(got.iter().any(|r| r.status.is_fault()));
    assert!(c.stats().faulted > 0);
    assert_eq!(c.latched_status(), FtStatus::SATURATED);
    let _ = srv.stop.send(());
}

#[tokio::test]
async fn the_simulators_force_sensor_served_over_rdt_reaches_the_client() {
    use softtouch_schemas::defaults;
    let rig =
        softtouch_sim::SimRig::new(&defaults::rig(), &defaults::scene(), 7, TokioClock::new())
            .expect("sim rig");
    let srv = spawn_server(rig.force_sensor, 10).await;
    let mut c = NetFtClient::connect(client_config(srv.rdt, srv.cal, 1000.0), clock())
        .await
        .expect("connect");
    c.start().await.expect("start");
    let got = read_at_least(&mut c, 300).await;
    assert!(
        got.iter()
            .all(|r| r.wrench_in_sensor.to_array().iter().all(|v| v.is_finite()))
    );
    for w in got.windows(2) {
        assert!(
            w[1].ft_sequence > w[0].ft_sequence,
            "the sensor's own counter is kept"
        );
    }
    let span = u64::from(got.last().expect("some").rdt_sequence - got[0].rdt_sequence) + 1;
    assert_eq!(span, got.len() as u64 + c.lost_readings());
    c.stop().await.expect("stop");
    let _ = srv.stop.send(());
    srv.task.await.expect("join").expect("server");
}

// ------------------------------------------------------------ hand-made peers

/// A fake sensor: a bare UDP socket the test drives by hand.
async fn peer_and_client(reply_timeout_ms: u64, attempts: u32) -> (UdpSocket, NetFtClient) {
    let peer = UdpSocket::bind(local()).await.expect("peer");
    let mut cfg = NetFtConfig::new(peer.local_addr().expect("addr"), 1000.0);
    cfg.scaling = Scaling::Given {
        counts_per_force: 1e6,
        counts_per_torque: 1e6,
    };
    cfg.reply_timeout = Duration::from_millis(reply_timeout_ms);
    cfg.read_timeout = Duration::from_millis(200);
    cfg.start_attempts = attempts;
    let c = NetFtClient::connect(cfg, clock()).await.expect("connect");
    (peer, c)
}

fn rec(seq: u32, status: u32) -> [u8; codec::RECORD_LEN] {
    codec::encode_record(&RawRecord {
        rdt_sequence: seq,
        ft_sequence: seq.wrapping_mul(3),
        status,
        counts: [1_000_000, 0, 0, 0, 0, 500_000],
    })
}

/// Wait for the start command and answer with one record of `seq`.
async fn accept_start(peer: &UdpSocket, seq: u32) -> SocketAddr {
    let mut b = [0u8; 64];
    let (n, from) = peer.recv_from(&mut b).await.expect("start command");
    let req = codec::decode_request(&b[..n]).expect("valid request");
    assert_eq!(req.command, Command::RealTime);
    assert_eq!(req.sample_count, 0);
    peer.send_to(&rec(seq, 0), from).await.expect("send");
    from
}

#[tokio::test]
async fn a_lost_start_command_is_sent_again() {
    let (peer, mut c) = peer_and_client(50, 10).await;
    let fake = tokio::spawn(async move {
        let mut b = [0u8; 64];
        // Ignore the first three start commands, as if they were lost.
        for _ in 0..3 {
            peer.recv_from(&mut b).await.expect("start");
        }
        accept_start(&peer, 1).await;
        peer
    });
    c.start().await.expect("start after retries");
    // At least the three lost ones and the answered one. On a loaded machine the peer
    // may answer after the 50 ms reply timeout, so the client may have sent more.
    let sent = c.stats().start_commands;
    assert!((4..=10).contains(&sent), "{sent} start commands");
    let mut out = Vec::new();
    assert_eq!(
        c.read(&mut out).await.expect("read"),
        1,
        "the confirming record is delivered"
    );
    assert!(
        close(out[0].wrench_in_sensor.force_n[0], 1.0)
            && close(out[0].wrench_in_sensor.torque_nm[2], 0.5)
    );
    drop(fake.await);
}

#[tokio::test]
async fn a_sensor_that_never_answers_times_out_clearly() {
    let (_peer, mut c) = peer_and_client(20, 3).await;
    let t0 = tokio::time::Instant::now();
    let e = c.start().await.expect_err("no answer");
    assert!(matches!(e, DeviceError::Timeout { .. }), "{e}");
    assert!(e.is_link() && !e.is_fault());
    assert_eq!(c.stats().start_commands, 3);
    // It waited out every attempt, and gave up: bounds that hold on a loaded machine.
    let waited = t0.elapsed();
    assert!(
        waited >= Duration::from_millis(60) && waited < Duration::from_secs(30),
        "{waited:?}"
    );
}

#[tokio::test]
async fn a_sensor_that_stops_answering_mid_stream_times_out() {
    let (peer, mut c) = peer_and_client(200, 1).await;
    let fake = tokio::spawn(async move {
        accept_start(&peer, 1).await;
        peer
    });
    c.start().await.expect("start");
    let _peer = fake.await.expect("peer");
    let mut out = Vec::new();
    assert_eq!(c.read(&mut out).await.expect("first"), 1);
    let e = c.read(&mut out).await.expect_err("silence");
    assert!(
        matches!(
            e,
            DeviceError::Timeout {
                timeout_ms: 200,
                ..
            }
        ),
        "{e}"
    );
}

#[tokio::test]
async fn a_stream_that_stops_is_asked_for_again_and_goes_on() {
    // A sensor that reboots (or is stopped by another client) mid-run streams again
    // only on a new start command; its sequence then starts over.
    let (peer, mut c) = peer_and_client(200, 1).await;
    let fake = tokio::spawn(async move {
        let to = accept_start(&peer, 41).await;
        peer.send_to(&rec(42, 0), to).await.expect("send");
        // Silent now; the client's second start command gets a fresh stream.
        let restarted_from = accept_start(&peer, 1).await;
        assert_eq!(restarted_from, to);
        peer.send_to(&rec(2, 0), to).await.expect("send");
        peer
    });
    let mut batch = Vec::new();
    c.start().await.expect("start");
    // read_timeout 200 ms, the restart after 100 ms of silence.
    let mut seen = Vec::new();
    while seen.len() < 4 {
        batch.clear();
        c.read(&mut batch)
            .await
            .unwrap_or_else(|e| panic!("read after {} readings: {e}", seen.len()));
        seen.extend(batch.iter().map(|r| r.rdt_sequence));
    }
    assert_eq!(seen, [41, 42, 1, 2]);
    let stats = c.stats();
    assert_eq!(stats.restarts, 1, "{stats:?}");
    assert_eq!(
        (stats.lost, stats.out_of_order),
        (0, 0),
        "a new stream, not a gap"
    );
    drop(fake.await);
}

#[tokio::test]
async fn a_late_datagram_of_the_old_stream_does_not_stall_the_new_one() {
    // After an hour at 1 kHz the sensor is restarted; one datagram of the old stream
    // (sequence 3 600 000) arrives after the restart. Taken as the new baseline, it
    // would hold back every record of the new stream (1, 2, ...) as old for an hour.
    let (peer, mut c) = peer_and_client(200, 1).await;
    let fake = tokio::spawn(async move {
        let to = accept_start(&peer, 1).await;
        peer.send_to(&rec(2, 0), to).await.expect("send");
        // Silent now; what answers the restart first is the old stream's straggler.
        let restarted_from = accept_start(&peer, 3_600_000).await;
        assert_eq!(restarted_from, to);
        for seq in 1..=3 {
            peer.send_to(&rec(seq, 0), to).await.expect("send");
        }
        peer
    });
    let mut batch = Vec::new();
    c.start().await.expect("start");
    let mut seen = Vec::new();
    while seen.len() < 5 {
        batch.clear();
        c.read(&mut batch)
            .await
            .unwrap_or_else(|e| panic!("read after {seen:?}: {e}"));
        seen.extend(batch.iter().map(|r| r.rdt_sequence));
    }
    assert_eq!(seen, [1, 2, 1, 2, 3]);
    let stats = c.stats();
    assert_eq!(stats.restarts, 1, "{stats:?}");
    assert_eq!(
        stats.out_of_order, 1,
        "the old stream's late record: {stats:?}"
    );
    drop(fake.await);
}

#[tokio::test]
async fn datagrams_read_together_are_stamped_a_period_apart() {
    // A host busy for 30 ms reads five queued datagrams at once; they were sampled
    // 1 ms apart (1000 Hz), and their stamps say so.
    let (peer, mut c) = peer_and_client(200, 1).await;
    let fake = tokio::spawn(async move {
        let to = accept_start(&peer, 1).await;
        for seq in 2..=6 {
            peer.send_to(&rec(seq, 0), to).await.expect("send");
        }
        peer
    });
    c.start().await.expect("start");
    let _peer = fake.await.expect("peer");
    tokio::time::sleep(Duration::from_millis(30)).await;
    let mut out = Vec::new();
    while out.len() < 6 {
        c.read(&mut out).await.expect("read");
    }
    let seqs: Vec<u32> = out.iter().map(|r| r.rdt_sequence).collect();
    assert_eq!(seqs, [1, 2, 3, 4, 5, 6]);
    for w in out.windows(2) {
        let dt = w[1].t.0 - w[0].t.0;
        assert!(
            dt.abs_diff(1_000_000) <= 1,
            "{dt} ns between {} and {}",
            w[0].rdt_sequence,
            w[1].rdt_sequence
        );
    }
}

#[tokio::test]
async fn sequence_gaps_wraps_and_backward_steps_are_counted() {
    let (peer, mut c) = peer_and_client(200, 1).await;
    let fake = tokio::spawn(async move {
        let to = accept_start(&peer, 0xFFFF_FFFE).await;
        // Wrap at 2^32 with one record (0x0000_0000) missing, then a record going
        // backwards (stale), then a gap of two.
        for seq in [0xFFFF_FFFF, 1, 0xFFFF_FFFF, 2, 5] {
            peer.send_to(&rec(seq, 0), to).await.expect("send");
        }
        peer
    });
    c.start().await.expect("start");
    let _peer = fake.await.expect("peer");
    let mut out = Vec::new();
    while out.len() < 5 {
        c.read(&mut out).await.expect("read");
    }
    let seqs: Vec<u32> = out.iter().map(|r| r.rdt_sequence).collect();
    assert_eq!(seqs, [0xFFFF_FFFE, 0xFFFF_FFFF, 1, 2, 5]);
    assert_eq!(
        c.lost_readings(),
        1 + 2,
        "0 lost at the wrap, 3 and 4 lost later"
    );
    assert_eq!(c.stats().out_of_order, 1);
    assert_eq!(out[2].ft_sequence, 3, "ft_sequence kept as sent");
}

#[tokio::test]
async fn status_words_are_decoded_as_warning_or_fault_and_still_delivered() {
    let (peer, mut c) = peer_and_client(200, 1).await;
    let fake = tokio::spawn(async move {
        let to = accept_start(&peer, 1).await;
        peer.send_to(&rec(2, FtStatus::MONITOR_LATCHED.0), to)
            .await
            .expect("send");
        peer.send_to(&rec(3, 0x0010_0000), to).await.expect("send");
        peer
    });
    c.start().await.expect("start");
    let _peer = fake.await.expect("peer");
    let mut out = Vec::new();
    while out.len() < 3 {
        c.read(&mut out).await.expect("read");
    }
    assert!(out[1].status.is_warning() && !out[1].status.is_fault());
    assert!(out[2].status.is_fault());
    let s = c.stats();
    assert_eq!((s.warnings, s.faulted), (1, 1));
    assert_eq!(c.latched_status(), FtStatus::MONITOR_LATCHED);
    c.clear_latched_status();
    assert_eq!(c.latched_status(), FtStatus::OK);
}

/// Malformed datagrams among good ones are counted and skipped: the good readings of
/// the same read are kept. A read that gets nothing but malformed datagrams until its
/// timeout reports the protocol error.
#[tokio::test]
async fn malformed_datagrams_are_counted_and_skipped_keeping_the_good_readings() {
    let (peer, mut c) = peer_and_client(200, 1).await;
    let fake = tokio::spawn(async move {
        let to = accept_start(&peer, 1).await;
        peer.send_to(&rec(2, 0), to).await.expect("valid");
        peer.send_to(&[0u8; 10], to).await.expect("truncated");
        peer.send_to(
            &vec![0u8; codec::RECORD_LEN * (codec::MAX_RECORDS_PER_DATAGRAM + 1)],
            to,
        )
        .await
        .expect("oversized");
        peer.send_to(&[7u8; 37], to).await.expect("partial");
        peer.send_to(b"GET / HTTP/1.0\r\n\r\n", to)
            .await
            .expect("random");
        peer.send_to(&rec(3, 0), to).await.expect("valid");
        (peer, to)
    });
    c.start().await.expect("start");
    let (peer, to) = fake.await.expect("peer");
    // Loopback datagrams are queued when `send_to` returns; wait for the last anyway.
    let mut out = Vec::new();
    let deadline = tokio::time::Instant::now() + Duration::from_secs(5);
    while out.len() < 3 && tokio::time::Instant::now() < deadline {
        c.read(&mut out)
            .await
            .expect("no error: bad datagrams are skipped");
    }
    let seqs: Vec<u32> = out.iter().map(|r| r.rdt_sequence).collect();
    assert_eq!(seqs, [1, 2, 3]);
    assert_eq!(c.stats().bad_datagrams, 4);
    assert_eq!(c.stats().lost, 0);

    // Only garbage, then silence: the read fails with the protocol error, counted.
    peer.send_to(&[1u8; 5], to).await.expect("garbage");
    let e = c.read(&mut out).await.expect_err("nothing valid came");
    assert!(matches!(e, DeviceError::Protocol { .. }), "{e}");
    assert_eq!(c.stats().bad_datagrams, 5);
    assert_eq!(out.len(), 3);
}

async fn fake_tcp(reply: Vec<u8>, answer: bool) -> SocketAddr {
    let l = TcpListener::bind(local()).await.expect("bind");
    let a = l.local_addr().expect("addr");
    tokio::spawn(async move {
        let (mut s, _) = l.accept().await.expect("accept");
        let mut req = [0u8; 20];
        let _ = s.read(&mut req).await;
        if answer {
            let _ = s.write_all(&reply).await;
            let _ = s.shutdown().await;
        } else {
            tokio::time::sleep(Duration::from_secs(5)).await;
        }
    });
    a
}

async fn connect_with(scaling: Scaling) -> Result<NetFtClient, DeviceError> {
    let mut cfg = NetFtConfig::new(local(), 1000.0);
    cfg.scaling = scaling;
    cfg.reply_timeout = Duration::from_millis(200);
    NetFtClient::connect(cfg, clock()).await
}

#[tokio::test]
async fn bad_calibration_replies_are_refused() {
    let good = codec::encode_calibration_reply(&Calibration::si(1_000_000, 1_000_000));
    let mut wrong_header = good;
    wrong_header[0] = 0x43;
    let a = fake_tcp(wrong_header.to_vec(), true).await;
    assert!(matches!(
        connect_with(Scaling::CalibrationRequest(a)).await,
        Err(DeviceError::Protocol { .. })
    ));
    let a = fake_tcp(good[..10].to_vec(), true).await;
    assert!(matches!(
        connect_with(Scaling::CalibrationRequest(a)).await,
        Err(DeviceError::Protocol { .. })
    ));
    let mut bad_unit = good;
    bad_unit[2] = 77;
    let a = fake_tcp(bad_unit.to_vec(), true).await;
    assert!(matches!(
        connect_with(Scaling::CalibrationRequest(a)).await,
        Err(DeviceError::Protocol { .. })
    ));
    let a = fake_tcp(Vec::new(), false).await;
    assert!(matches!(
        connect_with(Scaling::CalibrationRequest(a)).await,
        Err(DeviceError::Timeout { .. })
    ));
    let a = fake_tcp(good.to_vec(), true).await;
    assert_eq!(
        connect_with(Scaling::CalibrationRequest(a))
            .await
            .expect("good")
            .scaling(),
        (1e6, 1e6)
    );
}

#[tokio::test]
async fn counts_per_unit_can_come_from_netftapi2_xml() {
    let page = "HTTP/1.0 200 OK\r\nContent-Type: text/xml\r\n\r\n<?xml version=\"1.0\"?><netft>\
                <cfgcpf>1000000</cfgcpf><cfgcpt>1000</cfgcpt><scfgfu>N</scfgfu><scfgtu>Nmm</scfgtu></netft>";
    let a = fake_tcp(page.as_bytes().to_vec(), true).await;
    let c = connect_with(Scaling::Http(a)).await.expect("http");
    assert_eq!(c.scaling(), (1e6, 1e6));
    let a = fake_tcp(b"HTTP/1.0 404 Not Found\r\n\r\n".to_vec(), true).await;
    assert!(matches!(
        connect_with(Scaling::Http(a)).await,
        Err(DeviceError::Protocol { .. })
    ));
}

#[tokio::test]
async fn the_server_ignores_garbage_requests_and_serves_a_sample_count() {
    let srv = spawn_server(PatternSensor::new(2000.0), 10).await;
    let sock = UdpSocket::bind(local()).await.expect("bind");
    sock.connect(srv.rdt).await.expect("connect");
    sock.send(&[1, 2, 3]).await.expect("garbage");
    sock.send(&[0x43, 0x21, 0, 2, 0, 0, 0, 0])
        .await
        .expect("wrong header");
    sock.send(&codec::encode_request(Command::RealTime, 5))
        .await
        .expect("five");
    let mut b = [0u8; 512];
    let mut seqs = Vec::new();
    while let Ok(Ok(n)) = tokio::time::timeout(Duration::from_millis(300), sock.recv(&mut b)).await
    {
        let mut recs = Vec::new();
        codec::decode_records(&b[..n], &mut recs).expect("valid");
        seqs.extend(recs.iter().map(|r| r.rdt_sequence));
    }
    assert_eq!(seqs, [1, 2, 3, 4, 5], "exactly sample_count records");
    let _ = srv.stop.send(());
    let stats = srv.task.await.expect("join").expect("server");
    assert_eq!((stats.bad_requests, stats.commands), (2, 1));
}

/// Vendor bytes, not our encoder (network byte order, per ATI's Net F/T manual): the
/// calibration reply of a Nano17 in N and N·mm (header 0x1234, units 2 and 4, CpF 1e6,
/// CpT 1000 per N·mm, scale 1s), the start request our client must send (header,
/// command 0x0002, count 0), and one RDT record; decoded by our client.
#[tokio::test]
async fn a_literal_calibration_reply_and_rdt_record_decode_through_our_client() {
    const CALIBRATION_REPLY: [u8; 24] = [
        0x12, 0x34, 0x02, 0x04, 0x00, 0x0F, 0x42, 0x40, 0x00, 0x00, 0x03, 0xE8, 0x00, 0x01, 0x00,
        0x01, 0x00, 0x01, 0x00, 0x01, 0x00, 0x01, 0x00, 0x01,
    ];
    const START_REQUEST: [u8; 8] = [0x12, 0x34, 0x00, 0x02, 0x00, 0x00, 0x00, 0x00];
    const RECORD: [u8; 36] = [
        0x00, 0x00, 0x00, 0x01, // rdt_sequence 1
        0x00, 0x00, 0x0A, 0x2B, // ft_sequence 2603
        0x00, 0x00, 0x00, 0x00, // status OK
        0x00, 0x0F, 0x42, 0x40, // Fx 1 000 000 counts
        0xFF, 0xF8, 0x5E, 0xE0, // Fy −500 000
        0x00, 0x26, 0x25, 0xA0, // Fz 2 500 000
        0x00, 0x00, 0x03, 0xE8, // Tx 1000
        0xFF, 0xFF, 0xFC, 0x18, // Ty −1000
        0x00, 0x00, 0x00, 0x00, // Tz 0
    ];
    let cal = fake_tcp(CALIBRATION_REPLY.to_vec(), true).await;
    let peer = UdpSocket::bind(local()).await.expect("peer");
    let mut cfg = NetFtConfig::new(peer.local_addr().expect("addr"), 1000.0);
    cfg.scaling = Scaling::CalibrationRequest(cal);
    cfg.reply_timeout = Duration::from_secs(2);
    let mut c = NetFtClient::connect(cfg, clock()).await.expect("connect");
    assert_eq!(c.scaling(), (1e6, 1e6), "counts per N and per N·m");
    let fake = tokio::spawn(async move {
        let mut b = [0u8; 64];
        let (n, from) = peer.recv_from(&mut b).await.expect("start");
        peer.send_to(&RECORD, from).await.expect("record");
        b[..n].to_vec()
    });
    c.start().await.expect("start");
    assert_eq!(fake.await.expect("peer"), START_REQUEST);
    let r = read_at_least(&mut c, 1).await;
    assert_eq!((r[0].rdt_sequence, r[0].ft_sequence), (1, 2603));
    assert!(r[0].status.is_ok());
    let w = r[0].wrench_in_sensor;
    assert_eq!(w.force_n, [1.0, -0.5, 2.5]);
    assert_eq!(w.torque_nm, [0.001, -0.001, 0.0]);
}
