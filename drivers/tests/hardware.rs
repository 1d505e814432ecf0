//! Hardware tier (TESTING.md): the real force/torque sensors and the Hand-E, on the wall
//! clock. Always `#[ignore]`; run with `--ignored`. Each test reads its device from an
//! environment variable, and a missing one FAILS the test (naming the variable) rather
//! than passing it untested.
//!
//! ```text
//! SOFTTOUCH_NETFT_ADDRESS=192.168.1.1 SOFTTOUCH_ATI_PORT=/dev/ttyUSB0 \
//! SOFTTOUCH_HANDE_PORT=/dev/ttyUSB1 cargo test --release -p softtouch-drivers \
//!   --test hardware -- --ignored hardware_
//! ```

use softtouch_drivers::ati_serial::{self, AtiSerial, AtiSerialConfig};
use softtouch_drivers::gripper::{GripperCommand, ObjectStatus, opening_mm, position_for_opening};
use softtouch_drivers::hande::{self, HandE, HandEConfig};
use softtouch_drivers::netft::{self, NetFtClient, Scaling};
use softtouch_drivers::{Clock, ForceSensor, Gripper, TokioClock, open};
use softtouch_schemas::FtReading;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// The variable's value; a missing one fails the test with its name.
fn required(name: &str) -> String {
    std::env::var(name)
        .ok()
        .filter(|v| !v.trim().is_empty())
        .unwrap_or_else(|| panic!("{name} is not set (see TESTING.md, hardware tier)"))
}

/// The variable parsed, or `default` when unset; an unparsable value fails the test.
fn optional<T: std::str::FromStr>(name: &str, default: T) -> T {
    match std::env::var(name) {
        Err(_) => default,
        Ok(v) => v
            .parse()
            .unwrap_or_else(|_| panic!("{name}={v:?} does not parse (see TESTING.md)")),
    }
}

fn wall_clock() -> Arc<dyn Clock> {
    Arc::new(TokioClock::new())
}

/// Every reading finite, none faulted, stamps never going back.
fn check_readings(readings: &[FtReading], device: &str) {
    assert!(!readings.is_empty(), "{device}: no readings");
    for r in readings {
        assert!(
            r.wrench_in_sensor.to_array().iter().all(|v| v.is_finite()),
            "{device}: non-finite reading {r:?}"
        );
        assert!(
            !r.status.is_fault(),
            "{device}: status {} in {r:?}",
            r.status
        );
    }
    assert!(
        readings.windows(2).all(|w| w[1].t >= w[0].t),
        "{device}: stamps go back"
    );
}

#[tokio::test]
#[ignore = "hardware: needs a Net F/T at SOFTTOUCH_NETFT_ADDRESS; run with --ignored"]
async fn hardware_netft_reads_its_calibration_and_streams_at_its_rate() {
    let address = required("SOFTTOUCH_NETFT_ADDRESS");
    // The rate configured on the sensor's web page.
    let rate_hz: f64 = optional("SOFTTOUCH_NETFT_RATE_HZ", 1000.0);
    let config = open::netft_config(&address, rate_hz, None, None)
        .await
        .expect("resolve the address");
    let Scaling::CalibrationRequest(cal_addr) = config.scaling else {
        panic!("expected the calibration to be read from the sensor");
    };
    let cal = netft::client::read_calibration(cal_addr, Duration::from_secs(1))
        .await
        .expect("calibration over TCP 49151");
    let (per_n, per_nm) = cal.counts_per_si().expect("known units");
    assert!(
        per_n.is_finite() && per_n > 0.0 && per_nm.is_finite() && per_nm > 0.0,
        "calibration {cal:?}"
    );
    eprintln!("calibration: {per_n} counts/N, {per_nm} counts/N·m");

    let mut sensor = NetFtClient::connect(config, wall_clock())
        .await
        .expect("connect");
    sensor.start().await.expect("start streaming");
    let mut readings = Vec::new();
    let mut batch = Vec::new();
    let started = Instant::now();
    while started.elapsed() < Duration::from_secs(1) {
        sensor.read(&mut batch).await.expect("read");
        readings.append(&mut batch);
    }
    let secs = started.elapsed().as_secs_f64();
    sensor.stop().await.expect("stop streaming");
    check_readings(&readings, "net-ft");
    let stats = sensor.stats();
    let measured_hz = readings.len() as f64 / secs;
    eprintln!(
        "{} readings in {secs:.3} s ({measured_hz:.0} Hz), {stats:?}",
        readings.len()
    );
    assert!(
        (measured_hz - rate_hz).abs() <= 0.2 * rate_hz,
        "streamed {measured_hz:.0} Hz, configured {rate_hz} Hz (SOFTTOUCH_NETFT_RATE_HZ)"
    );
    assert!(
        stats.lost * 100 <= stats.received.max(1),
        "lost more than 1% of the readings: {stats:?}"
    );
    assert_eq!(stats.bad_datagrams, 0, "{stats:?}");
}

#[tokio::test]
#[ignore = "hardware: needs an ATI serial F/T box at SOFTTOUCH_ATI_PORT; run with --ignored"]
async fn hardware_ati_serial_reads_readings() {
    let port = required("SOFTTOUCH_ATI_PORT");
    let baud: u32 = optional("SOFTTOUCH_ATI_BAUD", 9600);
    // The box reports counts; without the calibration's counts per unit the readings
    // are in counts (1 count per unit), which is enough to see them arrive.
    let per_n: f64 = optional("SOFTTOUCH_ATI_COUNTS_PER_FORCE", 1.0);
    let per_nm: f64 = optional("SOFTTOUCH_ATI_COUNTS_PER_TORQUE", 1.0);
    let io = ati_serial::open_port(&port, baud).expect("open the port");
    let mut sensor = AtiSerial::new(io, AtiSerialConfig::new(per_n, per_nm), wall_clock())
        .await
        .expect("set the box to ASCII, resolved output");
    let one = sensor.query().await.expect("query one reading");
    check_readings(&[one], "ati-serial query");

    sensor.start().await.expect("start streaming");
    let mut readings = Vec::new();
    let mut batch = Vec::new();
    let started = Instant::now();
    while readings.len() < 20 && started.elapsed() < Duration::from_secs(3) {
        sensor.read(&mut batch).await.expect("read");
        readings.append(&mut batch);
    }
    sensor.stop().await.expect("stop streaming");
    eprintln!(
        "{} readings in {:.3} s, {:?}, first {one:?}",
        readings.len(),
        started.elapsed().as_secs_f64(),
        sensor.stats()
    );
    assert!(
        readings.len() >= 20,
        "only {} readings in 3 s",
        readings.len()
    );
    check_readings(&readings, "ati-serial");
    assert_eq!(sensor.lost_readings(), 0, "{:?}", sensor.stats());
}

/// Poll until the fingers stop (or 3 s); the last status.
async fn settle(gripper: &mut HandE) -> softtouch_drivers::GripperStatus {
    let started = Instant::now();
    loop {
        let s = gripper.status().await.expect("status");
        assert_eq!(s.fault, 0, "Hand-E fault {:#04x}: {s:?}", s.fault);
        if s.object != ObjectStatus::Moving || started.elapsed() > Duration::from_secs(3) {
            return s;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

#[tokio::test]
#[ignore = "hardware: needs a Hand-E at SOFTTOUCH_HANDE_PORT; run with --ignored"]
async fn hardware_hande_activates_and_moves_a_little() {
    let port = required("SOFTTOUCH_HANDE_PORT");
    let slave_id: u8 = optional("SOFTTOUCH_HANDE_SLAVE", hande::regs::DEFAULT_SLAVE);
    let io = hande::open_port(&port).expect("open the port");
    let config = HandEConfig {
        slave_id,
        ..HandEConfig::default()
    };
    let mut gripper = HandE::new(io, config, wall_clock());
    gripper.activate().await.expect("activate");
    let before = settle(&mut gripper).await;
    assert!(before.activated, "not activated: {before:?}");

    // 5 mm towards the middle of the stroke, slowly and gently, then back.
    let opening = opening_mm(before.position);
    let step_mm = if opening > 25.0 { -5.0 } else { 5.0 };
    let gentle = |position: u8| GripperCommand {
        position,
        speed: 32,
        force: 0,
    };
    let target = position_for_opening(opening + step_mm);
    gripper.command(gentle(target)).await.expect("move 5 mm");
    let moved = settle(&mut gripper).await;
    eprintln!("from {before:?}\nto {moved:?}");
    assert_eq!(moved.requested_position, target, "{moved:?}");
    if moved.object == ObjectStatus::AtPosition {
        assert!(
            moved.position.abs_diff(target) <= 3,
            "stopped at {} for {target}",
            moved.position
        );
    }
    gripper
        .command(gentle(before.position))
        .await
        .expect("move back");
    let back = settle(&mut gripper).await;
    assert_eq!(back.requested_position, before.position, "{back:?}");
}

#[tokio::test]
#[ignore = "hardware: needs a Net F/T at SOFTTOUCH_NETFT_ADDRESS; run with --ignored"]
async fn hardware_netft_confirms_its_bias_and_restarts_a_stream_another_client_stopped() {
    let address = required("SOFTTOUCH_NETFT_ADDRESS");
    let rate_hz: f64 = optional("SOFTTOUCH_NETFT_RATE_HZ", 1000.0);
    let config = open::netft_config(&address, rate_hz, None, None)
        .await
        .expect("resolve the address");
    let rdt = config.rdt_addr;
    let mut sensor = NetFtClient::connect(config, wall_clock())
        .await
        .expect("connect");
    sensor.start().await.expect("start streaming");
    // Untouched sensor: the bias takes, and the readings go to zero.
    sensor.bias().await.expect("bias confirmed");
    let mut readings = Vec::new();
    while readings.len() < 100 {
        sensor.read(&mut readings).await.expect("read");
    }
    let tail = readings.get(readings.len() - 50..).expect("50");
    let mean_fz = tail
        .iter()
        .map(|r| r.wrench_in_sensor.force_n[2])
        .sum::<f64>()
        / 50.0;
    assert!(mean_fz.abs() < 0.1, "Fz after the bias: {mean_fz} N");
    // Another client stops the stream (as a second program, or a sensor reboot, does).
    let other = tokio::net::UdpSocket::bind("0.0.0.0:0")
        .await
        .expect("bind");
    other
        .send_to(
            &netft::codec::encode_request(netft::codec::Command::Stop, 0),
            rdt,
        )
        .await
        .expect("send stop");
    let started = Instant::now();
    let mut more = Vec::new();
    while started.elapsed() < Duration::from_secs(1) {
        sensor.read(&mut more).await.expect("the stream comes back");
    }
    let stats = sensor.stats();
    eprintln!("{stats:?}");
    assert!(stats.restarts >= 1, "no restart: {stats:?}");
    assert!(!more.is_empty());
    sensor.stop().await.expect("stop streaming");
}

#[tokio::test]
#[ignore = "hardware: needs a Hand-E at SOFTTOUCH_HANDE_PORT; run with --ignored"]
async fn hardware_hande_exchanges_at_loop_rate_and_reactivates_without_moving() {
    let port = required("SOFTTOUCH_HANDE_PORT");
    let slave_id: u8 = optional("SOFTTOUCH_HANDE_SLAVE", hande::regs::DEFAULT_SLAVE);
    if let Some(ms) = hande::latency_timer_ms(&port) {
        assert!(
            ms <= 1,
            "the adapter's latency timer is {ms} ms: set it to 1 (docs/RIG.md)"
        );
    }
    let io = hande::open_port(&port).expect("open the port");
    let config = HandEConfig {
        slave_id,
        ..HandEConfig::default()
    };
    let mut gripper = HandE::new(io, config, wall_clock());
    gripper.activate().await.expect("activate");
    let before = settle(&mut gripper).await;
    // Activating an active gripper changes nothing (no reset, no opening).
    gripper.activate().await.expect("activate again");
    let again = settle(&mut gripper).await;
    assert!(
        again.position.abs_diff(before.position) <= 2,
        "re-activation moved the fingers: {before:?} -> {again:?}"
    );
    let hold = GripperCommand {
        position: again.position,
        speed: 32,
        force: 0,
    };
    let started = Instant::now();
    for _ in 0..100 {
        let s = gripper.command_and_status(hold).await.expect("exchange");
        assert_eq!(s.fault, 0, "{}", hande::regs::describe_fault(s.fault));
    }
    let hz = 100.0 / started.elapsed().as_secs_f64();
    eprintln!("{hz:.0} exchanges/s, {:?}", gripper.stats());
    assert!(
        hz >= 100.0,
        "{hz:.0} exchanges/s: the loop needs 100 or more"
    );
    assert_eq!(gripper.stats().timeouts, 0, "{:?}", gripper.stats());
}
