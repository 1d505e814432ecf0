//! The physics' cap on a session's success rate, from its scenes and lift alone: the
//! most of a scene's objects that any one grip force both lifts and leaves whole
//! ([`softtouch_sim::GripCap`]), and how many the plan's F_ref holds. A closed loop
//! that reads the force perfectly holds no more; the paper's rate is set beside it.

use softtouch_schemas::{Medium, SceneSpec};
use softtouch_sim::{GripCap, GripWindow, grip_window};

use super::{TrialPlan, TrialsError, medium_name, objects_of};

/// One scene's cap.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneCap {
    /// The scene's name.
    pub scene: String,
    /// Its medium.
    pub medium: Medium,
    /// Each object's window, in the plan's order.
    pub windows: Vec<GripWindow>,
    /// The best one force does.
    pub cap: GripCap,
    /// How many the plan's F_ref (per finger) holds.
    pub at_target: usize,
}

impl SceneCap {
    /// One line for people: the cap, then what bounds it.
    #[must_use]
    pub fn describe(&self, target_n: f64) -> String {
        let needs: Vec<String> = self
            .windows
            .iter()
            .filter(|w| !w.holds_at(target_n))
            .map(|w| match w.crushes_above_n {
                Some(c) if target_n > c => format!("`{}` crushes above {c} N", w.object),
                _ if w.holds_from_n.is_infinite() => {
                    format!("`{}` slips at any squeeze (μ {})", w.object, w.friction)
                }
                _ => format!(
                    "`{}` needs {:.2} N per finger (μ {}, load up to {:.3} N on the lift)",
                    w.object, w.holds_from_n, w.friction, w.peak_load_n
                ),
            })
            .collect();
        let delicate: Vec<String> = self
            .windows
            .iter()
            .filter_map(|w| {
                Some(format!(
                    "`{}` crushes above {} N",
                    w.object, w.crushes_above_n?
                ))
            })
            .collect();
        format!(
            "physics cap, `{}` ({}): any one grip force holds at most {}/{} objects ({:.0} %){}; at F_ref {target_n} N per finger {}/{}{}{}",
            self.scene,
            medium_name(self.medium),
            self.cap.held,
            self.cap.of,
            100.0 * self.cap.rate(),
            self.cap
                .at_n
                .map_or_else(String::new, |f| format!(", from {f:.2} N per finger")),
            self.at_target,
            self.cap.of,
            if needs.is_empty() {
                String::new()
            } else {
                format!(": {}", needs.join("; "))
            },
            if delicate.is_empty() {
                String::new()
            } else {
                format!(" ({})", delicate.join(", "))
            }
        )
    }
}

/// The cap of each of `scenes` on `plan`'s objects and lift.
///
/// # Errors
/// An object a scene lacks, a lift or friction the physics cannot take.
pub fn scene_caps(plan: &TrialPlan, scenes: &[SceneSpec]) -> Result<Vec<SceneCap>, TrialsError> {
    let objects = objects_of(plan, scenes)?;
    let lift = plan.lift();
    scenes
        .iter()
        .zip(&objects)
        .map(|(scene, objects)| {
            let windows = objects
                .iter()
                .map(|o| {
                    grip_window(scene, o, lift.height_m, lift.speed_m_s, lift.accel_m_s2)
                        .map_err(|e| TrialsError::Invalid(format!("scene `{}`: {e}", scene.name)))
                })
                .collect::<Result<Vec<_>, _>>()?;
            Ok(SceneCap {
                scene: scene.name.clone(),
                medium: scene.medium,
                cap: GripCap::of(&windows),
                at_target: windows.iter().filter(|w| w.holds_at(plan.target_n)).count(),
                windows,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shipped scenes at the paper's protocol: every land object lifts at F_ref;
    /// in water the bottle (wet μ 0.05) needs more than the cake survives, so no one
    /// force holds all five.
    #[test]
    fn the_shipped_water_scene_caps_the_closed_loop_under_the_papers_rate() {
        let scenes = super::super::load_scenes(&[], &[]).unwrap_or_else(|e| panic!("{e}"));
        let plan = TrialPlan {
            objects: scenes[0].objects.iter().map(|o| o.name.clone()).collect(),
            ..TrialPlan::default()
        };
        let caps = scene_caps(&plan, &scenes).unwrap_or_else(|e| panic!("{e}"));
        for c in &caps {
            eprintln!("{}", c.describe(plan.target_n));
        }
        assert_eq!((caps[0].cap.held, caps[0].at_target), (5, 5), "{caps:?}");
        let water = &caps[1];
        assert_eq!((water.cap.held, water.cap.of), (4, 5), "{water:?}");
        let bottle = water.windows.iter().find(|w| w.object == "bottle");
        assert!(bottle.is_some_and(|b| b.holds_from_n > 2.5), "{water:?}");
        assert!(
            water.describe(1.5).contains("`bottle` needs"),
            "{}",
            water.describe(1.5)
        );
    }
}
