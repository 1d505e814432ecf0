//! The rig's Hand-E on a pty pair: the soft grasp behind the project's Hand-E server,
//! the real Modbus client on the other end, calibrated and stored as
//! `grasp calibrate --rig` does. Shared by the rig trials on the simulated arm and
//! through franka-sim.

use std::sync::Arc;
use std::time::Duration;

use softtouch_drivers::hande::{self, HandE, HandEConfig, HandEService};
use softtouch_drivers::{Camera, Clock, DeviceError, Gripper, TokioClock};
use softtouch_grasp::{CalibrationConfig, calibrate_ends, calibrate_stiffness};
use softtouch_lab::grasp::calibration::{config_for, rig_setup_hash, to_row, top_for};
use softtouch_schemas::{RigConfig, SceneSpec};
use softtouch_sim::{GraspObject, SoftGraspHandle, SoftGripper, soft_grasp};
use softtouch_store::Store;
use softtouch_trainer::Predictor;

use crate::pty::PtyPair;

/// The Hand-E link and the world behind it.
pub(crate) struct HandERig {
    /// The client end: what the trials drive.
    pub(crate) hand_e: Box<dyn Gripper>,
    pub(crate) camera: Box<dyn Camera>,
    pub(crate) handle: SoftGraspHandle,
    /// The server's side: its watchdog count.
    pub(crate) service: HandEService<SoftGripper>,
    pub(crate) server: tokio::task::JoinHandle<Result<(), DeviceError>>,
    /// Sent (or dropped) to stop the server.
    pub(crate) server_stop: tokio::sync::oneshot::Sender<()>,
    pub(crate) clock: TokioClock,
    pub(crate) shared: Arc<dyn Clock>,
}

/// The soft grasp of `object` in `scene` behind a Hand-E server on `pair.b` (1 s
/// watchdog), the client on `pair.a`; then `grasp calibrate --rig`'s closing with the
/// object away, the stiffness from the model (`model`, its `bytes`) with the object
/// between the fingers, stored for `object_name` on `rig`. Panics on any failure.
pub(crate) async fn calibrated_hand_e(
    pair: &PtyPair,
    scene: &SceneSpec,
    (object_name, object): (&str, &GraspObject),
    (model, bytes): (&str, &[u8]),
    rig: &RigConfig,
    store: &Store,
) -> HandERig {
    let clock = TokioClock::new();
    let (gripper, camera, handle) =
        soft_grasp(scene, object.clone(), 30.0, 7, clock).expect("builds");
    let service = HandEService::new(gripper, 9).with_watchdog(Duration::from_secs(1));
    let (server_stop, server_stopped) = tokio::sync::oneshot::channel::<()>();
    let server = tokio::spawn(hande::serve_serial(
        service.clone(),
        hande::open_port(&pair.b).expect("open pty b"),
        async move {
            let _ = server_stopped.await;
        },
    ));
    let shared: Arc<dyn Clock> = Arc::new(clock);
    let mut hand_e: Box<dyn Gripper> = Box::new(HandE::new(
        hande::open_port(&pair.a).expect("open pty a"),
        HandEConfig::default(),
        shared.clone(),
    ));
    let mut camera: Box<dyn Camera> = Box::new(camera);

    handle.set_object(false).expect("clear");
    let ends = calibrate_ends(hand_e.as_mut(), &clock, &CalibrationConfig::default())
        .await
        .expect("ends");
    handle.set_object(true).expect("object back");
    let mut predictor = Predictor::from_bytes(bytes).expect("loads");
    let projection = softtouch_lab::grasp::sim::projection().expect("projection");
    let cal = calibrate_stiffness(
        hand_e.as_mut(),
        camera.as_mut(),
        &mut predictor,
        &projection,
        &ends.stroke,
        shared.as_ref(),
        &config_for(object, top_for(1.5)),
    )
    .await
    .expect("the finger's estimate sees the object");
    let sha = softtouch_collector::dataset::export::sha256_hex(bytes);
    let setup = rig_setup_hash(rig).expect("hash");
    let mut row = to_row(&cal, ("rig", &setup), (model, &sha), object_name, None).expect("row");
    row.mm_per_count = ends.stroke.mm_per_count;
    store.insert_grasp_calibration(&row).await.expect("stored");
    HandERig {
        hand_e,
        camera,
        handle,
        service,
        server,
        server_stop,
        clock,
        shared,
    }
}
