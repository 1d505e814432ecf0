//! The Hand-E driver against the simulated Hand-E (the simulator's gripper behind
//! the Modbus register map), over an in-memory pipe and a pty pair, and against
//! hand-made peers for CRC errors, exception replies and silence.

mod common;

use softtouch_drivers::gripper::{GripperCommand, ObjectStatus, opening_mm};
use softtouch_drivers::hande::{self, HandE, HandEConfig, HandEService, regs};
use softtouch_drivers::{Clock, DeviceError, Gripper, TokioClock};
use softtouch_schemas::defaults;
use softtouch_sim::SimRig;
use std::sync::Arc;
use std::time::Duration;
use tokio::io::{AsyncReadExt, AsyncWriteExt};

fn sim_service() -> HandEService<softtouch_sim::SimGripper> {
    let rig =
        SimRig::new(&defaults::rig(), &defaults::scene(), 3, TokioClock::new()).expect("sim rig");
    HandEService::new(rig.gripper, 9)
}

fn pipe_pair(service: HandEService<softtouch_sim::SimGripper>) -> (HandE, Arc<TokioClock>) {
    let (a, b) = tokio::io::duplex(1024);
    tokio::spawn(hande::serve_rtu(service, b, std::future::pending()));
    let clock = Arc::new(TokioClock::new());
    (HandE::new(a, HandEConfig::default(), clock.clone()), clock)
}

const CLOSE: GripperCommand = GripperCommand {
    position: 255,
    speed: 255,
    force: 255,
};

async fn wait_until_still(g: &mut HandE) -> softtouch_drivers::GripperStatus {
    loop {
        let s = g.status().await.expect("status");
        if s.object != ObjectStatus::Moving {
            return s;
        }
    }
}

#[tokio::test(start_paused = true)]
async fn activates_moves_and_reports_status_through_the_simulated_hand_e() {
    let (mut g, clock) = pipe_pair(sim_service());
    let s = g.status().await.expect("status");
    assert!(!s.activated);
    g.activate().await.expect("activate");
    assert!(g.status().await.expect("status").activated);
    g.command(CLOSE).await.expect("close");
    let s = wait_until_still(&mut g).await;
    assert_eq!(s.object, ObjectStatus::AtPosition);
    assert_eq!((s.requested_position, s.position, s.fault), (255, 255, 0));
    assert!(opening_mm(s.position) < 0.1);
    g.command(GripperCommand {
        position: 0,
        ..CLOSE
    })
    .await
    .expect("open");
    let s = wait_until_still(&mut g).await;
    assert!((opening_mm(s.position) - 50.0).abs() < 0.2, "{s:?}");
    // Never faster than 200 transactions per second, on the injected clock.
    let n = g.stats().transactions;
    let elapsed_ms = clock.now().0 / 1_000_000;
    assert!(
        elapsed_ms >= (n - 1) * 5,
        "{n} transactions in {elapsed_ms} ms"
    );
}

#[tokio::test(start_paused = true)]
async fn commands_are_paced_at_most_200_per_second() {
    let (mut g, clock) = pipe_pair(sim_service());
    let t0 = clock.now();
    for _ in 0..100 {
        g.status().await.expect("status");
    }
    let ms = (clock.now().0 - t0.0) as f64 / 1e6;
    assert!(ms >= 99.0 * 5.0, "100 reads in {ms} ms");
}

#[tokio::test(start_paused = true)]
async fn a_major_fault_needs_a_new_activation_edge() {
    let service = sim_service();
    let (mut g, _clock) = pipe_pair(service.clone());
    g.activate().await.expect("activate");
    service.inject_fault(0x0E);
    let s = g.status().await.expect("status");
    assert_eq!(s.fault, 0x0E);
    let e = g.command(CLOSE).await.expect_err("refused");
    assert!(
        matches!(
            e,
            DeviceError::Fault {
                code: Some(0x0E),
                ..
            }
        ),
        "{e}"
    );
    assert!(e.is_fault() && !e.is_link());
    g.activate().await.expect("re-activation clears it");
    assert_eq!(g.status().await.expect("status").fault, 0);
    g.command(CLOSE).await.expect("moves again");
}

#[tokio::test(start_paused = true)]
async fn activation_waits_out_a_slow_reset_and_the_stale_fault_before_it() {
    // A gripper that takes 80 ms to act on an rACT edge: right after rACT 0 it still
    // reads active, and right after rACT 1 it still shows the old major fault.
    let service = sim_service().with_edge_latency(Duration::from_millis(80));
    let (mut g, _clock) = pipe_pair(service.clone());
    g.activate().await.expect("first activation");
    service.inject_fault(0x0E);
    assert_eq!(g.status().await.expect("status").fault, 0x0E);
    g.activate()
        .await
        .expect("re-activation waits for the reset, then the edge");
    let s = g.status().await.expect("status");
    assert!(s.activated && s.fault == 0, "{s:?}");
    g.command(CLOSE).await.expect("moves again");
    assert_eq!(wait_until_still(&mut g).await.position, 255);
}

#[tokio::test(start_paused = true)]
async fn a_late_reply_is_flushed_and_never_taken_for_the_next_requests() {
    // The gripper answers the first status read 300 ms late (the client waits 200 ms),
    // then on time. Without the flush the late status reply would be read as the
    // write's reply (a function-code mismatch) and every later reply would be one
    // request behind.
    let service = sim_service();
    let (mut g, _clock) = pipe_pair(service.clone());
    g.activate().await.expect("activate");
    service.delay_next_reply(Duration::from_millis(300));
    let e = g.status().await.expect_err("the late reply times out");
    assert!(matches!(e, DeviceError::Timeout { .. }), "{e}");
    g.command(GripperCommand {
        position: 120,
        ..CLOSE
    })
    .await
    .expect("the next request gets its own reply");
    let s = wait_until_still(&mut g).await;
    assert_eq!((s.requested_position, s.position, s.fault), (120, 120, 0));
    let stats = g.stats();
    assert_eq!((stats.timeouts, stats.flushes), (1, 1), "{stats:?}");
    // The dropped bytes are the late reply: 3 registers read, 11 bytes on the wire.
    assert_eq!(stats.flushed_bytes, 11, "{stats:?}");
    for _ in 0..5 {
        assert_eq!(g.status().await.expect("on time").requested_position, 120);
    }
}

#[tokio::test(start_paused = true)]
async fn a_move_and_its_status_go_in_one_function_23_transaction() {
    let service = sim_service();
    let (mut g, _clock) = pipe_pair(service.clone());
    g.activate().await.expect("activate");
    let before = (service.requests(), g.stats().transactions);
    let s = g
        .command_and_status(GripperCommand {
            position: 90,
            ..CLOSE
        })
        .await
        .expect("exchange");
    assert_eq!(
        (service.requests(), g.stats().transactions),
        (before.0 + 1, before.1 + 1),
        "one request on the wire"
    );
    // Read after the write: the request is echoed, the fingers have not moved yet.
    assert_eq!((s.requested_position, s.fault), (90, 0));
    assert!(s.activated);
    assert_eq!(wait_until_still(&mut g).await.position, 90);
    // Refused, without sending, as a plain command is, on a major fault.
    service.inject_fault(0x0E);
    g.status().await.expect("status");
    let n = service.requests();
    let e = g.command_and_status(CLOSE).await.expect_err("refused");
    assert!(e.to_string().contains("overcurrent"), "{e}");
    assert_eq!(service.requests(), n);
}

#[tokio::test(start_paused = true)]
async fn a_gripper_in_fault_0x05_at_start_activates() {
    // A command sent before activation (or one left from before an emergency stop)
    // leaves gFLT 0x05; the activation sequence clears it.
    let service = sim_service();
    service.inject_fault(0x05);
    let (mut g, _clock) = pipe_pair(service.clone());
    assert_eq!(g.status().await.expect("status").fault, 0x05);
    g.activate().await.expect("activates through 0x05");
    let s = g.status().await.expect("status");
    assert!(s.activated && s.fault == 0, "{s:?}");
    g.command(CLOSE).await.expect("moves");
}

#[tokio::test(start_paused = true)]
async fn activating_an_active_gripper_only_reads_its_status() {
    let service = sim_service();
    let (mut g, _clock) = pipe_pair(service.clone());
    g.activate().await.expect("activate");
    g.command(CLOSE).await.expect("close");
    let held = wait_until_still(&mut g).await;
    let before = service.requests();
    g.activate().await.expect("again");
    assert_eq!(service.requests(), before + 1, "one status read, no reset");
    let s = g.status().await.expect("status");
    assert_eq!((s.position, s.requested_position), (held.position, 255));
}

#[tokio::test(start_paused = true)]
async fn an_activation_that_never_completes_names_the_fault_it_ends_on() {
    // Edges that are never acted on within the limit: the gripper keeps its fault.
    let service = sim_service().with_edge_latency(Duration::from_secs(3600));
    let (a, b) = tokio::io::duplex(1024);
    tokio::spawn(hande::serve_rtu(service.clone(), b, std::future::pending()));
    let config = HandEConfig {
        activation_timeout: Duration::from_secs(2),
        ..HandEConfig::default()
    };
    let mut g = HandE::new(a, config, Arc::new(TokioClock::new()));
    service.inject_fault(0x0D);
    let e = g.activate().await.expect_err("never activates");
    assert!(
        matches!(
            e,
            DeviceError::Fault {
                code: Some(0x0D),
                ..
            }
        ),
        "{e}"
    );
    let text = e.to_string();
    assert!(
        text.contains("activation did not complete within 2000 ms"),
        "{text}"
    );
    assert!(text.contains("activation fault"), "{text}");
}

#[tokio::test]
async fn works_over_a_pty_pair_with_the_tokio_modbus_rtu_server() {
    let Some(pair) = common::pty_pair() else {
        return;
    };
    let server_port = hande::open_port(&pair.b).expect("open pty b");
    let client_port = hande::open_port(&pair.a).expect("open pty a");
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    let server = tokio::spawn(hande::serve_serial(
        sim_service(),
        server_port,
        async move {
            let _ = rx.await;
        },
    ));
    let mut g = HandE::new(
        client_port,
        HandEConfig::default(),
        Arc::new(TokioClock::new()),
    );
    g.activate().await.expect("activate");
    g.command(GripperCommand {
        position: 128,
        speed: 255,
        force: 100,
    })
    .await
    .expect("move");
    let s = wait_until_still(&mut g).await;
    assert_eq!(s.position, 128);
    let _ = tx.send(());
    server.await.expect("join").expect("server");
}

/// A hand-made slave that answers the first request with `reply` (CRC appended,
/// then byte `corrupt` flipped if given), and every later one correctly.
async fn scripted(reply: Vec<u8>, corrupt: Option<usize>, silent: bool) -> HandE {
    let (a, mut b) = tokio::io::duplex(1024);
    tokio::spawn(async move {
        let mut buf = [0u8; 64];
        let mut first = true;
        loop {
            let Ok(n) = b.read(&mut buf).await else {
                return;
            };
            if n == 0 || silent {
                if n == 0 {
                    return;
                }
                continue;
            }
            let mut out = if first {
                reply.clone()
            } else {
                vec![9, 4, 6, 0x31, 0, 0, 0, 0, 0]
            };
            let crc = regs::crc16(&out);
            out.extend_from_slice(&crc.to_le_bytes());
            if first && let Some(i) = corrupt {
                out[i] ^= 0x40;
            }
            first = false;
            let _ = b.write_all(&out).await;
        }
    });
    let config = HandEConfig {
        reply_timeout: Duration::from_millis(100),
        ..HandEConfig::default()
    };
    HandE::new(a, config, Arc::new(TokioClock::new()))
}

#[tokio::test(start_paused = true)]
async fn a_reply_with_a_bad_crc_is_never_taken_as_data() {
    let reply = vec![9, 4, 6, 0x31, 0, 0, 0, 0, 0];
    for i in [3, 9] {
        let mut g = scripted(reply.clone(), Some(i), false).await;
        let e = g.status().await.expect_err("corrupted");
        assert!(e.is_link(), "corrupt byte {i}: {e}");
        assert!(!e.is_fault());
    }
}

#[tokio::test(start_paused = true)]
async fn exception_replies_are_device_faults_with_their_code() {
    let mut g = scripted(vec![9, 0x84, 0x02], None, false).await;
    let e = g.status().await.expect_err("exception");
    assert!(matches!(e, DeviceError::Fault { code: Some(2), .. }), "{e}");
    assert_eq!(g.stats().exceptions, 1);
    assert!(g.status().await.expect("next one answers").activated);
}

#[tokio::test(start_paused = true)]
async fn a_silent_gripper_times_out() {
    let mut g = scripted(Vec::new(), None, true).await;
    let e = g.status().await.expect_err("silence");
    assert!(
        matches!(
            e,
            DeviceError::Timeout {
                timeout_ms: 100,
                ..
            }
        ),
        "{e}"
    );
    let e = g.activate().await.expect_err("silence");
    assert!(matches!(e, DeviceError::Timeout { .. }), "{e}");
}

#[tokio::test(start_paused = true)]
async fn the_simulated_hand_e_refuses_registers_outside_its_map() {
    use tokio_modbus::client::{Reader, rtu};
    use tokio_modbus::{ExceptionCode, Slave};
    let (a, b) = tokio::io::duplex(1024);
    tokio::spawn(hande::serve_rtu(sim_service(), b, std::future::pending()));
    let mut ctx = rtu::attach_slave(a, Slave(9));
    let r = ctx
        .read_input_registers(0x0000, 3)
        .await
        .expect("transport");
    assert_eq!(r, Err(ExceptionCode::IllegalDataAddress));
    let r = ctx.read_coils(0, 1).await.expect("transport");
    assert_eq!(r, Err(ExceptionCode::IllegalFunction));
}

/// Vendor bytes, not our encoder: the Hand-E manual's close command (slave 9, function
/// 16 at 0x03E8: rACT|rGTO, position, speed and force 0xFF) and its echo reply, then
/// the manual's status example "object detected while closing" (B9 00 00 FF BD 00),
/// answered to our function-04 read. Every CRC is literal.
#[tokio::test(start_paused = true)]
async fn the_manuals_close_command_and_status_reply_match_our_client_byte_for_byte() {
    const CLOSE_REQUEST: [u8; 15] = [
        0x09, 0x10, 0x03, 0xE8, 0x00, 0x03, 0x06, 0x09, 0x00, 0x00, 0xFF, 0xFF, 0xFF, 0x42, 0x29,
    ];
    const CLOSE_REPLY: [u8; 8] = [0x09, 0x10, 0x03, 0xE8, 0x00, 0x03, 0x01, 0x30];
    const STATUS_REQUEST: [u8; 8] = [0x09, 0x04, 0x07, 0xD0, 0x00, 0x03, 0xB1, 0xCE];
    const STATUS_REPLY: [u8; 11] = [
        0x09, 0x04, 0x06, 0xB9, 0x00, 0x00, 0xFF, 0xBD, 0x00, 0x5C, 0x9A,
    ];
    let (a, mut b) = tokio::io::duplex(1024);
    let peer = tokio::spawn(async move {
        let mut seen = Vec::new();
        for (request, reply) in [
            (&CLOSE_REQUEST[..], &CLOSE_REPLY[..]),
            (&STATUS_REQUEST[..], &STATUS_REPLY[..]),
        ] {
            let mut got = vec![0u8; request.len()];
            b.read_exact(&mut got).await.expect("request");
            seen.push(got);
            b.write_all(reply).await.expect("reply");
        }
        seen
    });
    let mut g = HandE::new(a, HandEConfig::default(), Arc::new(TokioClock::new()));
    g.command(CLOSE)
        .await
        .expect("the manual's echo is accepted");
    let s = g.status().await.expect("the manual's status decodes");
    let seen = peer.await.expect("peer");
    assert_eq!(seen[0], CLOSE_REQUEST, "close command bytes");
    assert_eq!(seen[1], STATUS_REQUEST, "status request bytes");
    assert!(s.activated, "gACT and gSTA = 3");
    assert_eq!(s.object, ObjectStatus::ContactClosing, "gOBJ = 2");
    assert_eq!((s.fault, s.requested_position, s.position), (0, 0xFF, 0xBD));
    assert_eq!(s.current_ma, 0);
}
