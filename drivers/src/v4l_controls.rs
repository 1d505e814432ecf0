//! The V4L2 controls a rig's `[camera.image]` table locks, as a plan of writes and a
//! check of what the camera holds afterwards. Pure, so it is tested without a camera
//! (the `v4l` feature's driver applies it).
//!
//! Control ids are the kernel's (`linux/v4l2-controls.h`). Each automatic control is
//! turned off before its manual value is written: a UVC camera ignores, or refuses, a
//! manual exposure while automatic exposure is on. Only controls the camera lists are
//! touched ([`plan_for`]): the UVC driver has no automatic gain, so a typical USB
//! camera's gain is written without it; a setting whose value control is missing is
//! refused by name.

use softtouch_schemas::rig::ImageSettings;

/// `V4L2_CID_AUTO_WHITE_BALANCE` (boolean).
pub const AUTO_WHITE_BALANCE: u32 = 0x0098_090c;
/// `V4L2_CID_AUTOGAIN` (boolean).
pub const AUTOGAIN: u32 = 0x0098_0912;
/// `V4L2_CID_GAIN`.
pub const GAIN: u32 = 0x0098_0913;
/// `V4L2_CID_WHITE_BALANCE_TEMPERATURE`, K.
pub const WHITE_BALANCE_TEMPERATURE: u32 = 0x0098_091a;
/// `V4L2_CID_EXPOSURE_AUTO` (menu; 1 = `V4L2_EXPOSURE_MANUAL`).
pub const EXPOSURE_AUTO: u32 = 0x009a_0901;
/// `V4L2_CID_EXPOSURE_ABSOLUTE`, in 100 µs units.
pub const EXPOSURE_ABSOLUTE: u32 = 0x009a_0902;
/// `V4L2_EXPOSURE_MANUAL`.
pub const EXPOSURE_MANUAL: i64 = 1;

/// One control write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ControlWrite {
    /// The control's id.
    pub id: u32,
    /// Its name, for errors and `rig check`.
    pub name: &'static str,
    /// The value written.
    pub value: i64,
}

/// Exposure in V4L2's 100 µs units, rounded to the nearest step.
#[must_use]
pub fn exposure_steps(exposure_us: u32) -> i64 {
    (i64::from(exposure_us) + 50) / 100
}

/// The writes that lock `image`, in order: each automatic control off, then its value.
#[must_use]
pub fn plan(image: &ImageSettings) -> Vec<ControlWrite> {
    let mut out = Vec::new();
    let mut push = |id, name, value| out.push(ControlWrite { id, name, value });
    if let Some(us) = image.exposure_us {
        push(EXPOSURE_AUTO, "exposure_auto", EXPOSURE_MANUAL);
        push(
            EXPOSURE_ABSOLUTE,
            "exposure_time_absolute",
            exposure_steps(us),
        );
    }
    if let Some(k) = image.white_balance_k {
        push(AUTO_WHITE_BALANCE, "white_balance_automatic", 0);
        push(
            WHITE_BALANCE_TEMPERATURE,
            "white_balance_temperature",
            i64::from(k),
        );
    }
    if let Some(g) = image.gain {
        push(AUTOGAIN, "gain_automatic", 0);
        push(GAIN, "gain", i64::from(g));
    }
    out
}

/// The writes that lock `image` on a camera that lists the controls `listed` (ids
/// from `VIDIOC_QUERYCTRL`): an automatic control it lacks is left out (named in the
/// second value, for `rig check`), and a setting whose own control it lacks is refused
/// naming the setting.
pub fn plan_for(
    image: &ImageSettings,
    listed: &[u32],
) -> Result<(Vec<ControlWrite>, Vec<&'static str>), String> {
    const AUTOMATIC: [u32; 3] = [EXPOSURE_AUTO, AUTO_WHITE_BALANCE, AUTOGAIN];
    let mut writes = Vec::new();
    let mut lacking = Vec::new();
    for w in plan(image) {
        if listed.contains(&w.id) {
            writes.push(w);
        } else if AUTOMATIC.contains(&w.id) {
            lacking.push(w.name);
        } else {
            let setting = match w.id {
                EXPOSURE_ABSOLUTE => "exposure_us",
                WHITE_BALANCE_TEMPERATURE => "white_balance_k",
                _ => "gain",
            };
            return Err(format!(
                "[camera.image] {setting} asks for {} = {}, and the camera has no such control (v4l2-ctl -L lists those it has); remove {setting} from the rig file",
                w.name, w.value
            ));
        }
    }
    Ok((writes, lacking))
}

/// Compares what the camera holds (`held`: each planned control read back, `None`
/// where it could not be read) with the plan; the first difference, named.
pub fn check_held(plan: &[ControlWrite], held: &[Option<i64>]) -> Result<(), String> {
    for (i, w) in plan.iter().enumerate() {
        match held.get(i).copied().flatten() {
            Some(v) if v == w.value => {}
            Some(v) => {
                return Err(format!(
                    "asked {} = {}, the camera holds {v} (it clamps or rounds to what it supports; set a value it offers: v4l2-ctl -L)",
                    w.name, w.value
                ));
            }
            None => {
                return Err(format!(
                    "asked {} = {}, and it cannot be read back: the camera may not have this control (v4l2-ctl -L lists them)",
                    w.name, w.value
                ));
            }
        }
    }
    Ok(())
}

/// A frame-rate request's answer: the rate the camera set, checked against the rate
/// asked (within 1 %). A camera that silently runs slower would starve the loop.
pub fn check_rate(asked_fps: f64, numerator: u32, denominator: u32) -> Result<f64, String> {
    if numerator == 0 {
        return Err(format!(
            "asked {asked_fps:.1} frames/s, the camera answered a frame interval of {numerator}/{denominator} s"
        ));
    }
    let got = f64::from(denominator) / f64::from(numerator);
    if (got - asked_fps).abs() > 0.01 * asked_fps {
        return Err(format!(
            "asked {asked_fps:.1} frames/s, the camera set {got:.1} (a slower USB link or another camera on the bus?)"
        ));
    }
    Ok(got)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_setting_turns_its_automatic_control_off_before_its_value() {
        let all = ImageSettings {
            exposure_us: Some(5049),
            white_balance_k: Some(4600),
            gain: Some(12),
        };
        let p = plan(&all);
        let ids: Vec<u32> = p.iter().map(|w| w.id).collect();
        assert_eq!(
            ids,
            [
                EXPOSURE_AUTO,
                EXPOSURE_ABSOLUTE,
                AUTO_WHITE_BALANCE,
                WHITE_BALANCE_TEMPERATURE,
                AUTOGAIN,
                GAIN
            ]
        );
        assert_eq!(p[1].value, 50, "5049 µs is 50 steps of 100 µs");
        assert_eq!(exposure_steps(5050), 51);
        assert!(
            plan(&ImageSettings {
                exposure_us: None,
                white_balance_k: None,
                gain: None
            })
            .is_empty()
        );
    }

    #[test]
    fn a_value_the_camera_does_not_hold_is_named() {
        let p = plan(&ImageSettings {
            exposure_us: Some(5000),
            white_balance_k: None,
            gain: Some(12),
        });
        assert_eq!(
            check_held(&p, &[Some(1), Some(50), Some(0), Some(12)]),
            Ok(())
        );
        let e = check_held(&p, &[Some(1), Some(50), Some(0), Some(10)]).expect_err("clamped");
        assert!(e.contains("asked gain = 12, the camera holds 10"), "{e}");
        let e = check_held(&p, &[Some(3), Some(50), Some(0), Some(12)]).expect_err("auto");
        assert!(e.contains("exposure_auto = 1"), "{e}");
        let e = check_held(&p, &[Some(1)]).expect_err("unreadable");
        assert!(e.contains("cannot be read back"), "{e}");
    }

    #[test]
    fn only_controls_the_camera_lists_are_touched() {
        let all = ImageSettings {
            exposure_us: Some(5000),
            white_balance_k: Some(4600),
            gain: Some(12),
        };
        // A UVC camera: no automatic gain (the uvcvideo driver maps none).
        let uvc = [
            EXPOSURE_AUTO,
            EXPOSURE_ABSOLUTE,
            AUTO_WHITE_BALANCE,
            WHITE_BALANCE_TEMPERATURE,
            GAIN,
        ];
        let (writes, lacking) = plan_for(&all, &uvc).expect("a UVC camera takes it");
        assert!(writes.iter().all(|w| w.id != AUTOGAIN), "{writes:?}");
        assert_eq!(writes.last().map(|w| (w.id, w.value)), Some((GAIN, 12)));
        assert_eq!(lacking, ["gain_automatic"]);
        // Every control listed: the whole plan.
        let every = [uvc.as_slice(), &[AUTOGAIN]].concat();
        assert_eq!(plan_for(&all, &every).map(|p| p.0), Ok(plan(&all)));
        // No gain control at all: refused, naming the setting.
        let e = plan_for(&all, &uvc[..4]).expect_err("no gain");
        assert!(
            e.contains("gain asks for gain = 12") && e.contains("remove gain"),
            "{e}"
        );
        let e = plan_for(&all, &[]).expect_err("nothing listed");
        assert!(e.contains("exposure_us"), "{e}");
    }

    #[test]
    fn the_frame_rate_answer_is_checked() {
        assert_eq!(check_rate(120.0, 1, 120), Ok(120.0));
        assert!((check_rate(30.0, 1001, 30000).expect("29.97") - 29.97).abs() < 0.01);
        let e = check_rate(120.0, 1, 60).expect_err("half");
        assert!(e.contains("the camera set 60.0"), "{e}");
        assert!(check_rate(120.0, 0, 120).is_err());
    }
}
