//! Building rigs from the rig config: all simulated, and a real Net F/T (the
//! simulated server on loopback) on an otherwise simulated rig.

mod common;

use softtouch_drivers::netft::{NetFtServer, ServerConfig};
use softtouch_drivers::select::{self, SelectError};
use softtouch_drivers::{DeviceError, TokioClock};
use softtouch_schemas::defaults;
use softtouch_schemas::rig::{CameraDevice, ForceSensorDevice, GripperDevice};

#[tokio::test(start_paused = true)]
async fn an_all_simulated_rig_builds_from_the_defaults() {
    let mut d = select::build(&defaults::rig(), &defaults::scene(), 1, TokioClock::new())
        .await
        .expect("build");
    assert!(d.sim.is_some());
    d.force_sensor.start().await.expect("start");
    let mut out = Vec::new();
    assert!(d.force_sensor.read(&mut out).await.expect("read") > 0);
    d.gripper.activate().await.expect("activate");
}

#[tokio::test]
async fn a_net_ft_entry_connects_to_a_server_at_host_port() {
    let mut cfg = ServerConfig::at(([127, 0, 0, 1], 0).into());
    cfg.calibration_bind = None;
    let server = NetFtServer::bind(common::PatternSensor::new(1000.0), cfg)
        .await
        .expect("bind");
    let addr = server.rdt_addr().expect("addr");
    tokio::spawn(server.run(std::future::pending()));
    let mut rig = defaults::rig();
    rig.force_sensor = ForceSensorDevice::NetFt {
        address: addr.to_string(),
        rate_hz: 1000.0,
        counts_per_force: Some(1e6),
        counts_per_torque: Some(1e6),
        latency_s: None,
    };
    let mut d = select::build(&rig, &defaults::scene(), 1, TokioClock::new())
        .await
        .expect("build");
    d.force_sensor.start().await.expect("start");
    let mut out = Vec::new();
    assert!(d.force_sensor.read(&mut out).await.expect("read") > 0);
    assert_eq!(out[0].rdt_sequence, 1, "readings came over RDT");
}

#[tokio::test]
async fn real_devices_that_are_not_there_fail_with_the_device_named() {
    let mut rig = defaults::rig();
    rig.gripper = GripperDevice::HandE {
        port: "/dev/does-not-exist".into(),
        slave_id: 9,
    };
    let e = select::build(&rig, &defaults::scene(), 1, TokioClock::new())
        .await
        .expect_err("no port");
    assert!(
        matches!(
            e,
            SelectError::Device {
                device: "gripper",
                source: DeviceError::Link { .. }
            }
        ),
        "{e}"
    );
    let mut rig = defaults::rig();
    rig.camera = CameraDevice::V4l {
        device: "/dev/does-not-exist".into(),
        latency_s: None,
    };
    let e = select::build(&rig, &defaults::scene(), 1, TokioClock::new())
        .await
        .expect_err("no camera");
    assert!(
        matches!(
            e,
            SelectError::Device {
                device: "camera",
                ..
            }
        ),
        "{e}"
    );
}

#[tokio::test]
async fn addresses_take_an_optional_port() {
    assert_eq!(
        select::resolve("127.0.0.1", 49152)
            .await
            .expect("host")
            .port(),
        49152
    );
    assert_eq!(
        select::resolve("127.0.0.1:5000", 49152)
            .await
            .expect("host:port")
            .port(),
        5000
    );
    assert_eq!(
        select::resolve("::1", 49152).await.expect("v6").port(),
        49152
    );
    assert_eq!(
        select::resolve("[::1]:7", 49152)
            .await
            .expect("v6 port")
            .port(),
        7
    );
    let c = select::netft_config("127.0.0.1:6000", 1000.0, None, None)
        .await
        .expect("config");
    assert_eq!(
        c.scaling,
        softtouch_drivers::netft::Scaling::CalibrationRequest(([127, 0, 0, 1], 5999).into())
    );
}
